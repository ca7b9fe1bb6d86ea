//! `facespace track`: AAM search on every frame, each frame started from the last.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use facespace::codec::{self, TrackingSummary};
use facespace::{shape, video};

use super::{TrackingArgs, load_model, progress_bar, tracking_line};

#[derive(Args)]
pub struct TrackArgs {
    /// The face model to track with.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// A folder of frames (png, jpg), an MP4 or Y4M, or any video a system ffmpeg reads.
    input: PathBuf,
    #[command(flatten)]
    tracking: TrackingArgs,
    /// Output: a folder of .pts files (one per frame), or a .npy (frames × landmarks × 2).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: TrackArgs) -> Result<()> {
    let mut inputs = vec![a.input.as_path(), a.model.as_path()];
    inputs.extend(a.tracking.init.as_deref());
    super::check_output(&a.output, &inputs)?;
    let model = load_model(&a.model)?;
    let options = a.tracking.options(None)?;
    let source = video::Source::open(&a.input)?;
    // A frame folder's .pts files keep the frames' names.
    let names = source.frame_names();
    let (bar, progress) = progress_bar();
    let clock = std::time::Instant::now();
    let (landmarks, tracking) = codec::track_landmarks(&model, source, &options, progress)
        .map_err(|e| {
            super::tracking_context("tracking", &a.input, super::TRACKING_REMEDY)(e.into())
        })?;
    bar.finish_and_clear();
    let seconds = clock.elapsed().as_secs_f64();
    shape::write_sequence(&a.output, &landmarks, names.as_deref())?;
    println!(
        "tracked {} → {}",
        tracking_line(&TrackingSummary::of(&tracking), seconds),
        a.output.display()
    );
    Ok(())
}
