//! `facespace corpus demo`: the generated demo corpus (see `facespace::corpus::demo`).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use facespace::corpus::demo::{self, CorpusOptions, Split};
use facespace::model::load_training_set;

use super::{DEMO_MODEL, RendererArg, load_model, progress_bar};

#[derive(Subcommand)]
pub enum CorpusCommand {
    /// Generate the phoneme-labelled demo corpus (generated trajectories over real face-space
    /// points; see the README).
    Demo(DemoArgs),
}

#[derive(Args)]
pub struct DemoArgs {
    /// The demo model.
    #[arg(long, default_value = DEMO_MODEL)]
    model: PathBuf,
    /// Its training frames with .pts landmarks (the source of the real face-space points).
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/training"))]
    training: PathBuf,
    #[arg(long, default_value_t = CorpusOptions::default().seed)]
    seed: u64,
    /// Also render every frame as PNG under frames/NAME/.
    #[arg(long)]
    frames: bool,
    /// Which renderer draws the frames (with --frames).
    #[arg(long, value_enum, default_value_t)]
    renderer: RendererArg,
    /// Output folder (train/ and heldout/ inside).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(command: CorpusCommand) -> Result<()> {
    match command {
        CorpusCommand::Demo(a) => generate(a),
    }
}

fn generate(a: DemoArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let model = load_model(&a.model)?;
    let frames = load_training_set(&a.training, None)
        .with_context(|| format!("loading {}", a.training.display()))?;
    let options = CorpusOptions {
        seed: a.seed,
        ..CorpusOptions::default()
    };
    let corpus = demo::generate(&model, &frames, &options)?;
    let still = &frames[corpus.still_frame];
    let still_name = Path::new(&still.name)
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let renderer = if a.frames {
        Some(a.renderer.make(&model, None)?)
    } else {
        None
    };
    let (bar, progress) = progress_bar();
    corpus
        .save(
            &a.output,
            &model,
            &options,
            &still_name,
            renderer.as_deref().map(|r| (r, &still.image)),
            progress,
        )
        .with_context(|| format!("writing {}", a.output.display()))?;
    bar.finish_and_clear();
    let count = |split| corpus.sentences.iter().filter(|s| s.split == split).count();
    let total: usize = corpus
        .sentences
        .iter()
        .map(|s| s.sentence.frames.len())
        .sum();
    println!(
        "generated {} sentences ({} train, {} validation, {} test in heldout/), {total} frames at {} fps, in {:.2} s → {}",
        corpus.sentences.len(),
        count(Split::Train),
        count(Split::Validation),
        count(Split::Test),
        options.fps,
        start.elapsed().as_secs_f64(),
        a.output.display()
    );
    if a.frames {
        println!("rendered frames → {}", a.output.join("frames").display());
    }
    Ok(())
}
