//! `facespace codebook build | info | similarity`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::phonemes::{PHONES, PhoneMap};
use facespace::{plot, video};

use super::{load_model, progress_bar};

#[derive(Subcommand)]
pub enum CodebookCommand {
    /// Build a codebook from face-space trajectories (.npy) with phone labels of the same name.
    #[command(
        after_help = "Example: facespace codebook build --model models/demo/model --corpus out/corpus/train -o out/codebook"
    )]
    Build(BuildArgs),
    /// Sentences, frames, phone counts and the three most similar phones of each.
    #[command(after_help = "Example: facespace codebook info models/grid/codebook")]
    Info {
        /// Codebook folder.
        codebook: PathBuf,
    },
    /// Write the phoneme similarity matrix S as a heat map.
    #[command(
        after_help = "Example: facespace codebook similarity models/grid/codebook -o out/similarity.png"
    )]
    Similarity {
        /// Codebook folder.
        codebook: PathBuf,
        /// Output PNG (`--png`, its old name, still works).
        #[arg(short = 'o', long = "output", alias = "png")]
        png: PathBuf,
    },
}

#[derive(Args)]
pub struct BuildArgs {
    /// The face model the trajectories belong to.
    #[arg(long)]
    model: PathBuf,
    /// Folder of NAME.npy (frames × face-space dims) with NAME.lab / NAME.TextGrid / NAME.tsv.
    #[arg(long)]
    corpus: PathBuf,
    /// Frame rate of the trajectories (default: the corpus's `corpus.json`, else 25).
    #[arg(long)]
    fps: Option<f64>,
    /// Seconds each sentence's labels may end from its frames' end.
    #[arg(long, default_value_t = facespace::corpus::DEFAULT_TOLERANCE)]
    tolerance: f64,
    /// TextGrid tier to read (default: "phones" or "phonemes").
    #[arg(long)]
    tier: Option<String>,
    /// Two-column file mapping another phone set's labels to ARPAbet.
    #[arg(long)]
    phone_map: Option<PathBuf>,
    /// γ of S = exp(−γ D) (default: 1 / median distance).
    #[arg(long)]
    gamma: Option<f64>,
    /// Photometric normalisation: `sentence` re-centres each sentence's appearance on the
    /// corpus mean (lighting that drifts between recording sessions stops jumping at joins).
    /// Not the default: a re-centred codebook draws the corpus's mean lighting unless the
    /// synthesis is re-lit to a background take tracked with the same model (`say` over a
    /// talker's footage, `synth --background` with that model), so it suits recordings made
    /// over several sessions (GRID s1's), not one take or a generated corpus.
    #[arg(long, value_enum, default_value_t = PhotometricArg::None)]
    photometric: PhotometricArg,
    /// Output codebook folder.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PhotometricArg {
    /// The appearance as tracked.
    None,
    /// Each sentence's mean appearance replaced by the corpus mean.
    Sentence,
}

pub fn run(command: CodebookCommand) -> Result<()> {
    match command {
        CodebookCommand::Build(a) => build(a),
        CodebookCommand::Info { codebook } => {
            info(&load(&codebook)?);
            Ok(())
        }
        CodebookCommand::Similarity { codebook, png } => {
            super::check_output(&png, &[&codebook])?;
            similarity_png(&load(&codebook)?, &png)
        }
    }
}

fn load(dir: &Path) -> Result<Codebook> {
    Codebook::load(dir).with_context(|| format!("loading codebook {}", dir.display()))
}

fn build(a: BuildArgs) -> Result<()> {
    let mut inputs = vec![a.model.as_path(), a.corpus.as_path()];
    inputs.extend(a.phone_map.as_deref());
    super::check_output(&a.output, &inputs)?;
    let start = std::time::Instant::now();
    let model = load_model(&a.model)?;
    let map = match &a.phone_map {
        Some(p) => PhoneMap::read(p)?,
        None => PhoneMap::default(),
    };
    let options = SimilarityOptions {
        gamma: a.gamma,
        ..SimilarityOptions::default()
    };
    let recorded = facespace::corpus::recorded_fps(&a.corpus)?;
    let fps = match (a.fps, recorded) {
        (Some(given), Some(r)) if (given - r).abs() > 1e-9 => anyhow::bail!(
            "--fps {given}, but {} records {r} fps: leave --fps out",
            a.corpus.join(facespace::corpus::MANIFEST).display()
        ),
        (Some(given), _) => given,
        (None, Some(r)) => r,
        (None, None) => {
            eprintln!(
                "note: {} has no {}: its frames are taken to be at 25 fps (--fps sets it)",
                a.corpus.display(),
                facespace::corpus::MANIFEST
            );
            25.0
        }
    };
    let (bar, mut progress) = progress_bar();
    let cb = Codebook::from_corpus(
        &a.corpus,
        &model,
        fps,
        a.tier.as_deref(),
        &map,
        options,
        match a.photometric {
            PhotometricArg::None => facespace::corpus::Photometric::None,
            PhotometricArg::Sentence => facespace::corpus::Photometric::Sentence,
        },
        a.tolerance,
        &mut progress,
    )
    .with_context(|| {
        format!(
            "building a codebook from {} with model {} (the corpus must have been tracked with that model)",
            a.corpus.display(),
            a.model.display()
        )
    })?;
    bar.finish_and_clear();
    cb.save(&a.output)
        .with_context(|| format!("saving codebook {}", a.output.display()))?;
    println!(
        "built {} in {:.2} s",
        a.output.display(),
        start.elapsed().as_secs_f64()
    );
    info(&cb);
    Ok(())
}

fn info(cb: &Codebook) {
    let frames = cb.n_frames();
    println!("  sentences   {}", cb.sentences.len());
    println!(
        "  frames      {frames} at {} fps ({:.1} s)",
        cb.fps,
        frames as f64 / cb.fps
    );
    println!(
        "  face-space  {} values {}, model {}",
        cb.dims(),
        cb.layout,
        cb.model_hash.as_deref().unwrap_or("unknown")
    );
    let (absent, _) = cb.absent();
    if !absent.is_empty() {
        let names: Vec<&str> = absent.iter().map(|p| p.name()).collect();
        println!("  absent      {}", names.join(" "));
    }
    // S without the shape parameters, to show what shape changes.
    let without = Codebook {
        similarity: cb.similarity_with(&SimilarityOptions {
            use_shape: false,
            ..cb.options.clone()
        }),
        ..cb.clone()
    };
    println!(
        "  phone  count  mean ms  {:<34} without shape",
        "most similar (S)"
    );
    let durations = cb.mean_durations();
    let near = |cb: &Codebook, p| -> String {
        cb.nearest(p, 3)
            .iter()
            .map(|(q, s)| format!("{q} {s:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    for p in cb.present() {
        let (with, alone) = (near(cb, p), near(&without, p));
        println!(
            "  {:<5} {:>6} {:>8.0}  {with:<34} {}",
            p.name(),
            cb.occurrences[p.index()].len(),
            1000.0 * durations[p.index()],
            if alone == with {
                "(same)".into()
            } else {
                alone
            }
        );
    }
}

fn similarity_png(cb: &Codebook, png: &Path) -> Result<()> {
    let present = cb.present();
    let labels: Vec<&str> = present.iter().map(|p| PHONES[p.index()]).collect();
    let values: Vec<f64> = present
        .iter()
        .flat_map(|a| present.iter().map(move |b| cb.similarity(*a, *b)))
        .collect();
    let img = plot::heat_map(&values, &labels, "phoneme similarity S");
    video::write_png(png, &img)?;
    println!("wrote {} ({} phones)", png.display(), present.len());
    Ok(())
}
