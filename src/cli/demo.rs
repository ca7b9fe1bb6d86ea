//! `facespace demo`: the README's first command. From the committed demo model and its
//! training frames: generate the demo corpus, build the codebook, synthesise a sentence that
//! is not in the corpus, and write smoothed and unsmoothed videos, a blind side-by-side and a
//! trajectory plot to out/demo.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use facespace::codebook::{Codebook, Layout, SimilarityOptions};
use facespace::corpus::{self, CorpusOptions};
use facespace::model::{FaceModel, load_training_set};
use facespace::phonemes;
use facespace::synth::blend::{self, BlendOptions};

use super::synth::{Ab, DEFAULT_LAMBDA, smoothed, write_ab};

/// The demo utterance; it must not be one of the corpus sentences.
pub const DEMO_TEXT: &str = "A brave pilot found the hidden map.";

#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(short, long, default_value = "out/demo")]
    output: PathBuf,
    /// Text to synthesise (not a corpus sentence).
    #[arg(long, default_value = DEMO_TEXT)]
    text: String,
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model"))]
    model: PathBuf,
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/training"))]
    training: PathBuf,
}

pub fn run(a: DemoArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let normalise = |s: &str| {
        s.to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || *c == ' ')
            .collect::<String>()
    };
    if corpus::SENTENCES
        .iter()
        .any(|s| normalise(s) == normalise(&a.text))
    {
        bail!(
            "{:?} is a corpus sentence; the demo synthesises unseen text",
            a.text
        );
    }
    let model = FaceModel::load(&a.model)
        .with_context(|| format!("loading model {}", a.model.display()))?;
    let frames = load_training_set(&a.training, None)
        .with_context(|| format!("loading {}", a.training.display()))?;
    println!(
        "model {} ({} shape + {} appearance parameters, from {} real frames)",
        a.model.display(),
        model.shape.n_params(),
        model.appearance.n_params(),
        frames.len()
    );

    let generated = corpus::generate(&model, &frames, &CorpusOptions::default())?;
    let background = &frames[generated.still_frame].image;
    let (train, _) = generated.split();
    println!(
        "demo corpus: {} generated sentences (trajectories generated over real face-space points, not recorded)",
        train.len()
    );
    let layout = Layout::of(&model);
    let cb = Codebook::build(
        train,
        25.0,
        layout,
        Some(model.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )?;
    cb.save(&a.output.join("codebook"))?;

    let target = phonemes::text_to_segments(&a.text, &cb.mean_durations())?;
    let s = blend::blend(&cb, &target, &BlendOptions::default())?;
    let smooth = smoothed(&s, DEFAULT_LAMBDA)?;
    println!(
        "synthesised {:?}: {} phones, {} frames at 25 fps",
        a.text,
        target.len(),
        s.n_frames()
    );
    let ab = Ab {
        smoothed: &smooth,
        unsmoothed: &s.frames,
        real: None,
        target: &target,
        fps: 25.0,
        seed: 1,
        audio: None,
    };
    let key = write_ab(&a.output, &model, &layout, &ab, background)?;
    phonemes::write_labels(&a.output.join("utterance.lab"), &target)?;
    let report = serde_json::json!({ "text": a.text, "phones": s.phones, "warnings": s.warnings, "smoothing_lambda": DEFAULT_LAMBDA, "ab_key": key });
    facespace::atomic::write_file(
        &a.output.join("report.json"),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;

    let o = &a.output;
    println!("wrote to {}:", o.display());
    for (what, path) in [
        ("smoothed video", o.join("smoothed/video.mp4")),
        ("smoothed frames", o.join("smoothed/frames")),
        ("unsmoothed video", o.join("unsmoothed/video.mp4")),
        (
            "blind side by side (order in key.json)",
            o.join("side_by_side.mp4"),
        ),
        ("trajectory plot", o.join("plot.png")),
        ("phone timings", o.join("utterance.lab")),
        ("codebook", o.join("codebook")),
    ] {
        println!("  {what:<38} {}", path.display());
    }
    println!("done in {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}
