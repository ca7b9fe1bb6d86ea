//! What a talker is asked to say ([`SayRequest`]) and the one pipeline from it to pixels:
//! [`Talker::perform`] and [`Talker::say`].

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::{Talker, TalkerError};
use crate::codec::EncodeOptions;
use crate::footage::Plan;
use crate::mouths::SampledRenderer;
use crate::phonemes::{PhoneMap, Segment};
use crate::render::{DEFAULT_FEATHER, Edge, RendererChoice};
use crate::synth::backdrop::{Backdrop, PoseMode};
use crate::synth::blend::Blend;
use crate::synth::graph::Graph;
use crate::synth::output::{OutputOptions, Report};
use crate::synth::unit::UnitSelection;
use crate::synth::{Request, Smoothing, SynthError, Synthesiser, Utterance};
use crate::video::Sink;
use crate::{Progress, atomic};

/// What the face speaks.
#[derive(Clone, Debug, PartialEq)]
pub enum Speech {
    /// Text, spoken by a text-to-speech engine in the talker's voice; the speech is aligned
    /// and goes under the video.
    Text(String),
    /// A recording and its words, aligned to it; the recording goes under the video.
    Recording {
        /// The sound (WAV, MP4/M4A).
        audio: PathBuf,
        /// Its words.
        words: String,
    },
    /// A recording without its words: the phones are recognised from the sound alone
    /// ([`crate::align::Aligner::recognise`]; far less exact than aligned words, with a note
    /// saying so); the recording goes under the video.
    Sound(PathBuf),
    /// Phone timings; with a recording to put under the video, or silent.
    Labels {
        /// The label file (.lab, .TextGrid, .tsv).
        labels: PathBuf,
        /// The TextGrid tier to read.
        tier: Option<String>,
        /// Labels of another phone set, mapped to ARPAbet.
        map: PhoneMap,
        /// The sound, if any.
        audio: Option<PathBuf>,
    },
    /// Phone timings already in hand (ARPAbet, seconds); with a recording, or silent.
    Phones {
        /// The phones.
        phones: Vec<Segment>,
        /// The sound, if any.
        audio: Option<PathBuf>,
    },
}

/// What the face is drawn over.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Canvas {
    /// The talker's idle footage: a living frame as long as the speech.
    #[default]
    Footage,
    /// A video of the talker (a sentence's own take, say), tracked with the talker's model:
    /// its poses replayed frame by frame (a video shorter than the speech extended by joining
    /// its stretches where they match), or its first frame's held; its frame rate is the
    /// output's.
    Video {
        /// The video.
        path: PathBuf,
        /// Where the pose comes from.
        pose: PoseMode,
    },
    /// An image of the talker, its pose held.
    Image(PathBuf),
}

/// How an utterance is synthesised when not by the talker's own settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Top-N context blending with these settings.
    Blend(Blend),
    /// Frame-level unit selection.
    Unit(UnitSelection),
    /// The dynamic-phoneme graph.
    Graph(Graph),
}

impl Method {
    fn synthesiser(self) -> Box<dyn Synthesiser> {
        match self {
            Method::Blend(b) => Box::new(b),
            Method::Unit(u) => Box::new(u),
            Method::Graph(g) => Box::new(g),
        }
    }
}

/// A real trajectory to plot against the synthesis in the parts folder.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Real {
    /// None.
    #[default]
    None,
    /// A trajectory file (`.npy`, as `track` and `encode` write).
    File(PathBuf),
    /// The canvas video's own face, as tracked (a sentence drawn over its own take).
    Canvas,
}

/// How a parts folder is written: staged and swapped in whole, or straight into a folder
/// the caller stages.
#[derive(Clone, Copy)]
enum Staged {
    Swapped,
    ByCaller,
}

/// What to say and how.
#[derive(Clone, Debug)]
pub struct SayRequest {
    /// The speech.
    pub speech: Speech,
    /// A Festival voice other than the talker's.
    pub voice: Option<String>,
    /// Extra pronunciations for the aligner.
    pub dicts: Vec<PathBuf>,
    /// Which renderer draws.
    pub renderer: RendererChoice,
    /// Which of the best living frames ([`Footage::best_plan`]).
    pub seed: u64,
    /// Also write the folder of parts here (trajectory, frames, plot, report).
    pub parts: Option<PathBuf>,
    /// Use a recording's words even when they do not seem to be what is said
    /// ([`crate::align::WordFit::matches`]); by default such a request is refused.
    pub accept_mismatch: bool,
    /// Draw the appearance model's mouth even when the talker keeps recorded mouths (the A/B
    /// baseline of [`crate::mouths`]).
    pub model_mouth: bool,
    /// What the face is drawn over.
    pub canvas: Canvas,
    /// How to synthesise (default: the talker's settings).
    pub method: Option<Method>,
    /// Smoothing (default: on, with the talker's λ); [`Smoothing::Ab`] writes both variants
    /// and a blind side-by-side into the parts.
    pub smoothing: Option<Smoothing>,
    /// Output frame rate over a video or an image (default: the video's, else the footage's);
    /// over the footage its own rate always (a note says so when another was asked for).
    pub fps: Option<f64>,
    /// Refuse a phone the codebook lacks instead of borrowing the nearest one present.
    pub strict: bool,
    /// The parts: a real trajectory plotted against the synthesis.
    pub real: Real,
    /// The parts: also `beside_background.mp4`, the canvas as it is beside the synthesis.
    pub beside_background: bool,
}

impl SayRequest {
    /// The files and folders the request reads (its recording, labels, dictionaries).
    pub fn inputs(&self) -> Vec<&Path> {
        let mut inputs: Vec<&Path> = match &self.speech {
            Speech::Text(_) => Vec::new(),
            Speech::Recording { audio, .. } | Speech::Sound(audio) => vec![audio],
            Speech::Labels { labels, audio, .. } => {
                std::iter::once(labels.as_path()).chain(audio.as_deref()).collect()
            }
            Speech::Phones { audio, .. } => audio.iter().map(PathBuf::as_path).collect(),
        };
        inputs.extend(self.dicts.iter().map(PathBuf::as_path));
        match &self.canvas {
            Canvas::Footage => {}
            Canvas::Video { path, .. } | Canvas::Image(path) => inputs.push(path),
        }
        if let Real::File(path) = &self.real {
            inputs.push(path);
        }
        inputs
    }

    /// `speech`, with everything else as the talker has it.
    pub fn new(speech: Speech) -> Self {
        SayRequest {
            speech,
            voice: None,
            dicts: Vec::new(),
            renderer: RendererChoice::Auto,
            seed: 0,
            parts: None,
            accept_mismatch: false,
            model_mouth: false,
            canvas: Canvas::Footage,
            method: None,
            smoothing: None,
            fps: None,
            strict: false,
            real: Real::None,
            beside_background: false,
        }
    }
}

/// An utterance ready to draw: the synthesis fitted to its living frame.
pub struct Performance {
    /// The phones spoken.
    pub target: Vec<Segment>,
    /// The words, when there were words.
    pub words: Option<String>,
    /// The synthesis, anchored to the canvas's face and re-lit to it.
    pub utterance: Utterance,
    /// Which footage frames are shown (none for a still, or a video at least as long as the
    /// speech).
    pub plan: Option<Plan>,
    /// What the face is drawn over, with its poses.
    pub backdrop: Backdrop,
    /// The frame size.
    pub size: (u32, u32),
    /// The speech under the video, if any.
    pub sound: Option<PathBuf>,
    /// Notes for the user (a voice that was missing, phones borrowed).
    pub notes: Vec<String>,
}

/// What [`Talker::say`] made.
#[derive(Clone, Debug, Serialize)]
pub struct SayReport {
    /// The video written.
    pub video: PathBuf,
    /// Frames.
    pub frames: usize,
    /// Frames per second.
    pub fps: f64,
    /// Frame size.
    pub size: (u32, u32),
    /// Whether the video carries sound.
    pub sound: bool,
    /// The words, when there were words.
    pub words: Option<String>,
    /// Phones spoken.
    pub phones: usize,
    /// The synthesiser.
    pub method: String,
    /// Where the pose came from.
    pub pose: String,
    /// Output frames where the living frame joins two stretches, and what each join costs
    /// against the footage's median step.
    pub joins: Vec<usize>,
    /// [`Plan::join_costs`].
    pub join_costs: Vec<f32>,
    /// [`Plan::median_step`].
    pub median_step: f32,
    /// What rendered.
    pub renderer: String,
    /// Notes.
    pub notes: Vec<String>,
}

impl Talker {
    /// Everything up to the pixels: phones from the speech, the synthesis (by the talker's
    /// settings unless the request says otherwise), the canvas (by default a living frame of
    /// the footage as long as the speech), the synthesis anchored to the canvas's face (only
    /// lips and chin its own) and re-lit to it. Speech from text is made in `staging`.
    pub fn perform(
        &self,
        request: &SayRequest,
        staging: &Path,
    ) -> Result<Performance, TalkerError> {
        let mut notes = Vec::new();
        let (target, words, sound, heard) = self.phones(request, staging, &mut notes)?;
        let fps = match (request.fps, &request.canvas) {
            // The footage plays at its own rate: frame k of the video is footage frame k.
            (Some(fps), Canvas::Footage) => {
                if fps != self.footage.fps {
                    notes.push(format!("the footage plays at its own {} fps, not {fps}", self.footage.fps));
                }
                self.footage.fps
            }
            (Some(fps), _) => fps,
            (None, Canvas::Video { path, .. }) => crate::video::Source::open(path)?.info().fps,
            (None, _) => self.footage.fps,
        };
        crate::synth::validate_request(&target, fps)?;
        let n = crate::synth::frame_count(&target, fps);
        if let Some(sound) = &sound {
            crate::synth::output::check_sound(sound, n as f64 / fps)?;
        }
        let backdrop = match &request.canvas {
            Canvas::Footage => {
                let plan = self.footage.best_plan(n, request.seed);
                Backdrop::footage(&self.footage, &plan).map_err(SynthError::from)?
            }
            Canvas::Video { path, pose } => Backdrop::video(
                &self.model,
                path,
                *pose,
                n,
                &EncodeOptions::default(),
                crate::no_progress,
            )?,
            Canvas::Image(path) => Backdrop::still(&self.model, path)?,
        };
        let size = match &request.canvas {
            Canvas::Footage => self.footage.size,
            _ => backdrop.background()?.size(),
        };
        let settings = &self.manifest.settings;
        let synthesiser = match request.method {
            Some(method) => method.synthesiser(),
            None => settings.synthesiser(),
        };
        let smoothing = request.smoothing.unwrap_or(Smoothing::On(settings.smoothing));
        let req = Request {
            pose: backdrop.pose.clone(),
            ..Request::new(target.clone(), fps, smoothing)
        };
        let mut utterance = crate::synth::synthesise(synthesiser.as_ref(), &self.codebook, req)?;
        let borrowed: Vec<String> = (utterance.synthesis.phones.iter())
            .filter(|p| p.used != p.phone)
            .map(|p| format!("/{}/ at {:.2} s (nearest present: /{}/)", p.phone, p.start, p.used))
            .collect();
        if request.strict && !borrowed.is_empty() {
            return Err(TalkerError::Borrowed {
                dir: self.dir.clone(),
                phones: borrowed.join(", "),
            });
        }
        // Without words the talker's map, when it has one, draws the lips from the sound (it
        // is loaded only then: `say` from text or labels never reads it).
        if let Speech::Sound(audio) = &request.speech {
            let drawn = match self.sound_to_face()? {
                Some(map) => {
                    self.face_from_sound(map, audio, heard, &mut utterance)?;
                    "; the lips were predicted from the sound by the talker's sound-to-face map"
                }
                None => "",
            };
            notes.push(format!(
                "no words given: {}{drawn} (give the words for aligned phones and a surer lip sync)",
                self.heard_by()?
            ));
        }
        backdrop.fit(&self.model, &self.codebook, &mut utterance)?;
        notes.extend(utterance.synthesis.warnings.iter().cloned());
        Ok(Performance {
            target,
            words,
            utterance,
            plan: backdrop.plan.clone(),
            backdrop,
            size,
            sound,
            notes,
        })
    }

    /// Says `request` into the MP4 `out` (with its sound, in the canvas's framing), written
    /// atomically; with [`SayRequest::parts`] also the folder of parts. The one pipeline
    /// behind `say`, `synth --talker`, the demo and the Python package.
    pub fn say(
        &self,
        request: &SayRequest,
        out: &Path,
        progress: impl FnMut(Progress),
    ) -> Result<SayReport, TalkerError> {
        let parts = request.parts.as_deref().map(|p| (p, Staged::Swapped));
        self.draw(request, Some(out), parts, progress).map(|(report, _)| report)
    }

    /// Says `request` into the folder of parts `folder` only (the synthesis as video and
    /// frames, both variants and a blind side-by-side under [`Smoothing::Ab`], the
    /// trajectory, plot and report: what `synth` writes); the report's `video` is the folder.
    pub fn say_parts(
        &self,
        request: &SayRequest,
        folder: &Path,
        progress: impl FnMut(Progress),
    ) -> Result<(SayReport, Report), TalkerError> {
        self.parts(request, folder, Staged::Swapped, progress)
    }

    /// [`Talker::say_parts`] written straight into `folder`, which the caller stages (the
    /// demo, which swaps in its whole output when everything is written).
    pub fn say_parts_into(
        &self,
        request: &SayRequest,
        folder: &Path,
        progress: impl FnMut(Progress),
    ) -> Result<(SayReport, Report), TalkerError> {
        self.parts(request, folder, Staged::ByCaller, progress)
    }

    fn parts(
        &self,
        request: &SayRequest,
        folder: &Path,
        staged: Staged,
        progress: impl FnMut(Progress),
    ) -> Result<(SayReport, Report), TalkerError> {
        let (report, parts) = self.draw(request, None, Some((folder, staged)), progress)?;
        Ok((report, parts.expect("parts were asked for")))
    }

    /// [`Talker::perform`], then the pixels: into the MP4 `out` and the parts folder `parts`,
    /// each when given.
    fn draw(
        &self,
        request: &SayRequest,
        out: Option<&Path>,
        parts: Option<(&Path, Staged)>,
        mut progress: impl FnMut(Progress),
    ) -> Result<(SayReport, Option<Report>), TalkerError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| TalkerError::Io { path, source }
        };
        // Never over the request's own inputs or into the talker's folder (issue 69, R5-2/3).
        let mut inputs = request.inputs();
        inputs.push(&self.dir);
        for destination in out.iter().chain(parts.as_ref().map(|(p, _)| p)) {
            atomic::check_destination(destination, &inputs)?;
        }
        // Over an input is the first refusal (issue 69), then a format that is no video.
        if let Some(out) = out {
            crate::video::check_destination(out)?;
        }
        let first = out.or(parts.map(|(p, _)| p)).expect("somewhere to write");
        let staging = atomic::StagingDir::new(atomic::parent_of(first)).map_err(io(first))?;
        // The recorded mouths decode (about a second) while the speech is heard and synthesised.
        let (performance, mouths) = std::thread::scope(|scope| {
            let mouths = scope.spawn(|| {
                if request.model_mouth { Ok(None) } else { self.mouths() }
            });
            let performance = self.perform(request, staging.path());
            let mouths = mouths.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
            (performance, mouths)
        });
        let performance = performance?;
        let edge = Edge::Articulators(DEFAULT_FEATHER);
        let mut notes = performance.notes.clone();
        let variants = performance.utterance.variants();
        let frames = *variants.first().map(|(_, f)| f).ok_or(SynthError::Empty)?;
        // With recorded mouths the CPU draws, and no GPU is looked for.
        let (sampled, chosen);
        let renderer: &dyn crate::render::Renderer = match mouths? {
            Some(m) => {
                if request.renderer == RendererChoice::Gpu {
                    notes.push("recorded mouths are drawn on the CPU (--model-mouth draws on the GPU)".into());
                }
                sampled = SampledRenderer::new(&self.model, edge, m, frames);
                &sampled
            }
            None => {
                chosen = crate::render::choose_renderer(request.renderer, &self.model, edge)?;
                notes.extend(chosen.note.clone());
                chosen.renderer.as_ref()
            }
        };
        let size = performance.size;
        let sound = performance.sound.as_deref();
        let mut written = frames.len();
        if let Some(out) = out {
            let mut sink = Sink::create(out, size.0, size.1, frames.fps(), sound)?;
            crate::render::stream(
                renderer,
                frames,
                performance.backdrop.background()?,
                |image| sink.write(&image).map_err(TalkerError::from),
                &mut progress,
            )?;
            written = sink.finish()?;
        }
        let parts_report = match parts {
            Some((parts, staged)) => {
                let real = match &request.real {
                    Real::None => None,
                    Real::File(path) => Some(
                        crate::corpus::read_frames(path, self.model.layout(), frames.fps())
                            .map_err(|e| TalkerError::Real(Box::new(e)))?,
                    ),
                    Real::Canvas => Some(performance.backdrop.tracked.clone()),
                };
                let options = OutputOptions {
                    audio: sound,
                    seed: request.seed,
                    text: performance.words.as_deref(),
                    real: real.as_ref(),
                    beside_background: request.beside_background,
                };
                let background = performance.backdrop.background()?;
                let utterance = &performance.utterance;
                Some(match staged {
                    Staged::Swapped => crate::synth::output::write_folder(
                        parts, renderer, utterance, background, &options, &mut progress,
                    )?,
                    Staged::ByCaller => crate::synth::output::write(
                        parts, renderer, utterance, background, &options, &mut progress,
                    )?,
                })
            }
            None => None,
        };
        let plan = performance.plan.as_ref();
        let report = SayReport {
            video: out.unwrap_or(first).into(),
            frames: written,
            fps: frames.fps(),
            size,
            sound: sound.is_some(),
            words: performance.words.clone(),
            phones: performance.target.len(),
            method: performance.utterance.method.clone(),
            pose: performance.utterance.pose.clone(),
            joins: plan.map(|p| p.joins.clone()).unwrap_or_default(),
            join_costs: plan.map(|p| p.join_costs.clone()).unwrap_or_default(),
            median_step: plan.map_or(0.0, |p| p.median_step),
            renderer: renderer.describe(),
            notes,
        };
        Ok((report, parts_report))
    }
}
