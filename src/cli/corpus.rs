//! `facespace corpus demo`: the generated demo corpus (see `facespace::corpus::demo`);
//! `facespace corpus from-videos`: a corpus from recordings with phone labels (whole, or one
//! `--shard` of it); `facespace corpus merge`: the shards joined.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use facespace::corpus::demo::{self, CorpusOptions, Split};
use facespace::model::load_training_set;

use super::{RendererArg, load_model, progress_bar};

#[derive(Subcommand)]
pub enum CorpusCommand {
    /// Generate the phoneme-labelled demo corpus (generated trajectories over real face-space
    /// points; see the README).
    #[command(after_help = "Example: facespace corpus demo -o out/corpus")]
    Demo(DemoArgs),
    /// A corpus from recordings: every NAME.mp4 (or NAME.y4m, frame folder NAME/, any video
    /// ffmpeg reads) with NAME.lab / NAME.TextGrid / NAME.tsv in DIR is tracked and projected
    /// with the model → NAME.npy + labels (+ NAME.m4a) for `codebook build`.
    #[command(
        after_help = "Example: facespace corpus from-videos --model models/grid/model clips/ -o out/grid/train"
    )]
    FromVideos(FromVideosArgs),
    /// Join corpus folders made with `from-videos --shard K/N` (one per task of a job array)
    /// into the corpus one run over all the recordings writes, file for file.
    #[command(
        after_help = "Example: facespace corpus merge out/parts/0 out/parts/1 out/parts/2 -o out/grid/train"
    )]
    Merge(MergeArgs),
}

#[derive(Args)]
pub struct MergeArgs {
    /// The shards' corpus folders.
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// Output corpus folder.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct FromVideosArgs {
    /// The talker's model.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// Folder of recordings and their label files.
    dir: PathBuf,
    /// TextGrid tier to read (default: the tier named "phones" or "phonemes").
    #[arg(long)]
    tier: Option<String>,
    /// Phone-label map (as `codebook build --phone-map`).
    #[arg(long)]
    phone_map: Option<PathBuf>,
    #[command(flatten)]
    tracking: super::TrackingArgs,
    /// Share of recordings that may fail (each is named and left out) before the corpus is
    /// refused.
    #[arg(long, default_value_t = facespace::corpus::DEFAULT_MAX_FAILED)]
    max_failed: f64,
    /// Seconds the labels may end from the video's end (forced-aligner output ends with the
    /// sound, which can outlast the last frame).
    #[arg(long, default_value_t = facespace::corpus::DEFAULT_TOLERANCE)]
    tolerance: f64,
    /// Make only part K of N (0 ≤ K < N) of the corpus: the recordings whose place in name
    /// order is K modulo N — one task of a job array (`corpus merge` joins the parts).
    #[arg(long, default_value = "0/1")]
    shard: facespace::corpus::Shard,
    /// Align transcripts even when their words do not seem to be what is said (by default
    /// such a recording is left out, naming its worst words).
    #[arg(long)]
    accept_mismatch: bool,
    /// Output corpus folder.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct DemoArgs {
    /// The demo model.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// Its training frames with .pts landmarks (the source of the real face-space points;
    /// default: the folder the model was built from, as its model.json records).
    #[arg(long, value_parser = super::committed_path)]
    training: Option<PathBuf>,
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
        CorpusCommand::FromVideos(a) => from_videos(a),
        CorpusCommand::Merge(a) => merge(a),
    }
}

/// The folder `model` was built from (its model.json's sources, all in one folder), where it
/// still exists — relative to the working folder or to the source tree, as the build saw it.
/// A corpus of one talker's model over another talker's frames is refused (issue 33: it
/// used the demo talker's frames whatever the model).
fn own_training(path: &Path, model: &facespace::model::FaceModel) -> Result<PathBuf> {
    let parents: std::collections::BTreeSet<PathBuf> = model
        .source
        .iter()
        .filter_map(|s| Path::new(s).parent().map(Path::to_path_buf))
        .collect();
    let parents: Vec<PathBuf> = parents.into_iter().collect();
    let [folder] = parents.as_slice() else {
        anyhow::bail!(
            "model {}: its training frames are not one folder it records; give --training with the frames it was built from",
            path.display()
        );
    };
    let found = [folder.clone(), Path::new(env!("CARGO_MANIFEST_DIR")).join(folder)]
        .into_iter()
        .find(|p| p.is_dir());
    found.with_context(|| {
        format!(
            "model {} was built from {}, which is not here; give --training with those frames (a corpus over another talker's frames would not be this model's talker)",
            path.display(),
            folder.display()
        )
    })
}

fn generate(a: DemoArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let model = load_model(&a.model)?;
    let training = match &a.training {
        Some(t) => t.clone(),
        None => own_training(&a.model, &model)?,
    };
    let frames = load_training_set(&training, None)
        .with_context(|| format!("loading {}", training.display()))?;
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

fn merge(a: MergeArgs) -> Result<()> {
    let inputs: Vec<&Path> = a.parts.iter().map(PathBuf::as_path).collect();
    super::check_output(&a.output, &inputs)?;
    let (fps, files) = facespace::corpus::merge(&a.parts, &a.output)
        .with_context(|| format!("merging {} corpus parts", a.parts.len()))?;
    println!(
        "{files} files of {} parts at {fps} fps → {}",
        a.parts.len(),
        a.output.display()
    );
    Ok(())
}

fn from_videos(a: FromVideosArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let mut inputs = vec![a.model.as_path(), a.dir.as_path()];
    inputs.extend(a.phone_map.as_deref());
    super::check_output(&a.output, &inputs)?;
    let model = load_model(&a.model)?;
    let options = a.tracking.options(None)?;
    let map = match &a.phone_map {
        Some(p) => facespace::phonemes::PhoneMap::read(p)?,
        None => facespace::phonemes::PhoneMap::default(),
    };
    let (bar, progress) = progress_bar();
    if !(0.0..=1.0).contains(&a.max_failed) {
        anyhow::bail!(
            "--max-failed {} is not a share between 0 and 1",
            a.max_failed
        );
    }
    let made = facespace::corpus::from_recordings(
        &model,
        &a.dir,
        &a.output,
        &options,
        &facespace::corpus::Reading {
            tier: a.tier.clone(),
            map,
            max_failed: a.max_failed,
            tolerance: a.tolerance,
            shard: a.shard,
            accept_mismatch: a.accept_mismatch,
        },
        progress,
    )
    .with_context(|| format!("making a corpus of {}", a.dir.display()))?;
    bar.finish_and_clear();
    let (fps, sentences) = (made.fps, &made.sentences);
    for s in sentences {
        println!(
            "  {}: {} frames, residual mean {:.2}, {} lost{}",
            s.name,
            s.frames,
            s.tracking.mean_error,
            s.tracking.lost,
            if s.audio { ", sound kept" } else { "" }
        );
    }
    for s in &made.skipped {
        println!("  left out {}: {}", s.name, s.reason);
    }
    if !made.skipped.is_empty() {
        println!(
            "{} of {} recordings left out (at most {:.0} % may be; --max-failed)",
            made.skipped.len(),
            made.skipped.len() + sentences.len(),
            a.max_failed * 100.0
        );
    }
    println!(
        "{} sentences at {fps} fps in {:.1} s → {} (next: facespace codebook build --model {} --corpus {} -o CODEBOOK)",
        sentences.len(),
        start.elapsed().as_secs_f64(),
        a.output.display(),
        a.model.display(),
        a.output.display()
    );
    Ok(())
}
