//! `facespace frames`: frames spread over a video, to mark landmarks on.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::video;

use super::progress_bar;

#[derive(Args)]
pub struct FramesArgs {
    /// A video (MP4, Y4M, or any a system ffmpeg reads) or a frame folder.
    input: PathBuf,
    /// How many frames, spread evenly from the first to the last.
    #[arg(long, default_value_t = 40)]
    count: usize,
    /// Output folder of NNNNNN.png (NNNNNN: the frame's index in the video).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: FramesArgs) -> Result<()> {
    super::check_output(&a.output, &[&a.input])?;
    let (bar, progress) = progress_bar();
    let written = video::export_frames(&a.input, a.count, &a.output, progress)
        .with_context(|| format!("exporting frames of {}", a.input.display()))?;
    bar.finish_and_clear();
    println!(
        "wrote {} frames (indices {}…{}) → {}",
        written.len(),
        written.first().unwrap_or(&0),
        written.last().unwrap_or(&0),
        a.output.display()
    );
    Ok(())
}
