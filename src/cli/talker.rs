//! `facespace talker build`: a talker folder from a model, its codebook and footage clips.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use facespace::talker::build::{Identity, Parts, Recordings, Validation};
use facespace::talker::{Mode, Settings, Voice};

use super::progress_bar;

#[derive(Subcommand)]
pub enum TalkerCommand {
    /// Make a talker folder: the model, the codebook, idle footage tracked, the settings and
    /// the voice. Run again after an interruption: the parts already made are kept.
    #[command(
        after_help = "Example: facespace talker build --model out/model --codebook out/codebook --footage rec/a.mp4 rec/b.mp4 --name me -o out/me"
    )]
    Build(Box<BuildArgs>),
    /// Keep recorded mouths in a talker (or drop them with --frames 0): the mouth is then
    /// drawn with the talker's own teeth, lips and skin over the model's.
    #[command(
        after_help = "Example: facespace talker mouths --talker models/grid --from ../shared/data/grid-s1/clips"
    )]
    Mouths(MouthsArgs),
    /// Learn the talker's map from sound to face, so that `say --audio` without the words
    /// predicts the lips from the sound itself rather than from recognised phones.
    #[command(
        after_help = "Example: facespace talker sound-to-face --talker models/grid --from ../shared/data/grid-s1/clips"
    )]
    SoundToFace(SoundToFaceArgs),
}

#[derive(Args)]
pub struct SoundToFaceArgs {
    /// The talker folder.
    #[arg(long)]
    talker: PathBuf,
    /// The folder of the codebook's recordings (NAME.mp4, with their sound).
    #[arg(long)]
    from: PathBuf,
    /// The least video frames of recordings with sound to learn from (default: about a
    /// minute of speech; a map learnt on less follows the lips worse than recognised phones).
    #[arg(long, default_value_t = facespace::sound_to_face::LEAST_FRAMES)]
    least_frames: usize,
}

#[derive(Args)]
pub struct MouthsArgs {
    /// The talker folder.
    #[arg(long)]
    talker: PathBuf,
    /// The folder of the codebook's recordings (NAME.mp4).
    #[arg(long)]
    from: PathBuf,
    /// About how many recorded frames to keep (0: none).
    #[arg(long, default_value_t = facespace::mouths::DEFAULT_FRAMES)]
    frames: usize,
}

#[derive(Args)]
pub struct BuildArgs {
    /// The talker's model (`model build`; whole-face, or a lower-face region model).
    #[arg(long)]
    model: PathBuf,
    /// The talker's recordings: each NAME.mp4 with its words in NAME.txt (or phone labels
    /// NAME.lab / .TextGrid / .tsv). They become the corpus (kept in the talker's corpus/),
    /// the codebook (appearance re-centred per sentence) and, from the --footage-clips takes
    /// where his head sat as it usually does and alike, the idle footage.
    #[arg(long, conflicts_with_all = ["codebook", "footage", "footage_from"])]
    recordings: Option<PathBuf>,
    /// A codebook built with the model (`codebook build --photometric sentence`), instead of
    /// --recordings.
    #[arg(long, required_unless_present = "recordings")]
    codebook: Option<PathBuf>,
    /// Videos of the talker for the living frame (natural head motion and blinks; together
    /// at least a second, better half a minute).
    #[arg(long, num_args = 1.., required_unless_present_any = ["footage_from", "recordings"])]
    footage: Vec<PathBuf>,
    /// Instead of --footage: a folder of the codebook's recordings (NAME.mp4), from which the
    /// --footage-clips takes are used: the one whose head sat most as it usually does, and
    /// those whose head sat nearest it.
    #[arg(long, conflicts_with = "footage")]
    footage_from: Option<PathBuf>,
    /// Validation sentences of the talker, tracked with the model and not in the codebook (a
    /// `corpus from-videos` folder): blend N and λ are chosen on them (lip motion ≥ 0.9× and
    /// inner-mouth s.d. within 10 % of real, then the best correlated), instead of --top-n and
    /// --smoothing. --recordings keeps every 10th of its own recordings for this.
    #[arg(long, conflicts_with = "recordings")]
    validation: Option<PathBuf>,
    /// A folder of the codebook's recordings (NAME.mp4) to keep recorded mouths from, so the
    /// mouth is drawn with the talker's own teeth and skin (default: --footage-from's folder;
    /// --recordings keeps them from its own).
    #[arg(long, conflicts_with = "recordings")]
    mouths_from: Option<PathBuf>,
    /// About how many recorded frames of mouths to keep (0: none; the model's mouth).
    #[arg(long, default_value_t = facespace::mouths::DEFAULT_FRAMES)]
    mouth_frames: usize,
    /// How many takes --footage-from or --recordings use.
    #[arg(long, default_value_t = 16)]
    footage_clips: usize,
    /// The talker's name.
    #[arg(long)]
    name: String,
    /// What the recordings are (corpus, licence), for the provenance record.
    #[arg(long, default_value = "recordings of the talker")]
    about: String,
    /// Examples blended per phone, N, when no validation sentences choose it.
    #[arg(long, default_value_t = facespace::synth::blend::DEFAULT_TOP_N)]
    top_n: usize,
    /// Context width C.
    #[arg(long, default_value_t = 1)]
    context: usize,
    /// Smoothing weight λ, when no validation sentences choose it.
    #[arg(long, default_value_t = facespace::synth::DEFAULT_SMOOTHING)]
    smoothing: f64,
    /// What the blend's appearance deviations are scaled by (1: as the examples spread);
    /// chosen per talker on its validation sentences (GRID s1's: 1.15, README).
    #[arg(long, default_value_t = 1.0)]
    appearance_gain: f64,
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
        TalkerCommand::Build(a) => build(*a),
        TalkerCommand::Mouths(a) => mouths(a),
        TalkerCommand::SoundToFace(a) => sound_to_face(a),
    }
}

fn sound_to_face(a: SoundToFaceArgs) -> Result<()> {
    let clock = std::time::Instant::now();
    let (bar, progress) = progress_bar();
    let talker = facespace::talker::build::set_sound_to_face(&a.talker, &a.from, a.least_frames, progress)
        .with_context(|| format!("learning the sound-to-face map of {}", a.talker.display()))?;
    bar.finish_and_clear();
    let (sentences, frames) = talker
        .sound_to_face()?
        .map(|m| m.learnt_from())
        .unwrap_or_default();
    println!(
        "{}: the face learnt from the sound of {sentences} sentences ({frames} frames) in {:.1} s",
        a.talker.display(),
        clock.elapsed().as_secs_f64()
    );
    Ok(())
}

fn mouths(a: MouthsArgs) -> Result<()> {
    let clock = std::time::Instant::now();
    let (bar, progress) = progress_bar();
    let talker = facespace::talker::build::set_mouths(&a.talker, &a.from, a.frames, progress)
        .with_context(|| format!("recorded mouths for {}", a.talker.display()))?;
    bar.finish_and_clear();
    match talker.mouths()? {
        Some(m) => println!(
            "{}: {} recorded mouths kept from {} sentences in {:.1} s",
            a.talker.display(),
            m.len(),
            m.stretches.len(),
            clock.elapsed().as_secs_f64()
        ),
        None => println!("{}: draws the model's mouth", a.talker.display()),
    }
    Ok(())
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
            appearance_gain: a.appearance_gain,
            chosen_on: a.chosen_on.clone(),
        },
        voice,
        recordings: a.about.clone(),
    };
    // Before any work: settings no synthesis can use are refused here, not after minutes.
    identity.settings.check("--", '-')?;
    let clock = std::time::Instant::now();
    let (bar, mut progress) = progress_bar();
    let parts = match (&a.recordings, &a.codebook) {
        (Some(dir), _) => facespace::talker::build::parts_from_recordings(
            &Recordings {
                model: a.model.clone(),
                dir: dir.clone(),
                footage_clips: a.footage_clips,
            },
            &a.output,
            &mut progress,
        )
        .map(|p| Parts {
            mouth_frames: a.mouth_frames,
            ..p
        })?,
        (None, Some(codebook)) => {
            let model = super::load_model(&a.model)?;
            let cb = facespace::codebook::Codebook::load(codebook)
                .with_context(|| format!("loading codebook {}", codebook.display()))?;
            Parts {
                model: a.model.clone(),
                codebook: codebook.clone(),
                footage: match &a.footage_from {
                    Some(dir) => {
                        let names = facespace::footage::footage_takes(
                            &model,
                            &cb,
                            a.footage_clips,
                        )?;
                        facespace::footage::take_videos(dir, &names)
                            .with_context(|| format!("--footage-from {}", dir.display()))?
                    }
                    None => a.footage.clone(),
                },
                validation: match &a.validation {
                    Some(dir) => Some(Validation::load(dir, &model, cb.fps)?),
                    None => None,
                },
                mouths_from: a.mouths_from.clone().or(a.footage_from.clone()),
                mouth_frames: a.mouth_frames,
            }
        }
        (None, None) => anyhow::bail!("give --recordings, or --codebook with --footage"),
    };
    let talker = facespace::talker::build::build(&identity, &parts, &a.output, progress)?;
    bar.finish_and_clear();
    println!("settings: {}", talker.manifest.settings.chosen_on);
    let (phones, shapes) = talker.codebook.absent();
    let names = |ps: &[facespace::phonemes::Phone]| ps.iter().map(|p| p.name()).collect::<Vec<_>>().join(" ");
    if !phones.is_empty() {
        let shapes: Vec<String> = shapes.iter().map(|c| format!("/{}/", names(c))).collect();
        println!(
            "the recordings never say {}{}: their lips are borrowed from the nearest phones present (record sentences with them to complete the talker)",
            names(&phones),
            if shapes.is_empty() { String::new() } else { format!(" — no mouth shape of {}", shapes.join(", ")) }
        );
    }
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
