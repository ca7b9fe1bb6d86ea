//! `facespace synth`: blend synthesis with smoothing on, off or A/B.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use facespace::codebook::Codebook;
use facespace::codec::EncodeOptions;
use facespace::phonemes::{self, PhoneMap};
use facespace::render::{Background, DEFAULT_FEATHER, Edge};
use facespace::synth::Synthesiser;
use facespace::synth::backdrop::{Backdrop, PoseMode};
use facespace::synth::blend::Blend;
use facespace::synth::graph::Graph;
use facespace::synth::output::{self, OutputOptions};
use facespace::synth::unit::{UnitSelection, WeightsFile};
use facespace::synth::{self, DEFAULT_SMOOTHING, Pose, Request, Smoothing, synthesise};
use facespace::talker::{Canvas, Method, Real, SayRequest, Speech, Talker};
use facespace::{align, audio, corpus, video};

/// Whether a background path is a single image (else a video or frame folder).
fn is_image(path: &std::path::Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| video::IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

use super::{RendererArg, load_model, progress_bar};

/// What to do when the background's face is lost: it is tracked with --model (or its
/// whole-face tracker), which may be of someone else.
const BACKGROUND_REMEDY: &str = "the background is tracked with --model; for a background of another talker give a model of theirs with --track-model MODEL, or use a background of the codebook's talker";

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Smooth {
    On,
    Off,
    /// Both, plus a blind side-by-side and a comparison plot.
    Ab,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Mode {
    /// Top-N context blending.
    Blend,
    /// Frame-level unit selection (Viterbi over codebook frames).
    Unit,
    /// The dynamic-phoneme graph.
    Graph,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PoseArg {
    Hold,
    Replay,
}

#[derive(Args)]
pub struct SynthArgs {
    /// The face model the codebook was built with (default: found by the model hash the
    /// codebook records — the model/ beside it, then the committed models — else the demo
    /// model, models/demo/model).
    #[arg(long)]
    model: Option<PathBuf>,
    /// A talker folder (`talker build`), drawn as `say` draws it (its recorded mouths, voice,
    /// ear and word check; over its idle footage unless --background is given), its settings
    /// (N, C, λ) overridden by the flags. Without it and without --codebook, the default
    /// talker (`models/grid`, as `say`).
    #[arg(long, conflicts_with_all = ["model", "codebook", "track_model"])]
    talker: Option<PathBuf>,
    /// With a talker: draw the appearance model's mouth even where it keeps recorded mouths
    /// (the A/B baseline).
    #[arg(long)]
    model_mouth: bool,
    /// The codebook to synthesise from (`codebook build`; default: the talker's).
    #[arg(long)]
    codebook: Option<PathBuf>,
    /// Phone timings (.lab, .TextGrid, .tsv).
    #[arg(long, conflicts_with_all = ["text", "transcript", "say"], required_unless_present_any = ["text", "transcript", "say", "audio"])]
    labels: Option<PathBuf>,
    /// Text to speak. With --audio, the words of that recording, aligned to it; alone, phone
    /// durations come from the codebook (CMU dictionary).
    #[arg(long, conflicts_with_all = ["transcript", "say"])]
    text: Option<String>,
    /// A text file with the words of the --audio recording, aligned to it.
    #[arg(long, requires = "audio", conflicts_with = "say")]
    transcript: Option<PathBuf>,
    /// Text for a text-to-speech engine (Festival, else espeak-ng): its speech is aligned,
    /// drives the face, and is muxed into the video.
    #[arg(long, conflicts_with = "audio")]
    say: Option<String>,
    /// Extra pronunciations for the aligner (`WORD  P H O N E S` lines); may repeat.
    #[arg(long = "dict")]
    dicts: Vec<PathBuf>,
    /// TextGrid tier of --labels to read (default: the tier named "phones" or "phonemes").
    #[arg(long)]
    tier: Option<String>,
    /// Two-column file mapping another phone set's labels (of --labels) to ARPAbet.
    #[arg(long)]
    phone_map: Option<PathBuf>,
    /// How to synthesise.
    #[arg(long, value_enum, default_value_t = Mode::Blend)]
    mode: Mode,
    /// Which renderer draws the faces.
    #[arg(long, value_enum, default_value_t)]
    renderer: RendererArg,
    /// Unit-selection weights and constants (a `train-weights` file; default: all weights 1,
    /// [unitsel]'s constants).
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Context width C (default: the talker's, else 1).
    #[arg(long)]
    context: Option<usize>,
    /// Examples blended per phone, N (default: the talker's, else 5 — chosen on GRID s1's
    /// validation split).
    #[arg(long)]
    top_n: Option<usize>,
    /// Blend by the plain weighted average, without restoring the examples' spread (the
    /// motion then shrinks with N).
    #[arg(long)]
    plain_average: bool,
    /// Smoothing spline on, off, or both for a blind A/B side-by-side.
    #[arg(long, value_enum, default_value_t = Smooth::On)]
    smooth: Smooth,
    /// Smoothing weight λ of the cubic smoothing spline (default: the talker's, else 3e-5 —
    /// chosen on GRID s1's validation split).
    #[arg(long)]
    smoothing: Option<f64>,
    /// Output frame rate (default: the background video's, else the codebook's).
    #[arg(long)]
    fps: Option<f64>,
    /// Background to draw the face on: an image, or a video (any format `track` reads) whose
    /// frames play under the face (default: plain grey at the codebook's median pose).
    #[arg(long)]
    background: Option<PathBuf>,
    /// Where the pose comes from with a background video: replay its tracked poses frame by
    /// frame (a video shorter than the speech extended by joining its stretches where they
    /// match, never backwards), or hold its first frame still. A background
    /// image always lends its own pose.
    #[arg(long, value_enum, default_value_t = PoseArg::Replay)]
    pose: PoseArg,
    /// The model that finds and tracks the face in the background (default: --model, which
    /// tracks with its whole-face tracker when it is a region model built by `model build
    /// --region`).
    #[arg(long)]
    track_model: Option<PathBuf>,
    /// A real trajectory (.npy) of the same utterance, plotted against the synthesis.
    #[arg(long)]
    real: Option<PathBuf>,
    /// Seed of the blind A/B order.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Refuse a phone the codebook lacks instead of borrowing the nearest one present (its
    /// viseme class, else the nearest class by mouth shape), which is otherwise done with a
    /// warning naming both.
    #[arg(long)]
    strict: bool,
    /// Also write beside_background.mp4: the background as it is (over a sentence's own
    /// video, the real recording) beside the synthesis drawn on it.
    #[arg(long, requires = "background")]
    beside_background: bool,
    /// Speech to drive the face and mux into the MP4s: WAV or MP4/M4A (AAC), other formats
    /// through a system ffmpeg. With --text or --transcript it is aligned to those words
    /// (refused when they do not seem to be what is said); with --labels the labels time the
    /// face; alone, its phones are recognised from the sound.
    #[arg(long)]
    audio: Option<PathBuf>,
    /// Use the words of --audio even when they do not seem to be what is said.
    #[arg(long, requires = "audio")]
    accept_mismatch: bool,
    /// Output folder (written whole, never over a folder facespace did not write).
    #[arg(short, long)]
    output: PathBuf,
}

/// The model `codebook` (read from `path`) was built with, found by the hash it records: the
/// `model/` beside the codebook (a talker folder's, say), then the committed models; loaded.
fn model_of(
    path: &std::path::Path,
    codebook: &Codebook,
) -> Option<(PathBuf, facespace::model::FaceModel)> {
    let hash = codebook.model_hash.as_ref()?;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let mut candidates: Vec<PathBuf> = path
        .parent()
        .map(|p| vec![p.join("model"), p.join("lower")])
        .unwrap_or_default();
    for talker in ["grid", "demo"] {
        candidates.push(root.join(talker).join("model"));
    }
    candidates.push(root.join("grid/lower"));
    facespace::model::FaceModel::find_by_hash(hash, &candidates)
}

pub fn run(mut a: SynthArgs) -> Result<()> {
    if a.talker.is_none() && a.codebook.is_none() {
        a.talker = Some(super::committed_path(super::say::DEFAULT_TALKER)?);
    }
    match a.talker.clone() {
        Some(talker) => with_talker(a, &talker),
        None => from_codebook(a),
    }
}

/// `synth --talker T`: the talker's own pipeline ([`Talker::say_parts`], as `say` draws —
/// recorded mouths, appearance gain, ear, word check), varied by the flags.
fn with_talker(a: SynthArgs, dir: &std::path::Path) -> Result<()> {
    // (With --talker given, clap refuses these; with the default talker, this does.)
    for (given, flag) in [(&a.model, "--model"), (&a.track_model, "--track-model")] {
        if given.is_some() {
            anyhow::bail!(
                "{flag} with --talker: a talker draws with its own model and codebook; give --codebook (and --model) without --talker to synthesise from another codebook"
            );
        }
    }
    let talker = Talker::load(dir).with_context(|| format!("loading the talker {}", super::shown(dir)))?;
    let settings = &talker.manifest.settings;
    let speech = match (&a.say, &a.text, &a.audio) {
        (Some(text), ..) => Speech::Text(text.clone()),
        // Words without a recording: durations from the codebook, silent.
        (None, Some(text), None) if a.labels.is_none() => Speech::Phones {
            phones: phonemes::text_to_segments(text, &talker.codebook.mean_durations())?,
            audio: None,
        },
        _ => super::speech_of(
            a.labels.as_deref(),
            a.tier.as_deref(),
            a.phone_map.as_deref(),
            a.audio.as_deref(),
            a.text.as_deref(),
            a.transcript.as_deref(),
        )?
        .context("give --labels, --text, --transcript, --audio or --say")?,
    };
    let blend = Blend {
        context: a.context.unwrap_or(settings.context),
        top_n: a.top_n.unwrap_or(settings.top_n),
        preserve_variance: !a.plain_average,
        appearance_gain: settings.appearance_gain,
    };
    let lambda = a.smoothing.unwrap_or(settings.smoothing);
    facespace::talker::Settings { top_n: blend.top_n, context: blend.context, smoothing: lambda, ..settings.clone() }
        .check("--", '-')?;
    let request = SayRequest {
        dicts: a.dicts.clone(),
        renderer: a.renderer.choice(),
        seed: a.seed,
        accept_mismatch: a.accept_mismatch,
        model_mouth: a.model_mouth,
        canvas: match &a.background {
            None => Canvas::Footage,
            Some(p) if is_image(p) => Canvas::Image(p.clone()),
            Some(p) => Canvas::Video { path: p.clone(), pose: pose_mode(a.pose) },
        },
        method: Some(match a.mode {
            Mode::Blend => Method::Blend(blend),
            Mode::Unit => Method::Unit(match &a.weights {
                Some(p) => WeightsFile::read(p)?.unit_selection(),
                None => UnitSelection::default(),
            }),
            Mode::Graph => Method::Graph(Graph::default()),
        }),
        smoothing: Some(smoothing(a.smooth, lambda)),
        fps: a.fps,
        strict: a.strict,
        real: a.real.clone().map_or(Real::None, Real::File),
        beside_background: a.beside_background,
        ..SayRequest::new(speech)
    };
    let clock = std::time::Instant::now();
    let (bar, progress) = progress_bar();
    let (said, report) = talker
        .say_parts(&request, &a.output, progress)
        .map_err(|e| match (&e, &a.background) {
            (facespace::talker::TalkerError::Backdrop(_), Some(p)) => {
                super::tracking_context("background", p, BACKGROUND_REMEDY)(e.into())
            }
            _ => anyhow::Error::from(e),
        })
        .with_context(|| format!("{} synthesising into {}", talker.manifest.name, a.output.display()))?;
    bar.finish_and_clear();
    for note in &said.notes {
        println!("note: {note}");
    }
    println!(
        "synthesised {} phones, {} frames at {} fps in {:.1} s ({}; pose {}; {}) → {}",
        said.phones,
        report.frames,
        said.fps,
        clock.elapsed().as_secs_f64(),
        report.method,
        report.pose,
        said.renderer,
        a.output.display()
    );
    list_written(&a.output);
    Ok(())
}

fn pose_mode(pose: PoseArg) -> PoseMode {
    match pose {
        PoseArg::Hold => PoseMode::Hold,
        PoseArg::Replay => PoseMode::Replay,
    }
}

fn smoothing(smooth: Smooth, lambda: f64) -> Smoothing {
    match smooth {
        Smooth::On => Smoothing::On(lambda),
        Smooth::Off => Smoothing::Off,
        Smooth::Ab => Smoothing::Ab(lambda),
    }
}

/// What a synthesis folder holds, for the user.
fn list_written(dir: &std::path::Path) {
    let mut written: Vec<String> = std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| !n.starts_with('.'))
                .collect()
        })
        .unwrap_or_default();
    written.sort();
    println!("wrote to {}: {}", dir.display(), written.join(", "));
}

/// `synth --codebook CB`: a codebook with no talker (no footage, recorded mouths or ear), drawn
/// on plain grey or over a background.
fn from_codebook(a: SynthArgs) -> Result<()> {
    let top_n = a.top_n.unwrap_or(facespace::synth::blend::DEFAULT_TOP_N);
    let context = a.context.unwrap_or(1);
    let lambda = a.smoothing.unwrap_or(DEFAULT_SMOOTHING);
    let codebook_path = a
        .codebook
        .clone()
        .context("give --codebook (or --talker)")?;
    let cb = Codebook::load(&codebook_path)
        .with_context(|| format!("loading codebook {}", codebook_path.display()))?;
    // Without --model, the one the codebook records (loaded once, here).
    let found = match &a.model {
        Some(_) => None,
        None => model_of(&codebook_path, &cb),
    };
    let model_path = a
        .model
        .clone()
        .or_else(|| found.as_ref().map(|(p, _)| p.clone()))
        .unwrap_or_else(|| PathBuf::from(super::DEMO_MODEL));
    let mut inputs = vec![model_path.as_path(), codebook_path.as_path()];
    for p in [
        &a.labels,
        &a.transcript,
        &a.phone_map,
        &a.weights,
        &a.background,
        &a.track_model,
        &a.real,
        &a.audio,
    ] {
        inputs.extend(p.as_deref());
    }
    inputs.extend(a.dicts.iter().map(|d| d.as_path()));
    super::check_output(&a.output, &inputs)?;
    let model = match found {
        Some((_, model)) => model,
        None => load_model(&model_path)?,
    };
    cb.check_model(&model).with_context(|| match &a.model {
        Some(m) => format!("codebook {} and model {}", codebook_path.display(), m.display()),
        None => format!(
            "codebook {}: you gave no --model, none beside it or committed has the model hash it records, and the default is the demo model ({}); give the model the codebook was built with",
            codebook_path.display(),
            super::shown(&model_path)
        ),
    })?;
    // Speech from text: the engine's text and WAV live in a locked staging folder beside the
    // output until the MP4s have them — removed when done, and by the next run if this one
    // is killed (never left in /tmp).
    let spoken = match &a.say {
        Some(_) => Some(
            facespace::atomic::StagingDir::new(facespace::atomic::parent_of(&a.output))
                .context("a staging folder for the speech")?,
        ),
        None => None,
    };
    let speech = match (&a.say, &spoken) {
        (Some(text), Some(spoken)) => {
            let wav = spoken.path().join("speech.wav");
            // Words the aligner cannot time are refused before any engine runs.
            facespace::tts::check_text(text).context("--say")?;
            let text = &facespace::phonemes::spoken::written_out(text);
            facespace::tts::check_text(text).context("--say")?;
            facespace::align::Aligner::load_default(&a.dicts)?
                .phone_count(text)
                .context("--say")?;
            let spoken = facespace::tts::speak_as(text, &wav, None).context("--say")?;
            if let Some(note) = &spoken.note {
                eprintln!("note: {note}");
            }
            println!("speech by {} ({}) → aligned", spoken.engine.name(), spoken.voice);
            Some(wav)
        }
        _ => a.audio.clone(),
    };
    let words = match (&a.say, &a.text, &a.transcript) {
        (Some(t), ..) => Some(t.clone()),
        (None, Some(t), _) if a.audio.is_some() => Some(t.clone()),
        (None, None, Some(p)) => Some(
            facespace::safe_read::read_regular_string(p)
                .with_context(|| format!("reading the transcript {}", p.display()))?,
        ),
        _ => None,
    };
    let target = match (&a.labels, &words, &speech) {
        (Some(path), ..) => {
            let map = match &a.phone_map {
                Some(p) => PhoneMap::read(p)?,
                None => PhoneMap::default(),
            };
            phonemes::read_labels(path, a.tier.as_deref(), &map)?
        }
        (None, words, Some(sound)) => {
            let aligner = facespace::align::Aligner::load_default(&a.dicts)?;
            let heard = audio::read(sound, align::frontend::SAMPLE_RATE, align::MAX_SECONDS)
                .map_err(align::AlignError::from)
                .and_then(|s| {
                    aligner.hear(&s.samples, s.rate, words.as_deref(), a.accept_mismatch || a.say.is_some())
                })
                .with_context(|| format!("the speech {}", sound.display()))?;
            if words.is_none() {
                eprintln!("note: no words given: the phones were recognised from the sound alone (give --text or --transcript for aligned phones and a closer lip sync)");
            }
            align::segments(&heard)
        }
        (None, None, None) => match &a.text {
            Some(text) => phonemes::text_to_segments(text, &cb.mean_durations())?,
            None => anyhow::bail!("give --labels, --text, --transcript or --say"),
        },
        (None, Some(_), None) => unreachable!("words without speech come from --text alone"),
    };
    // Checked here, before any work, so the message names where the phones came from.
    let source = match (&a.labels, &a.say, &speech) {
        (Some(p), ..) => p.display().to_string(),
        (None, Some(_), _) => "--say".to_owned(),
        (None, None, Some(s)) if words.is_some() => format!("the alignment of {}", s.display()),
        (None, None, Some(s)) => format!("the phones recognised in {}", s.display()),
        _ => "--text".to_owned(),
    };
    let fps = match (a.fps, &a.background) {
        (Some(f), _) => f,
        (None, Some(p)) if !is_image(p) => {
            video::Source::open(p)
                .with_context(|| format!("background {}", p.display()))?
                .info()
                .fps
        }
        _ => cb.fps,
    };
    synth::validate_request(&target, fps)
        .with_context(|| format!("the phones of {source} at {fps} fps"))?;
    let real = match &a.real {
        Some(p) => Some(corpus::read_frames(p, model.layout(), fps)?),
        None => None,
    };
    let smoothing = smoothing(a.smooth, lambda);
    let synthesiser: Box<dyn Synthesiser> = match a.mode {
        Mode::Blend => Box::new(Blend {
            context,
            top_n,
            preserve_variance: !a.plain_average,
            appearance_gain: 1.0,
        }),
        Mode::Unit => Box::new(match &a.weights {
            Some(p) => WeightsFile::read(p)?.unit_selection(),
            None => UnitSelection::default(),
        }),
        Mode::Graph => Box::new(Graph::default()),
    };
    let frames = synth::frame_count(&target, fps);
    // Sound far longer than the phones is refused now, before any tracking or rendering.
    if let Some(sound) = &speech {
        output::check_sound(sound, frames as f64 / fps)?;
    }
    let tracker = match &a.track_model {
        Some(p) => Some(load_model(p)?),
        None => None,
    };
    let tracker = tracker.as_ref().unwrap_or(&model);
    if a.track_model.is_some() && tracker.tracker().hash() != model.tracker().hash() {
        eprintln!(
            "note: --track-model is not the model of the codebook's talker: the face synthesised for the codebook's talker is drawn over the background's face — a face swap, not that person speaking"
        );
    }
    let backdrop = match &a.background {
        Some(p) if is_image(p) => {
            Some(Backdrop::still(tracker, p).map_err(|e| {
                super::tracking_context("background", p, BACKGROUND_REMEDY)(e.into())
            })?)
        }
        Some(p) => {
            let (bar, progress) = progress_bar();
            let b = Backdrop::video(
                tracker,
                p,
                pose_mode(a.pose),
                frames,
                &EncodeOptions::default(),
                progress,
            )
            .map_err(|e| super::tracking_context("background", p, BACKGROUND_REMEDY)(e.into()))?;
            bar.finish_and_clear();
            Some(b)
        }
        None => None,
    };
    let request = Request::new(target, fps, smoothing);
    let clock = std::time::Instant::now();
    let utterance = match &backdrop {
        Some(b) => b.synthesise(synthesiser.as_ref(), &cb, &model, request)?,
        None => synthesise(synthesiser.as_ref(), &cb, Request { pose: Pose::Codebook, ..request })?,
    };
    let borrowed: Vec<String> = utterance
        .synthesis
        .phones
        .iter()
        .filter(|p| p.used != p.phone)
        .map(|p| {
            format!(
                "/{}/ at {:.2} s (nearest present: /{}/)",
                p.phone, p.start, p.used
            )
        })
        .collect();
    if a.strict && !borrowed.is_empty() {
        anyhow::bail!(
            "--strict: the codebook {} has no example of {}; build it from sentences that have them, or drop --strict to borrow the nearest phones",
            codebook_path.display(),
            borrowed.join(", ")
        );
    }
    let synth_ms = clock.elapsed().as_secs_f64() * 1e3;
    // Over a real face only the lips and jaw are drawn: the eyes stay the frame's own.
    let edge = match backdrop {
        Some(_) => Edge::Articulators(DEFAULT_FEATHER),
        None => Edge::Feathered(DEFAULT_FEATHER),
    };
    let background = match backdrop {
        Some(b) => b.background()?,
        None => {
            let region = if model.region.is_some() {
                "; this is a region model, so only its region is drawn, floating on grey"
            } else {
                ""
            };
            eprintln!(
                "warning: no --background: the face is drawn on plain grey at the codebook's median pose{region}; give --background VIDEO (or an image) of the talker for a real frame"
            );
            Background::plain_for(&model, &utterance.synthesis.frames)
        }
    };
    let renderer = a.renderer.make(&model, edge)?;
    let (bar, progress) = progress_bar();
    bar.set_prefix(format!("{} · ", renderer.describe()));
    let report = output::write_folder(
        &a.output,
        renderer.as_ref(),
        &utterance,
        background,
        &OutputOptions {
            audio: speech.as_deref(),
            seed: a.seed,
            real: real.as_ref(),
            text: words.as_deref().or(a.text.as_deref()),
            beside_background: a.beside_background,
        },
        progress,
    )
    .with_context(|| format!("writing {}", a.output.display()))?;
    bar.finish_and_clear();
    println!(
        "synthesised {} phones, {} frames at {} fps in {synth_ms:.1} ms ({}; pose {}) → {}",
        utterance.target.len(),
        report.frames,
        fps,
        report.method,
        report.pose,
        a.output.display()
    );
    for w in &report.warnings {
        println!("  warning: {w}");
    }
    list_written(&a.output);
    Ok(())
}
