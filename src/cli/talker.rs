//! `facespace talker build`: a talker folder from a model, its codebook and footage clips.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use facespace::talker::build::{Identity, Parts};
use facespace::talker::{Mode, Settings, Voice};

use super::progress_bar;

#[derive(Subcommand)]
pub enum TalkerCommand {
    /// Make a talker folder: the model, the codebook, idle footage tracked, the settings and
    /// the voice. Run again after an interruption: the parts already made are kept.
    #[command(
        after_help = "Example: facespace talker build --model out/model --codebook out/codebook --footage rec/a.mp4 rec/b.mp4 --name me -o out/me"
    )]
    Build(BuildArgs),
}

#[derive(Args)]
pub struct BuildArgs {
    /// The whole-face model (`model build`).
    #[arg(long)]
    model: PathBuf,
    /// A codebook built with it (`codebook build --photometric sentence`).
    #[arg(long)]
    codebook: PathBuf,
    /// Videos of the talker for the living frame (natural head motion and blinks; together
    /// at least a second, better half a minute).
    #[arg(long, num_args = 1.., required_unless_present = "footage_from")]
    footage: Vec<PathBuf>,
    /// Instead of --footage: a folder of the codebook's recordings (NAME.mp4), from which the
    /// --footage-clips takes whose head sat most alike are used.
    #[arg(long, conflicts_with = "footage")]
    footage_from: Option<PathBuf>,
    /// How many takes --footage-from uses.
    #[arg(long, default_value_t = 16)]
    footage_clips: usize,
    /// The talker's name.
    #[arg(long)]
    name: String,
    /// What the recordings are, for the provenance record.
    #[arg(long, default_value = "recordings of the talker")]
    recordings: String,
    /// Examples blended per phone, N (chosen on validation: `eval --validation`).
    #[arg(long, default_value_t = facespace::synth::blend::DEFAULT_TOP_N)]
    top_n: usize,
    /// Context width C.
    #[arg(long, default_value_t = 1)]
    context: usize,
    /// Smoothing weight λ.
    #[arg(long, default_value_t = facespace::synth::DEFAULT_SMOOTHING)]
    smoothing: f64,
    /// Where the settings were chosen, in words.
    #[arg(long, default_value = "facespace's defaults (GRID s1's validation split)")]
    chosen_on: String,
    /// The Festival voice for speech from text, and the package that installs it
    /// (VOICE:PACKAGE, e.g. kal_diphone:festvox-kallpc16k).
    #[arg(long)]
    voice: Option<String>,
    /// The talker folder.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(command: TalkerCommand) -> Result<()> {
    match command {
        TalkerCommand::Build(a) => build(a),
    }
}

fn build(a: BuildArgs) -> Result<()> {
    let voice = match &a.voice {
        Some(v) => {
            let (festival, package) = v.split_once(':').with_context(|| {
                format!("--voice {v:?}: expected VOICE:PACKAGE (kal_diphone:festvox-kallpc16k)")
            })?;
            Some(Voice {
                festival: festival.into(),
                package: package.into(),
            })
        }
        None => None,
    };
    let identity = Identity {
        name: a.name.clone(),
        settings: Settings {
            mode: Mode::Blend,
            top_n: a.top_n,
            context: a.context,
            smoothing: a.smoothing,
            chosen_on: a.chosen_on.clone(),
        },
        voice,
        recordings: a.recordings.clone(),
    };
    let footage = match &a.footage_from {
        Some(dir) => {
            let model = super::load_model(&a.model)?;
            let codebook = facespace::codebook::Codebook::load(&a.codebook)
                .with_context(|| format!("loading codebook {}", a.codebook.display()))?;
            let names = facespace::talker::footage::closest_takes(&model, &codebook, a.footage_clips)?;
            names
                .iter()
                .map(|n| {
                    let video = dir.join(format!("{n}.mp4"));
                    anyhow::ensure!(
                        video.is_file(),
                        "--footage-from {}: no {n}.mp4 (the codebook's sentence {n})",
                        dir.display()
                    );
                    Ok(video)
                })
                .collect::<Result<Vec<_>>>()?
        }
        None => a.footage.clone(),
    };
    let parts = Parts {
        model: a.model.clone(),
        codebook: a.codebook.clone(),
        footage,
    };
    let clock = std::time::Instant::now();
    let (bar, progress) = progress_bar();
    let talker = facespace::talker::build::build(&identity, &parts, &a.output, progress)?;
    bar.finish_and_clear();
    let f = &talker.footage;
    println!(
        "talker {} → {} in {:.1} s: {} codebook sentences; footage {} clips, {} frames ({:.1} s, median step {:.2} grey levels)",
        talker.manifest.name,
        a.output.display(),
        clock.elapsed().as_secs_f64(),
        talker.codebook.sentences.len(),
        f.clips.len(),
        f.len(),
        f.len() as f64 / f.fps,
        f.median_step()
    );
    Ok(())
}
