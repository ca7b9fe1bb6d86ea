//! The whole pipeline on committed data (`facespace demo`, the README's first command).
//!
//! **GRID s1** (the default, recorded): a test-split sentence that is not in the codebook is
//! aligned from its own sound and words, synthesised by top-N blending (the talker's N and λ,
//! chosen by `talker build` on GRID's validation split) and by unit selection from the codebook of his 741
//! kept training sentences, drawn by his talker as `say` draws ([`crate::talker::Talker::say_parts_into`]:
//! his recorded mouths, his appearance gain) over the sentence's own video (its tracked pose
//! replayed, the synthesis re-lit to its lighting), and written with its sound: smoothed,
//! unsmoothed, the blind A/B side-by-side, and the real recording beside the synthesis.
//!
//! **FGNet** (`--talker fgnet`, generated): build a lower-face region model from the
//! talker's training frames, generate the demo corpus from its real face-space points, build
//! the codebook, and synthesise a sentence that is not in the corpus the same ways over a
//! real stretch of his video (the rest of the face — eyes, brows, blinks, head motion — from
//! the video, whose tracked pose the synthesis replays).

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::Progress;
use crate::codebook::{Codebook, CodebookError, SimilarityOptions};
use crate::codec::EncodeOptions;
use crate::corpus::demo::{self as generator, CorpusOptions, GenerateError, Split};
use crate::mesh::Region;
use crate::model::{BuildOptions, FaceModel, ModelError, load_training_set};
use crate::phonemes::{self, PhonemeError};
use crate::render::{DEFAULT_FEATHER, RenderError, RendererChoice, choose_renderer};
use crate::synth::backdrop::{Backdrop, BackdropError, PoseMode};
use crate::synth::blend::Blend;
use crate::synth::output::{self, OutputError, OutputOptions, Report};
use crate::synth::unit::UnitSelection;
use crate::synth::{GENERATED_SMOOTHING, Request, Smoothing, SynthError};

/// The FGNet demo utterance; it must not be one of the corpus sentences.
pub const DEMO_TEXT: &str = "A brave pilot found the hidden map.";

fn committed(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// The demo model and its training frames, in the source tree.
pub fn default_model() -> PathBuf {
    committed("models/demo/model")
}

/// The demo model's training frames with their landmarks.
pub fn default_training() -> PathBuf {
    committed("models/demo/training")
}

/// 100 frames of the talker's video (frames 1500–1599 of the FGNet sequence), the demo's
/// background.
pub fn default_background() -> PathBuf {
    committed("models/demo/background.mp4")
}

/// GRID s1's full-face model (`models/grid/README.md`).
pub fn grid_model() -> PathBuf {
    committed("models/grid/model")
}

/// GRID s1's codebook: his 741 kept training sentences, appearance re-centred per sentence.
pub fn grid_codebook() -> PathBuf {
    committed("models/grid/codebook")
}

/// A GRID s1 test-split recording (not in the codebook), its words in `bbbf9a.txt` beside it.
pub fn grid_clip() -> PathBuf {
    committed("models/grid/demo/bbbf9a.mp4")
}

/// Whose face the demo shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Talker {
    /// GRID speaker 1: recorded sentences with their sound.
    #[default]
    Grid,
    /// The FGNet talker: a corpus generated over his real face-space points.
    Fgnet,
}

/// What can go wrong in the demo.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DemoError {
    /// The text is one of the corpus sentences.
    #[error("{0:?} is a corpus sentence; the demo synthesises unseen text")]
    SeenText(String),
    /// The recording is one of the codebook's sentences.
    #[error("{0} is a codebook sentence; the demo synthesises a held-out one (GRID's test split)")]
    SeenClip(PathBuf),
    /// The recording's words could not be read.
    #[error("{path}: the words of the recording could not be read ({source}); give --text")]
    Words {
        /// The transcript expected beside the recording.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The recording's sound could not be aligned with its words.
    #[error("aligning {path}: {source}")]
    Align {
        /// The recording.
        path: PathBuf,
        /// The cause.
        source: crate::align::AlignError,
    },
    /// The model or its training frames could not be loaded.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The corpus could not be generated.
    #[error(transparent)]
    Generate(#[from] GenerateError),
    /// The codebook could not be built or saved.
    #[error(transparent)]
    Codebook(#[from] CodebookError),
    /// The text did not become phones.
    #[error(transparent)]
    Phonemes(#[from] PhonemeError),
    /// Synthesis failed.
    #[error(transparent)]
    Synth(#[from] SynthError),
    /// The background video could not be tracked.
    #[error(transparent)]
    Backdrop(#[from] BackdropError),
    /// Writing the outputs failed.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The renderer asked for could not be made.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The talker could not be loaded or speak (boxed: the largest of these errors).
    #[error(transparent)]
    Talker(Box<crate::talker::TalkerError>),
}

impl From<crate::talker::TalkerError> for DemoError {
    fn from(e: crate::talker::TalkerError) -> Self {
        DemoError::Talker(Box::new(e))
    }
}

/// Options of [`run`].
#[derive(Clone, Debug, Default)]
pub struct DemoOptions {
    /// Output folder.
    pub output: PathBuf,
    /// Whose face.
    pub talker: Talker,
    /// GRID: the recording to synthesise (default [`grid_clip`]); FGNet: the video to draw
    /// over (default [`default_background`]).
    pub clip: Option<PathBuf>,
    /// GRID: the recording's words (default: `NAME.txt` beside it); FGNet: the text to
    /// synthesise (default [`DEMO_TEXT`]; not a corpus sentence).
    pub text: Option<String>,
    /// Which renderer draws.
    pub renderer: RendererChoice,
}

/// What the demo did.
#[derive(Clone, Debug)]
pub struct DemoReport {
    /// Whose face.
    pub talker: Talker,
    /// The model drawn.
    pub model: PathBuf,
    /// Shape parameters of the model.
    pub shape_params: usize,
    /// Appearance parameters of the model.
    pub appearance_params: usize,
    /// The lower-face region model's appearance parameters (FGNet).
    pub region_appearance_params: Option<usize>,
    /// What the codebook holds, in words (the corpus named recorded or generated).
    pub corpus: String,
    /// The text spoken.
    pub text: String,
    /// The video drawn over.
    pub background: PathBuf,
    /// Phones of the utterance.
    pub phones: usize,
    /// Frames of the utterance.
    pub frames: usize,
    /// The blended utterance's report (also in `report.json`).
    pub report: Report,
    /// The unit-selection utterance's report (also in `unit/report.json`).
    pub unit_report: Report,
    /// Why the CPU rendered, when the GPU was hoped for.
    pub renderer_note: Option<String>,
    /// What was written where.
    pub files: Vec<(&'static str, PathBuf)>,
}

/// Runs the demo (see the module docs). Everything is built in a staging folder beside
/// `options.output` and swapped in at the end: a killed run leaves the previous demo whole,
/// and a folder facespace did not write is never replaced.
pub fn run(options: &DemoOptions, progress: impl FnMut(Progress)) -> Result<DemoReport, DemoError> {
    let mut report = None;
    crate::atomic::replace_dir(
        &options.output,
        "demo",
        |staged| {
            report = Some(match options.talker {
                Talker::Grid => grid_into(options, staged, progress)?,
                Talker::Fgnet => fgnet_into(options, staged, progress)?,
            });
            Ok(())
        },
        |source| {
            DemoError::from(OutputError::Io {
                path: options.output.clone(),
                source,
            })
        },
    )?;
    Ok(report.expect("the demo ran"))
}

/// The GRID demo (see the module docs) writing into `w`; the report names the files where
/// they will be (`options.output`).
fn grid_into(
    options: &DemoOptions,
    w: &Path,
    mut progress: impl FnMut(Progress),
) -> Result<DemoReport, DemoError> {
    // His talker folder: its model, codebook and the settings chosen on his validation split.
    let talker = crate::talker::Talker::load(&committed("models/grid"))?;
    let (model, cb) = (&talker.model, &talker.codebook);
    let settings = &talker.manifest.settings;
    let model_path = grid_model();
    let clip = options.clip.clone().unwrap_or_else(grid_clip);
    let stem = clip.file_stem().map(|s| s.to_string_lossy().into_owned());
    if cb.sentences.iter().any(|s| Some(&s.name) == stem.as_ref()) {
        return Err(DemoError::SeenClip(clip));
    }
    let words = match &options.text {
        Some(t) => t.clone(),
        None => {
            let path = clip.with_extension("txt");
            crate::safe_read::read_regular_string(&path)
                .map_err(|source| DemoError::Words { path, source })?
        }
    };
    // Speech in: the recording's own sound with its words, drawn by his talker over the
    // sentence's own take (its tracked poses replayed, the synthesis anchored and re-lit to
    // it, his recorded mouths): blend and unit selection, each smoothed and not.
    let words = words.trim();
    let request = |method| crate::talker::SayRequest {
        renderer: options.renderer,
        canvas: crate::talker::Canvas::Video {
            path: clip.clone(),
            pose: PoseMode::Replay,
        },
        method,
        smoothing: Some(Smoothing::Ab(settings.smoothing)),
        seed: 1,
        real: crate::talker::Real::Canvas,
        beside_background: true,
        ..crate::talker::SayRequest::new(crate::talker::Speech::Recording {
            audio: clip.clone(),
            words: words.to_owned(),
        })
    };
    let (said, report) = talker.say_parts_into(&request(None), w, &mut progress)?;
    let unit = crate::talker::Method::Unit(UnitSelection::default());
    let (_, unit_report) = talker.say_parts_into(&request(Some(unit)), &w.join("unit"), &mut progress)?;
    // The words and phones as aligned, for a look in Praat.
    let alignment = crate::align::Aligner::load_default(&[])
        .and_then(|a| a.align_file(&clip, words))
        .map_err(|source| DemoError::Align {
            path: clip.clone(),
            source,
        })?;
    alignment.write(&w.join("utterance.TextGrid"))?;
    // The main verb: the same recording and words through `say`, over his idle footage (not
    // the sentence's own take) — what `facespace say --audio CLIP --text WORDS` writes.
    let request = crate::talker::SayRequest {
        renderer: options.renderer,
        ..crate::talker::SayRequest::new(crate::talker::Speech::Recording {
            audio: clip.clone(),
            words: words.to_owned(),
        })
    };
    talker.say(&request, &w.join("say.mp4"), &mut progress)?;
    let o = &options.output;
    Ok(DemoReport {
        talker: Talker::Grid,
        model: model_path,
        shape_params: model.shape.n_params(),
        appearance_params: model.appearance.n_params(),
        region_appearance_params: None,
        corpus: format!(
            "{} recorded GRID s1 training sentences (appearance re-centred per sentence)",
            cb.sentences.len()
        ),
        text: words.to_owned(),
        background: clip.clone(),
        phones: said.phones,
        frames: report.frames,
        renderer_note: None,
        report,
        unit_report,
        files: [
            vec![(
                "real recording | synthesis, with sound",
                o.join("beside_background.mp4"),
            )],
            synthesis_files(o, "trajectory plot (with the real one)"),
            vec![
                ("words and phones aligned", o.join("utterance.TextGrid")),
                (
                    "say: the same words over his footage",
                    o.join("say.mp4"),
                ),
            ],
        ]
        .concat(),
    })
}

/// The FGNet demo (see the module docs) writing into `w`; the report names the files where
/// they will be (`options.output`).
fn fgnet_into(
    options: &DemoOptions,
    w: &Path,
    mut progress: impl FnMut(Progress),
) -> Result<DemoReport, DemoError> {
    let text = options.text.clone().unwrap_or_else(|| DEMO_TEXT.to_owned());
    let background = options.clip.clone().unwrap_or_else(default_background);
    let normalise = |s: &str| {
        s.to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || *c == ' ')
            .collect::<String>()
    };
    if generator::SENTENCES
        .iter()
        .any(|s| normalise(s) == normalise(&text))
    {
        return Err(DemoError::SeenText(text));
    }
    let model_path = default_model();
    let model = FaceModel::load(&model_path)?;
    let frames = load_training_set(&default_training(), None)?;
    let o = &options.output;
    // The lower face from the same frames: the rest of the face comes from the background.
    let region = FaceModel::build(
        &frames,
        &BuildOptions {
            pixels: model.frame.n_pixels(),
            region: Some(Region::LowerFace),
            margin: model.placement.margin,
            ..BuildOptions::default()
        },
        &mut crate::no_progress,
    )?;
    region.save(&w.join("model"))?;
    let generated = generator::generate(&region, &frames, &CorpusOptions::default())?;
    let train = generated.part(Split::Train);
    let sentences = train.len();
    let cb = Codebook::build(
        train,
        CorpusOptions::default().fps,
        region.layout(),
        Some(region.hash()),
        SimilarityOptions::default(),
        &mut crate::no_progress,
    )?;
    cb.save(&w.join("codebook"))?;
    let target = phonemes::text_to_segments(&text, &cb.mean_durations())?;
    let (backdrop, fps) = replayed_backdrop(&model, &background, &target)?;
    let request = Request {
        pose: backdrop.pose.clone(),
        ..Request::new(target, fps, Smoothing::Ab(GENERATED_SMOOTHING))
    };
    let chosen = choose_renderer(options.renderer, &region, Some(DEFAULT_FEATHER))?;
    let renderer = chosen.renderer.as_ref();
    let output_options = OutputOptions {
        seed: 1,
        text: Some(&text),
        ..OutputOptions::default()
    };
    let (utterance, report, unit_report) = both_modes(
        w,
        &Blend::default(),
        &cb,
        &region,
        &backdrop,
        request,
        renderer,
        &output_options,
        &mut progress,
    )?;
    Ok(DemoReport {
        talker: Talker::Fgnet,
        model: model_path,
        shape_params: model.shape.n_params(),
        appearance_params: model.appearance.n_params(),
        region_appearance_params: Some(region.appearance.n_params()),
        corpus: format!(
            "{sentences} generated sentences (trajectories generated over the real face-space points of {} frames, not recorded)",
            frames.len()
        ),
        text,
        background,
        phones: utterance.target.len(),
        frames: utterance.synthesis.frames.len(),
        renderer_note: chosen.note.clone(),
        report,
        unit_report,
        files: [
            synthesis_files(o, "trajectory plot"),
            vec![
                ("lower-face model", o.join("model")),
                ("codebook", o.join("codebook")),
            ],
        ]
        .concat(),
    })
}

/// What [`both_modes`] writes under `o`, named for the report (`plot`: how the plot is
/// described).
fn synthesis_files(o: &Path, plot: &'static str) -> Vec<(&'static str, PathBuf)> {
    vec![
        ("smoothed video", o.join("smoothed/video.mp4")),
        ("smoothed frames", o.join("smoothed/frames")),
        ("unsmoothed video", o.join("unsmoothed/video.mp4")),
        (
            "blind side by side (order in key.json)",
            o.join("side_by_side.mp4"),
        ),
        (plot, o.join("plot.png")),
        ("unit selection (same files)", o.join("unit")),
        ("phone timings", o.join("utterance.lab")),
    ]
}

/// `video` tracked with `tracker`, its poses replayed under an utterance of `target`'s
/// length, and its frame rate (frames at the video's own rate, so its motion plays at the
/// recorded speed).
fn replayed_backdrop(
    tracker: &FaceModel,
    video: &Path,
    target: &[crate::phonemes::Segment],
) -> Result<(Backdrop, f64), DemoError> {
    let fps = crate::video::Source::open(video)
        .map_err(BackdropError::from)?
        .info()
        .fps;
    let backdrop = Backdrop::video(
        tracker,
        video,
        PoseMode::Replay,
        crate::synth::frame_count(target, fps),
        &EncodeOptions::default(),
        crate::no_progress,
    )?;
    Ok((backdrop, fps))
}

/// The same request by both modes over one backdrop — `blend` into `w`, unit selection into
/// `w/unit` — each fitted to the backdrop (a region model anchored to its face, a re-centred
/// codebook re-lit to its take) and written; returns the blended utterance and both reports.
#[allow(clippy::too_many_arguments)]
fn both_modes(
    w: &Path,
    blend: &Blend,
    cb: &Codebook,
    model: &FaceModel,
    backdrop: &Backdrop,
    request: Request,
    renderer: &dyn crate::render::Renderer,
    output_options: &OutputOptions<'_>,
    mut progress: impl FnMut(Progress),
) -> Result<(crate::synth::Utterance, Report, Report), DemoError> {
    let unit = UnitSelection::default();
    let modes: [(&dyn crate::synth::Synthesiser, PathBuf); 2] =
        [(blend, w.to_path_buf()), (&unit, w.join("unit"))];
    let mut done = Vec::with_capacity(2);
    for (synthesiser, dir) in modes {
        let utterance = backdrop.synthesise(synthesiser, cb, model, request.clone())?;
        let report = output::write(
            &dir,
            renderer,
            &utterance,
            backdrop.background()?,
            output_options,
            &mut progress,
        )?;
        done.push((utterance, report));
    }
    let (_, unit_report) = done.pop().expect("two modes");
    let (utterance, report) = done.pop().expect("two modes");
    Ok((utterance, report, unit_report))
}
