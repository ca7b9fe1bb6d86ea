//! `facespace corpus demo`: the generated demo corpus (see `facespace::corpus`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use facespace::corpus::{self, CorpusOptions};
use facespace::model::{FaceModel, load_training_set};
use facespace::render::{CpuRenderer, Renderer};
use facespace::{atomic, npy, phonemes, video};

#[derive(Subcommand)]
pub enum CorpusCommand {
    /// Generate the phoneme-labelled demo corpus (generated trajectories over real face-space
    /// points; see the README).
    Demo(DemoArgs),
}

#[derive(Args)]
pub struct DemoArgs {
    /// The demo model.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model"))]
    model: PathBuf,
    /// Its training frames with .pts landmarks (the source of the real face-space points).
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/training"))]
    training: PathBuf,
    #[arg(long, default_value_t = CorpusOptions::default().seed)]
    seed: u64,
    /// Also render every frame as PNG under frames/NAME/.
    #[arg(long)]
    frames: bool,
    /// Output folder (train/ and heldout/ inside).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(command: CorpusCommand) -> Result<()> {
    match command {
        CorpusCommand::Demo(a) => demo(a),
    }
}

fn demo(a: DemoArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let model = FaceModel::load(&a.model)
        .with_context(|| format!("loading model {}", a.model.display()))?;
    let frames = load_training_set(&a.training, None)
        .with_context(|| format!("loading {}", a.training.display()))?;
    let options = CorpusOptions {
        seed: a.seed,
        ..CorpusOptions::default()
    };
    let generated = corpus::generate(&model, &frames, &options)?;
    let sentences = &generated.sentences;
    let background = &frames[generated.still_frame];
    let dims = model.n_params();
    for s in sentences {
        let dir = a.output.join(if s.held_out { "heldout" } else { "train" });
        npy::write(
            &dir.join(format!("{}.npy", s.name)),
            &[s.frames.len() / dims, dims],
            &s.frames,
        )?;
        phonemes::write_labels(&dir.join(format!("{}.lab", s.name)), &s.segments)?;
        atomic::write_file(
            &dir.join(format!("{}.txt", s.name)),
            format!("{}\n", s.text).as_bytes(),
        )?;
    }
    let manifest = serde_json::json!({
        "generator": "facespace corpus demo",
        "note": "Trajectories are GENERATED (dominance-function coarticulation over real face-space points of the demo training frames), not recorded. Phone sequences come from the CMU dictionary, durations from a table with seeded jitter.",
        "options": options,
        "model_hash": model.hash(),
        "still_frame": std::path::Path::new(&background.name).file_name().map(|n| n.to_string_lossy().into_owned()),
        "fps": options.fps,
        "train": sentences.iter().filter(|s| !s.held_out).map(|s| &s.name).collect::<Vec<_>>(),
        "heldout": sentences.iter().filter(|s| s.held_out).map(|s| &s.name).collect::<Vec<_>>(),
        "texts": sentences.iter().map(|s| (&s.name, &s.text)).collect::<std::collections::BTreeMap<_, _>>(),
    });
    atomic::write_file(
        &a.output.join("corpus.json"),
        serde_json::to_string_pretty(&manifest)?.as_bytes(),
    )?;
    let total: usize = sentences.iter().map(|s| s.frames.len() / dims).sum();
    println!(
        "generated {} sentences ({} train, {} held out), {total} frames at {} fps, in {:.2} s → {}",
        sentences.len(),
        sentences.iter().filter(|s| !s.held_out).count(),
        sentences.iter().filter(|s| s.held_out).count(),
        options.fps,
        start.elapsed().as_secs_f64(),
        a.output.display()
    );
    if a.frames {
        let (bar, mut progress) = super::progress_bar();
        for (i, s) in sentences.iter().enumerate() {
            let rows: Vec<f64> = s.frames.iter().map(|&v| v as f64).collect();
            let images = CpuRenderer.render(&model, &rows, &background.image)?;
            video::write_png_frames(&a.output.join("frames").join(&s.name), &images)?;
            progress(facespace::Progress {
                stage: "rendering",
                done: i + 1,
                total: sentences.len(),
            });
        }
        bar.finish_and_clear();
        println!("rendered frames → {}", a.output.join("frames").display());
    }
    Ok(())
}
