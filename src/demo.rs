//! The whole pipeline on the committed demo data (`facespace demo`, the README's first
//! command): build a lower-face region model from the talker's training frames, generate the
//! demo corpus from its real face-space points, build the codebook, synthesise a sentence
//! that is not in the corpus by top-N blending and by unit selection, and write each smoothed
//! and unsmoothed with a blind side-by-side — the lower face synthesised, the rest of the face (eyes, brows, blinks, head motion) from a
//! real stretch of the talker's video, whose tracked pose the synthesis replays.

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
use crate::synth::{DEFAULT_SMOOTHING, Request, Smoothing, SynthError, synthesise};

/// The demo utterance; it must not be one of the corpus sentences.
pub const DEMO_TEXT: &str = "A brave pilot found the hidden map.";

/// The demo model and its training frames, in the source tree.
pub fn default_model() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/demo/model")
}

/// The demo model's training frames with their landmarks.
pub fn default_training() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/demo/training")
}

/// 100 frames of the talker's video (frames 1500–1599 of the FGNet sequence), the demo's
/// background.
pub fn default_background() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/demo/background.mp4")
}

/// What can go wrong in the demo.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DemoError {
    /// The text is one of the corpus sentences.
    #[error("{0:?} is a corpus sentence; the demo synthesises unseen text")]
    SeenText(String),
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
}

/// Options of [`run`].
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Output folder.
    pub output: PathBuf,
    /// The text to synthesise (not a corpus sentence).
    pub text: String,
    /// The model folder.
    pub model: PathBuf,
    /// Its training frames with `.pts` landmarks.
    pub training: PathBuf,
    /// A video of the talker to draw the synthesised lower face over.
    pub background: PathBuf,
    /// Which renderer draws.
    pub renderer: RendererChoice,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            output: PathBuf::from("out/demo"),
            text: DEMO_TEXT.into(),
            model: default_model(),
            training: default_training(),
            background: default_background(),
            renderer: RendererChoice::Auto,
        }
    }
}

/// What the demo did.
#[derive(Clone, Debug)]
pub struct DemoReport {
    /// Shape parameters of the model.
    pub shape_params: usize,
    /// Appearance parameters of the model.
    pub appearance_params: usize,
    /// Real training frames the corpus draws on.
    pub training_frames: usize,
    /// Appearance parameters of the lower-face region model.
    pub region_appearance_params: usize,
    /// Generated training sentences in the codebook.
    pub sentences: usize,
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
            report = Some(run_into(options, staged, progress)?);
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

/// [`run`] writing into `w`; the report names the files where they will be (`options.output`).
fn run_into(
    options: &DemoOptions,
    w: &std::path::Path,
    mut progress: impl FnMut(Progress),
) -> Result<DemoReport, DemoError> {
    let normalise = |s: &str| {
        s.to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || *c == ' ')
            .collect::<String>()
    };
    if generator::SENTENCES
        .iter()
        .any(|s| normalise(s) == normalise(&options.text))
    {
        return Err(DemoError::SeenText(options.text.clone()));
    }
    let model = FaceModel::load(&options.model)?;
    let frames = load_training_set(&options.training, None)?;
    let o = &options.output;
    // The lower face from the same frames: the rest of the face comes from the background.
    let region = FaceModel::build(
        &frames,
        &BuildOptions {
            pixels: model.frame.n_pixels(),
            region: Some(Region::LowerFace),
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
    let target = phonemes::text_to_segments(&options.text, &cb.mean_durations())?;
    // Frames at the background's own rate, so its motion plays at the recorded speed.
    let fps = crate::video::Source::open(&options.background)
        .map_err(BackdropError::from)?
        .info()
        .fps;
    let backdrop = Backdrop::video(
        &model,
        &options.background,
        PoseMode::Replay,
        crate::synth::frame_count(&target, fps),
        &EncodeOptions::default(),
        crate::no_progress,
    )?;
    let request = Request {
        pose: backdrop.pose.clone(),
        ..Request::new(target, fps, Smoothing::Ab(DEFAULT_SMOOTHING))
    };
    let chosen = choose_renderer(options.renderer, &region, Some(DEFAULT_FEATHER))?;
    let renderer = chosen.renderer.as_ref();
    let output_options = OutputOptions {
        seed: 1,
        text: Some(&options.text),
        ..OutputOptions::default()
    };
    // The same sentence by both modes: top-N blending in `o`, unit selection in `o/unit`.
    let mut utterance = synthesise(&Blend::default(), &cb, request.clone())?;
    backdrop.anchor_region(&region, &mut utterance)?;
    let report = output::write(
        w,
        renderer,
        &utterance,
        backdrop.background()?,
        &output_options,
        &mut progress,
    )?;
    let mut unit = synthesise(&UnitSelection::default(), &cb, request)?;
    backdrop.anchor_region(&region, &mut unit)?;
    let unit_report = output::write(
        &w.join("unit"),
        renderer,
        &unit,
        backdrop.background()?,
        &output_options,
        &mut progress,
    )?;
    phonemes::write_labels(&w.join("utterance.lab"), &utterance.target)?;
    Ok(DemoReport {
        shape_params: model.shape.n_params(),
        appearance_params: model.appearance.n_params(),
        training_frames: frames.len(),
        region_appearance_params: region.appearance.n_params(),
        sentences,
        phones: utterance.target.len(),
        frames: utterance.synthesis.frames.len(),
        renderer_note: chosen.note.clone(),
        report,
        unit_report,
        files: vec![
            ("smoothed video", o.join("smoothed/video.mp4")),
            ("smoothed frames", o.join("smoothed/frames")),
            ("unsmoothed video", o.join("unsmoothed/video.mp4")),
            (
                "blind side by side (order in key.json)",
                o.join("side_by_side.mp4"),
            ),
            ("trajectory plot", o.join("plot.png")),
            ("unit selection (same files)", o.join("unit")),
            ("phone timings", o.join("utterance.lab")),
            ("lower-face model", o.join("model")),
            ("codebook", o.join("codebook")),
        ],
    })
}
