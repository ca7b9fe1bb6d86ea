//! `facespace demo`: the README's first command (see `facespace::demo`).

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use facespace::demo::{self, DemoOptions, Talker};

use super::progress_bar;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum TalkerArg {
    /// GRID speaker 1: a recorded test sentence, synthesised from its own sound.
    #[default]
    Grid,
    /// The FGNet talker over a corpus generated from his real face-space points.
    Fgnet,
}

#[derive(Args)]
#[command(
    after_help = "Example: facespace demo -o out/demo   (then open out/demo/beside_background.mp4)"
)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(short, long, default_value = "out/demo")]
    output: PathBuf,
    /// Whose face: GRID s1 (recorded, with sound) or FGNet (generated corpus).
    #[arg(long, value_enum, default_value_t)]
    talker: TalkerArg,
    /// GRID: a recording of a sentence not in his codebook, its words in NAME.txt beside it
    /// (default: the committed test sentence models/grid/demo/bbbf9a.mp4). FGNet: the video
    /// to draw the lower face over (default: models/demo/background.mp4).
    #[arg(long)]
    clip: Option<PathBuf>,
    /// GRID: the words of the recording (default: NAME.txt beside it). FGNet: the text to
    /// synthesise, not a corpus sentence (default: "A brave pilot found the hidden map.").
    #[arg(long)]
    text: Option<String>,
    /// Which renderer draws.
    #[arg(long, value_enum, default_value_t)]
    renderer: super::RendererArg,
}

pub fn run(a: DemoArgs) -> Result<()> {
    if let Some(clip) = &a.clip {
        super::check_output(&a.output, &[clip.as_path()])?;
    }
    let clock = std::time::Instant::now();
    let (bar, progress) = progress_bar();
    let options = DemoOptions {
        output: a.output,
        talker: match a.talker {
            TalkerArg::Grid => Talker::Grid,
            TalkerArg::Fgnet => Talker::Fgnet,
        },
        clip: a.clip,
        text: a.text,
        renderer: a.renderer.choice(),
    };
    let r = demo::run(&options, progress)?;
    bar.finish_and_clear();
    if let Some(note) = &r.renderer_note {
        eprintln!("note: {note}");
    }
    print!(
        "model {} ({} shape + {} appearance parameters)",
        super::shown(&r.model),
        r.shape_params,
        r.appearance_params,
    );
    match r.region_appearance_params {
        Some(n) => println!("; its lower-face region model: {n} appearance parameters"),
        None => println!(),
    }
    println!("codebook: {}", r.corpus);
    println!(
        "synthesised {:?}: {} phones, {} frames at {} fps ({}; {}), over {} (pose {})",
        r.text,
        r.phones,
        r.frames,
        r.report.fps,
        r.report.method,
        r.report.renderer,
        super::shown(&r.background),
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
    for w in r.report.warnings.iter().chain(&r.unit_report.warnings) {
        println!("  warning: {w}");
    }
    println!("wrote to {}:", options.output.display());
    for (what, path) in &r.files {
        println!("  {what:<40} {}", path.display());
    }
    println!("done in {:.1} s", clock.elapsed().as_secs_f64());
    Ok(())
}
