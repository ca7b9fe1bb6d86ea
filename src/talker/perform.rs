//! What a talker is asked to say ([`SayRequest`]) and the one pipeline from it to pixels:
//! [`Talker::perform`] and [`Talker::say`].

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::footage::Plan;
use super::{Talker, TalkerError};
use crate::phonemes::{PhoneMap, Segment};
use crate::mouths::SampledRenderer;
use crate::render::{DEFAULT_FEATHER, Edge, RendererChoice};
use crate::synth::backdrop::Backdrop;
use crate::synth::output::OutputOptions;
use crate::synth::{Request, Smoothing, SynthError, Utterance};
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
        }
    }
}

/// An utterance ready to draw: the synthesis fitted to its living frame.
pub struct Performance {
    /// The phones spoken.
    pub target: Vec<Segment>,
    /// The words, when there were words.
    pub words: Option<String>,
    /// The synthesis, anchored to the footage's face and re-lit to it.
    pub utterance: Utterance,
    /// Which footage frames are shown.
    pub plan: Plan,
    /// The living frame.
    pub backdrop: Backdrop,
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
    /// Everything up to the pixels: phones from the speech, the synthesis by the talker's
    /// settings, the living frame as long as the speech, the synthesis anchored to the
    /// footage's face (only lips and chin its own) and re-lit to it. Speech from text is made
    /// in `staging`.
    pub fn perform(
        &self,
        request: &SayRequest,
        staging: &Path,
    ) -> Result<Performance, TalkerError> {
        let mut notes = Vec::new();
        let (target, words, sound, heard) = self.phones(request, staging, &mut notes)?;
        let fps = self.footage.fps;
        crate::synth::validate_request(&target, fps)?;
        let n = crate::synth::frame_count(&target, fps);
        if let Some(sound) = &sound {
            crate::synth::output::check_sound(sound, n as f64 / fps)?;
        }
        let plan = self.footage.best_plan(n, request.seed);
        let backdrop = Backdrop::footage(&self.footage, &plan).map_err(SynthError::from)?;
        let settings = &self.manifest.settings;
        let synthesiser = settings.synthesiser();
        let req = Request {
            pose: backdrop.pose.clone(),
            ..Request::new(target.clone(), fps, Smoothing::On(settings.smoothing))
        };
        let mut utterance = crate::synth::synthesise(synthesiser.as_ref(), &self.codebook, req)?;
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
        backdrop
            .anchor_region(&self.model, &mut utterance)
            .map_err(|source| TalkerError::Model {
                dir: self.dir.clone(),
                source: Box::new(source),
            })?;
        backdrop.match_lighting(&self.model, &self.codebook, &mut utterance);
        notes.extend(utterance.synthesis.warnings.iter().cloned());
        Ok(Performance {
            target,
            words,
            utterance,
            plan,
            backdrop,
            sound,
            notes,
        })
    }

    /// Says `request` into the MP4 `out` (with its sound, in the footage's framing), written
    /// atomically; with [`SayRequest::parts`] also the folder of parts. The one pipeline
    /// behind `say`.
    pub fn say(
        &self,
        request: &SayRequest,
        out: &Path,
        mut progress: impl FnMut(Progress),
    ) -> Result<SayReport, TalkerError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| TalkerError::Io { path, source }
        };
        // Never over the request's own inputs or into the talker's folder (issue 69, R5-2/3).
        let mut inputs = request.inputs();
        inputs.push(&self.dir);
        atomic::check_destination(out, &inputs)?;
        crate::video::check_destination(out)?;
        if let Some(parts) = &request.parts {
            atomic::check_destination(parts, &inputs)?;
        }
        let staging = atomic::StagingDir::new(atomic::parent_of(out)).map_err(io(out))?;
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
        let frames = performance
            .utterance
            .variants()
            .first()
            .map(|(_, f)| (*f).clone())
            .ok_or(SynthError::Empty)?;
        // With recorded mouths the CPU draws, and no GPU is looked for.
        let (sampled, chosen);
        let renderer: &dyn crate::render::Renderer = match mouths? {
            Some(m) => {
                if request.renderer == RendererChoice::Gpu {
                    notes.push("recorded mouths are drawn on the CPU (--model-mouth draws on the GPU)".into());
                }
                sampled = SampledRenderer::new(&self.model, edge, m, &frames);
                &sampled
            }
            None => {
                chosen = crate::render::choose_renderer(request.renderer, &self.model, edge)?;
                notes.extend(chosen.note.clone());
                chosen.renderer.as_ref()
            }
        };
        let size = self.footage.size;
        let sound = performance.sound.as_deref();
        let mut sink = Sink::create(out, size.0, size.1, frames.fps(), sound)?;
        crate::render::stream(
            renderer,
            &frames,
            performance.backdrop.background()?,
            |image| sink.write(&image).map_err(TalkerError::from),
            &mut progress,
        )?;
        let written = sink.finish()?;
        if let Some(parts) = &request.parts {
            crate::synth::output::write_folder(
                parts,
                renderer,
                &performance.utterance,
                performance.backdrop.background()?,
                &OutputOptions {
                    audio: sound,
                    seed: request.seed,
                    text: performance.words.as_deref(),
                    ..OutputOptions::default()
                },
                &mut progress,
            )?;
        }
        Ok(SayReport {
            video: out.into(),
            frames: written,
            fps: frames.fps(),
            size,
            sound: sound.is_some(),
            words: performance.words.clone(),
            phones: performance.target.len(),
            method: performance.utterance.method.clone(),
            joins: performance.plan.joins.clone(),
            join_costs: performance.plan.join_costs.clone(),
            median_step: performance.plan.median_step,
            renderer: renderer.describe(),
            notes,
        })
    }
}
