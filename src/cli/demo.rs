//! `facespace demo`: the README's first command (see `facespace::demo`).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use facespace::demo::{self, DEMO_TEXT, DemoOptions};

use super::progress_bar;

#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(short, long, default_value = "out/demo")]
    output: PathBuf,
    /// Text to synthesise (not a corpus sentence).
    #[arg(long, default_value = DEMO_TEXT)]
    text: String,
    #[arg(long, default_value = super::DEMO_MODEL)]
    model: PathBuf,
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/training"))]
    training: PathBuf,
    /// A video of the talker to draw the synthesised lower face over.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/background.mp4"))]
    background: PathBuf,
    /// Which renderer draws.
    #[arg(long, value_enum, default_value_t)]
    renderer: super::RendererArg,
}

pub fn run(a: DemoArgs) -> Result<()> {
    let clock = std::time::Instant::now();
    let (bar, progress) = progress_bar();
    let options = DemoOptions {
        output: a.output,
        text: a.text,
        model: a.model,
        training: a.training,
        background: a.background,
        renderer: a.renderer.choice(),
    };
    let r = demo::run(&options, progress)?;
    bar.finish_and_clear();
    if let Some(note) = &r.renderer_note {
        eprintln!("note: {note}");
    }
    println!(
        "model {} ({} shape + {} appearance parameters, from {} real frames); its lower-face region model: {} appearance parameters",
        options.model.display(),
        r.shape_params,
        r.appearance_params,
        r.training_frames,
        r.region_appearance_params
    );
    println!(
        "demo corpus: {} generated sentences (trajectories generated over real face-space points, not recorded)",
        r.sentences
    );
    println!(
        "synthesised {:?}: {} phones, {} frames at {} fps ({}), over {} (pose {})",
        options.text,
        r.phones,
        r.frames,
        r.report.fps,
        r.report.renderer,
        options.background.display(),
        r.report.pose
    );
    if let Some(s) = &r.unit_report.selection {
        println!(
            "unit selection: {} runs of codebook frames (mean {:.1} frames), target cost {:.1}/frame, visual cost {:.3} at joins",
            s.segments.len(),
            s.sl_avg,
            s.tc_avg,
            s.vc_avg
        );
    }
    println!("wrote to {}:", options.output.display());
    for (what, path) in &r.files {
        println!("  {what:<38} {}", path.display());
    }
    println!("done in {:.1} s", clock.elapsed().as_secs_f64());
    Ok(())
}
