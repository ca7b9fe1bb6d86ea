//! A talker: everything needed to make one person speak, in one folder (issue 33).
//!
//! `talker.json` names the parts and holds the synthesis settings chosen on validation:
//!
//! - `model/`: the whole-face model that tracked the footage and draws the face;
//! - `codebook/`: the codebook of the talker's sentences in that model's space;
//! - `footage/`: idle footage, tracked ([`footage`]): the living frame every utterance is
//!   drawn over, only the lips and jaw replaced.
//!
//! [`Talker::say`] is the one pipeline from speech (text, a recording with its words, or phone
//! labels) to a video with sound: `say`, `synth --talker` and the demo call it.

pub mod build;
pub mod footage;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::align::Evidence;
use crate::codebook::{Codebook, CodebookError};
use crate::manifest::{self, ManifestError};
use crate::model::{FaceModel, ModelError};
use crate::phonemes::{PhoneMap, PhonemeError, Segment};
use crate::render::sampled::SampledRenderer;
use crate::render::{DEFAULT_FEATHER, Edge, RenderError, RendererChoice};
use crate::synth::backdrop::Backdrop;
use crate::synth::blend::Blend;
use crate::synth::graph::Graph;
use crate::synth::output::{OutputError, OutputOptions};
use crate::synth::unit::UnitSelection;
use crate::synth::{Request, Smoothing, SynthError, Synthesiser, Utterance};
use crate::video::{Sink, VideoError};
use crate::{Progress, atomic};
use footage::{Footage, FootageError, Plan};

/// The talker folder format this build writes and reads.
pub const TALKER_VERSION: u32 = 1;
const FORMAT: &str = "facespace-talker";
/// The talker's manifest.
pub const MANIFEST: &str = "talker.json";

/// How a talker synthesises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Top-N context blending.
    Blend,
    /// Unit selection.
    Unit,
    /// The dynamic-phoneme graph.
    Graph,
}

/// The synthesis settings a talker carries (chosen on a validation part kept apart from what
/// is reported).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// How to synthesise.
    pub mode: Mode,
    /// Examples blended per phone, N.
    pub top_n: usize,
    /// Context width C.
    pub context: usize,
    /// Smoothing weight λ of the cubic smoothing spline.
    pub smoothing: f64,
    /// Blend's appearance gain ([`Blend::appearance_gain`]); 1 in talkers made before it.
    #[serde(default = "unit_gain")]
    pub appearance_gain: f64,
    /// Where they were chosen, in words.
    pub chosen_on: String,
}

fn unit_gain() -> f64 {
    1.0
}

/// The largest appearance gain a talker may carry: beyond it the texture swings far outside
/// anything recorded (GRID s1's is 1.15).
pub const MAX_APPEARANCE_GAIN: f64 = 4.0;

/// The most examples a talker blends per phone: far more than any choice made on validation
/// sentences (3–12), few enough that a blend stays quick.
pub const MAX_TOP_N: usize = 1000;

impl Settings {
    /// Refuses settings no synthesis can use, naming the field (`prefix` before its name:
    /// `settings.` in a manifest, `--` on the command line): N from 1 to
    /// [`MAX_TOP_N`], C up to [`crate::synth::blend::MAX_CONTEXT`], λ
    /// from 0 to [`crate::synth::MAX_SMOOTHING`], the appearance gain in (0,
    /// [`MAX_APPEARANCE_GAIN`]]. Checked when a talker loads and before `talker build` does
    /// any work (issue 69, R5-14: `--smoothing NaN` built for minutes).
    pub fn check(&self, prefix: &str, separator: char) -> Result<(), crate::options::InvalidOption> {
        use crate::options::{count_in, in_range};
        let name = |field: &str| format!("{prefix}{}", field.replace('_', &separator.to_string()));
        count_in(&name("top_n"), self.top_n, 1, MAX_TOP_N)?;
        count_in(&name("context"), self.context, 0, crate::synth::blend::MAX_CONTEXT)?;
        in_range(&name("smoothing"), self.smoothing, 0.0, crate::synth::MAX_SMOOTHING)?;
        in_range(
            &name("appearance_gain"),
            self.appearance_gain,
            f64::MIN_POSITIVE,
            MAX_APPEARANCE_GAIN,
        )?;
        Ok(())
    }

    /// The blend settings chosen on validation sentences (`split`: which, in words), with
    /// the appearance gain given.
    pub fn chosen(
        choice: &crate::eval::systems::SettingsChoice,
        split: &str,
        appearance_gain: f64,
    ) -> Self {
        Settings {
            mode: Mode::Blend,
            top_n: choice.chosen.top_n,
            context: 1,
            smoothing: choice.chosen.smoothing,
            appearance_gain,
            chosen_on: choice.describe(split),
        }
    }

    /// The synthesiser these settings name.
    pub fn synthesiser(&self) -> Box<dyn Synthesiser> {
        match self.mode {
            Mode::Blend => Box::new(Blend {
                context: self.context,
                top_n: self.top_n,
                preserve_variance: true,
                appearance_gain: self.appearance_gain,
            }),
            Mode::Unit => Box::new(UnitSelection::default()),
            Mode::Graph => Box::new(Graph::default()),
        }
    }
}

/// The text-to-speech voice that suits the talker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Voice {
    /// Festival's name for it (`kal_diphone`).
    pub festival: String,
    /// The Debian package that installs it, for the hint when it is missing.
    pub package: String,
}

/// Where the talker came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The recordings, in words (corpus, split, licence).
    pub recordings: String,
    /// How the folder was made.
    pub made_by: String,
    /// The facespace version that made it.
    pub facespace: String,
}

/// `talker.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TalkerManifest {
    /// Always `facespace-talker`.
    pub format: String,
    /// [`TALKER_VERSION`].
    pub version: u32,
    /// Who this is.
    pub name: String,
    /// The whole-face model folder (a name inside the talker folder).
    pub model: String,
    /// The codebook folder.
    pub codebook: String,
    /// The footage folder.
    pub footage: String,
    /// The recorded mouths folder ([`crate::mouths`]), when the talker keeps them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mouths: Option<String>,
    /// The learnt map from sound to face ([`crate::sound_to_face`]), when the talker has
    /// one: lips from a recording without its words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sound_to_face: Option<String>,
    /// The synthesis settings.
    pub settings: Settings,
    /// The voice for speech from text.
    pub voice: Option<Voice>,
    /// Where it came from.
    pub provenance: Provenance,
}

/// The sound of the recording `audio` as the aligner hears it (16 kHz, at most
/// [`crate::align::MAX_SECONDS`]).
fn speech_sound(audio: &Path) -> Result<crate::audio::Audio, TalkerError> {
    crate::audio::read(audio, crate::align::frontend::SAMPLE_RATE, crate::align::MAX_SECONDS)
        .map_err(|e| TalkerError::Align {
            path: audio.to_path_buf(),
            source: Box::new(e.into()),
        })
}

/// What can go wrong with a talker.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum TalkerError {
    /// `talker.json` is missing, damaged or of another version.
    #[error("talker {dir}: {source}")]
    Manifest {
        /// The talker folder.
        dir: PathBuf,
        /// The cause (boxed: the error enum travels in every result).
        source: Box<ManifestError>,
    },
    /// The model part.
    #[error("talker {dir}: its model: {source}")]
    Model {
        /// The talker folder.
        dir: PathBuf,
        /// The cause (boxed: the error enum travels in every result).
        source: Box<ModelError>,
    },
    /// The codebook part.
    #[error("talker {dir}: its codebook: {source}")]
    Codebook {
        /// The talker folder.
        dir: PathBuf,
        /// The cause (boxed: a codebook error is large, and every result carries the enum).
        source: Box<CodebookError>,
    },
    /// The footage part.
    #[error("talker {dir}: its {source}")]
    Footage {
        /// The talker folder.
        dir: PathBuf,
        /// The cause (boxed: the error enum travels in every result).
        source: Box<FootageError>,
    },
    /// The sound-to-face part.
    #[error("talker {dir}: its sound-to-face map: {source}")]
    SoundToFace {
        /// The talker folder.
        dir: PathBuf,
        /// The cause.
        source: Box<crate::sound_to_face::SoundToFaceError>,
    },
    /// The recorded mouths part.
    #[error("talker {dir}: its {source}")]
    Mouths {
        /// The talker folder.
        dir: PathBuf,
        /// The cause (boxed: the error enum travels in every result).
        source: Box<crate::mouths::MouthsError>,
    },
    /// A part made with another model than the talker's.
    #[error(
        "talker {dir}: its {part} was made with another model ({found}) than its model ({expected}); rebuild the talker (`facespace talker build`)"
    )]
    Foreign {
        /// The talker folder.
        dir: PathBuf,
        /// Which part.
        part: &'static str,
        /// The part's model hash.
        found: String,
        /// The model's hash.
        expected: String,
    },
    /// Text-to-speech failed (no engine: the install line).
    #[error(transparent)]
    Tts(#[from] crate::tts::TtsError),
    /// The speech could not be aligned with its words.
    #[error("aligning {path}: {source}")]
    Align {
        /// The sound.
        path: PathBuf,
        /// The cause (boxed: the error enum travels in every result).
        source: Box<crate::align::AlignError>,
    },
    /// The recordings could not be made a corpus.
    #[error("the corpus of {dir}: {source}")]
    Corpus {
        /// The recordings.
        dir: PathBuf,
        /// The cause.
        source: Box<crate::corpus::CorpusError>,
    },
    /// The phones could not be read.
    #[error(transparent)]
    Phonemes(#[from] PhonemeError),
    /// Synthesis failed.
    #[error(transparent)]
    Synth(#[from] SynthError),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// Writing failed.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// The video could not be written.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The living frame's footage could not be read.
    #[error(transparent)]
    Backdrop(#[from] crate::synth::backdrop::BackdropError),
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A folder `talker build` did not make, which it never builds into.
    #[error(
        "{dir} holds files talker build did not make ({found}, …): give a new or empty folder (a folder it made keeps its {record})",
        record = build::BUILD_RECORD
    )]
    NotOurs {
        /// The folder.
        dir: PathBuf,
        /// A few of its files.
        found: String,
    },
    /// Words that cannot be aligned (none, or not in the dictionary), found before any
    /// speech is made.
    #[error("the words: {source}")]
    Words {
        /// Why.
        source: Box<crate::align::AlignError>,
    },
    /// The speech a text-to-speech engine made from the text could not be aligned.
    #[error("the speech {engine} made from the text: {source}")]
    Spoken {
        /// The engine.
        engine: &'static str,
        /// Why.
        source: Box<crate::align::AlignError>,
    },
    /// An output that would replace an input, lie inside the talker or an input folder, or
    /// replace a device (checked before any work).
    #[error(transparent)]
    Destination(#[from] atomic::DestinationError),
}

/// The phones of a request's speech, its words when there were words, the sound to put
/// under the video, and what the talker's own ear heard in it when it recognised the phones.
type Heard = (Vec<Segment>, Option<String>, Option<PathBuf>, Option<Evidence>);

/// A talker, loaded (module docs).
pub struct Talker {
    /// Its folder.
    pub dir: PathBuf,
    /// Its manifest.
    pub manifest: TalkerManifest,
    /// The whole-face model.
    pub model: FaceModel,
    /// The codebook.
    pub codebook: Codebook,
    /// The idle footage.
    pub footage: Footage,
    /// The model's hash as loaded, which the parts loaded later are checked against (taking
    /// it reads every array of the model: 10 MB for GRID s1's).
    model_hash: String,
    /// The aligner with the committed dictionary, loaded when first needed and kept, with the
    /// phone bigram it estimates, for every later request without extra dictionaries.
    aligner: std::sync::OnceLock<crate::align::Aligner>,
    /// The recorded mouths, loaded when first drawn and kept.
    mouths: std::sync::OnceLock<crate::mouths::Mouths>,
    /// The sound-to-face map, loaded when first used and kept.
    sound_to_face: std::sync::OnceLock<crate::sound_to_face::SoundToFace>,
    /// The codebook's median pose, found when first asked for and kept.
    median_pose: std::sync::OnceLock<crate::shape::Similarity>,
}

/// The manifest of the talker folder `dir`, checked as [`Talker::load`] checks it: only
/// regular files inside the folder (`talker.json`, then every part it names and the files in
/// them), its format and version, and settings a synthesis can use.
pub fn read_manifest(dir: &Path) -> Result<TalkerManifest, TalkerError> {
    let manifest_error = |source| TalkerError::Manifest {
        dir: dir.into(),
        source: Box::new(source),
    };
    manifest::check_confined(dir, &[MANIFEST]).map_err(manifest_error)?;
    let m: TalkerManifest =
        manifest::read(&dir.join(MANIFEST), FORMAT, TALKER_VERSION).map_err(manifest_error)?;
    let parts = [Some(&m.model), Some(&m.codebook), Some(&m.footage), m.mouths.as_ref(), m.sound_to_face.as_ref()];
    let parts: Vec<&str> = parts.into_iter().flatten().map(String::as_str).collect();
    manifest::check_confined(dir, &parts).map_err(manifest_error)?;
    if let Err(why) = m.settings.check("settings.", '_') {
        return Err(manifest_error(ManifestError::Invalid {
            path: dir.join(MANIFEST),
            reason: why.to_string(),
        }));
    }
    Ok(m)
}

/// The value kept in `cell`, loaded by `load` the first time. A failed load is not kept (the
/// next call tries again); two threads racing both load, and one result is kept.
fn loaded_once<T, E>(
    cell: &std::sync::OnceLock<T>,
    load: impl FnOnce() -> Result<T, E>,
) -> Result<&T, E> {
    if let Some(v) = cell.get() {
        return Ok(v);
    }
    let loaded = load()?;
    Ok(cell.get_or_init(|| loaded))
}

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
    /// Loads the talker folder `dir`: the manifest (its version checked), then each part,
    /// each checked against the model. An error names the part.
    pub fn load(dir: &Path) -> Result<Talker, TalkerError> {
        Self::load_with(dir, true)
    }

    /// [`Talker::load`] as if it kept no recorded mouths (to make them again).
    pub(crate) fn load_without_mouths(dir: &Path) -> Result<Talker, TalkerError> {
        Self::load_with(dir, false)
    }

    fn load_with(dir: &Path, mouths: bool) -> Result<Talker, TalkerError> {
        let manifest_error = |source| TalkerError::Manifest {
            dir: dir.into(),
            source: Box::new(source),
        };
        let mut m = read_manifest(dir)?;
        if !mouths {
            m.mouths = None;
        }
        let part = |name: &str| manifest::member(dir, name).map_err(manifest_error);
        let (model_dir, codebook_dir, footage_dir) =
            (part(&m.model)?, part(&m.codebook)?, part(&m.footage)?);
        if let Some(mouths) = &m.mouths {
            let path = part(mouths)?;
            if !path.is_dir() {
                return Err(TalkerError::Mouths {
                    dir: dir.into(),
                    source: Box::new(crate::mouths::MouthsError::Inconsistent {
                        dir: path,
                        reason: "the folder named in talker.json is missing".into(),
                    }),
                });
            }
        }
        // The three parts load side by side (the model's hash reads every array of it).
        let (model, codebook, footage) = std::thread::scope(|scope| {
            let model = scope.spawn(|| {
                FaceModel::load(&model_dir).map(|model| {
                    let hash = model.hash();
                    (model, hash)
                })
            });
            let footage = scope.spawn(|| Footage::load(&footage_dir));
            let codebook = Codebook::load(&codebook_dir);
            let model = model.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
            let footage = footage.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
            (model, codebook, footage)
        });
        let (model, hash) = model.map_err(|source| TalkerError::Model {
            dir: dir.into(),
            source: Box::new(source),
        })?;
        let codebook = codebook.map_err(|source| TalkerError::Codebook {
            dir: dir.into(),
            source: Box::new(source),
        })?;
        codebook
            .check_model_hash(&hash, model.layout())
            .map_err(|source| TalkerError::Codebook {
                dir: dir.into(),
                source: Box::new(source),
            })?;
        let footage = footage.map_err(|source| TalkerError::Footage {
            dir: dir.into(),
            source: Box::new(source),
        })?;
        if footage.model_hash != hash {
            return Err(TalkerError::Foreign {
                dir: dir.into(),
                part: "footage",
                found: footage.model_hash.clone(),
                expected: hash,
            });
        }
        Ok(Talker {
            dir: dir.into(),
            manifest: m,
            model,
            codebook,
            footage,
            model_hash: hash,
            aligner: std::sync::OnceLock::new(),
            mouths: std::sync::OnceLock::new(),
            sound_to_face: std::sync::OnceLock::new(),
            median_pose: std::sync::OnceLock::new(),
        })
    }

    /// [`Codebook::median_pose`] of the talker's codebook, kept: a live session's every batch
    /// is synthesised at it, and it reads every frame of the codebook.
    pub fn median_pose(&self) -> crate::shape::Similarity {
        *self.median_pose.get_or_init(|| self.codebook.median_pose())
    }

    /// The talker's own aligner (the committed dictionary), loaded on first use and kept.
    pub(crate) fn default_aligner(&self) -> Result<&crate::align::Aligner, crate::align::AlignError> {
        loaded_once(&self.aligner, || crate::align::Aligner::load_default(&[]))
    }

    /// The talker's sound-to-face map, if it has one: loaded on first use and kept.
    pub fn sound_to_face(
        &self,
    ) -> Result<Option<&crate::sound_to_face::SoundToFace>, TalkerError> {
        let Some(name) = &self.manifest.sound_to_face else {
            return Ok(None);
        };
        let load = || {
            let path = manifest::member(&self.dir, name)
                .map_err(crate::sound_to_face::SoundToFaceError::Manifest)?;
            let phones = self
                .default_aligner()
                .map_err(|e| crate::sound_to_face::SoundToFaceError::Sound {
                    path: path.clone(),
                    source: Box::new(e),
                })?
                .model
                .ci_names
                .len();
            crate::sound_to_face::SoundToFace::load_for(&path, &self.model, &self.model_hash, phones)
        };
        loaded_once(&self.sound_to_face, load)
            .map(Some)
            .map_err(|source| TalkerError::SoundToFace {
                dir: self.dir.clone(),
                source: Box::new(source),
            })
    }

    /// The talker's recorded mouths, if it keeps them: loaded on first use and kept (their
    /// video is decoded piece by piece as frames of it are drawn).
    pub fn mouths(&self) -> Result<Option<&crate::mouths::Mouths>, TalkerError> {
        let Some(name) = &self.manifest.mouths else {
            return Ok(None);
        };
        let load = || {
            let path = manifest::member(&self.dir, name)
                .map_err(crate::mouths::MouthsError::Manifest)?;
            crate::mouths::Mouths::load_for(&path, &self.model, &self.model_hash)
        };
        loaded_once(&self.mouths, load).map(Some).map_err(|source| TalkerError::Mouths {
            dir: self.dir.clone(),
            source: Box::new(source),
        })
    }

    /// The phones of the recording `audio`, its words unknown: heard by the talker's own ear
    /// (its sound-to-face map's [`crate::sound_to_face::PhoneClassifier`]) where it has one,
    /// else by the acoustic model's phone loop. Sound that is not speech is refused.
    pub fn recognise(&self, audio: &Path) -> Result<Vec<crate::align::TimedPhone>, TalkerError> {
        Ok(self.hear_sound(audio)?.0)
    }

    /// [`Self::recognise`], with the evidence the talker's own ear heard the phones by
    /// (`None` when the acoustic model's phone loop heard them).
    fn hear_sound(&self, audio: &Path) -> Result<(Vec<crate::align::TimedPhone>, Option<Evidence>), TalkerError> {
        let sound = speech_sound(audio)?;
        let failed = |e| TalkerError::Align {
            path: audio.to_path_buf(),
            source: Box::new(e),
        };
        let aligner = self.default_aligner().map_err(failed)?;
        let (samples, rate) = (&sound.samples, sound.rate);
        if let Some(map) = self.sound_to_face()?
            && let Some((phones, heard)) = map.recognise(aligner, samples, rate).map_err(failed)?
        {
            return Ok((phones, Some(heard)));
        }
        let lm = aligner.phone_loop(crate::align::PHONE_WEIGHT, crate::align::PHONE_PENALTY);
        Ok((aligner.recognise(samples, rate, &lm).map_err(failed)?, None))
    }

    /// The phones of the recording `audio` aligned to its `words` by `aligner` (the talker's
    /// own: [`Self::aligner`]), refused — unless `accept_mismatch` — when the words do not
    /// fit the sound, as the talker's own ear and the general model together hear it where it
    /// has an ear (far surer than the general model's fit alone, BENCHMARKS "The talker's own
    /// ear").
    pub fn hear_words(
        &self,
        aligner: &crate::align::Aligner,
        audio: &Path,
        words: &str,
        accept_mismatch: bool,
    ) -> Result<Vec<crate::align::TimedPhone>, TalkerError> {
        let sound = speech_sound(audio)?;
        let failed = |e| TalkerError::Align {
            path: audio.to_path_buf(),
            source: Box::new(e),
        };
        let (samples, rate) = (&sound.samples, sound.rate);
        if let Some(map) = self.sound_to_face()?.filter(|_| !accept_mismatch)
            && let Some(phones) = map.hear_words(aligner, samples, rate, words).map_err(failed)?
        {
            return Ok(phones);
        }
        aligner
            .hear(samples, rate, Some(words), accept_mismatch)
            .map_err(failed)
    }

    /// The talker's own aligner (the committed dictionary), loaded on first use and kept.
    pub fn aligner(&self) -> Result<&crate::align::Aligner, TalkerError> {
        self.default_aligner().map_err(|e| TalkerError::Align {
            path: self.dir.clone(),
            source: Box::new(e),
        })
    }

    /// How [`Self::recognise`] hears phones, for a note to the user.
    pub fn heard_by(&self) -> Result<&'static str, TalkerError> {
        Ok(match self.sound_to_face()? {
            Some(map) if map.hears_phones() => {
                "the phones were heard by the talker's own ear (a classifier learnt on its recordings)"
            }
            _ => "the phones were recognised by the general acoustic model (far less exact)",
        })
    }

    /// A live phone recogniser on the talker's kept aligner (16 kHz sound).
    pub fn live_recogniser(&self) -> Result<crate::align::Recogniser<'_>, crate::align::AlignError> {
        let aligner = self.default_aligner()?;
        let lm = aligner.phone_loop(crate::align::PHONE_WEIGHT, crate::align::PHONE_PENALTY);
        aligner.recogniser(crate::align::frontend::SAMPLE_RATE, &lm)
    }

    /// `text` spoken in the talker's voice (or `voice`) into the WAV `wav`, and its phones
    /// aligned to that sound; with notes for the user (a voice that was missing). The text is
    /// checked first — its length ([`crate::tts::check_text`]) and that the aligner knows
    /// every word — so text that cannot be timed never runs an engine.
    pub fn speak(
        &self,
        text: &str,
        voice: Option<&str>,
        aligner: &crate::align::Aligner,
        wav: &Path,
    ) -> Result<(Vec<Segment>, Vec<String>), TalkerError> {
        let words = |source| TalkerError::Words {
            source: Box::new(source),
        };
        crate::tts::check_text(text)?;
        aligner.phone_count(text).map_err(words)?;
        let voice = voice.or(self.manifest.voice.as_ref().map(|v| v.festival.as_str()));
        let spoken = crate::tts::speak_as(text, wav, voice)?;
        let mut notes = vec![format!(
            "the text was spoken by {} in the voice {}",
            spoken.engine.name(),
            spoken.voice
        )];
        if let Some(note) = spoken.note {
            let hint = self
                .manifest
                .voice
                .as_ref()
                .filter(|v| Some(v.festival.as_str()) == voice)
                .map(|v| format!(" (`apt-get install {}`)", v.package))
                .unwrap_or_default();
            notes.push(format!("{note}{hint}"));
        }
        let phones = aligner.align_file(wav, text).map_err(|source| TalkerError::Spoken {
            engine: spoken.engine.name(),
            source: Box::new(source),
        })?;
        Ok((phones.segments(), notes))
    }

    /// The phones of `speech` and the sound to put under them, made in `staging` when the
    /// speech is text.
    fn phones(
        &self,
        request: &SayRequest,
        staging: &Path,
        notes: &mut Vec<String>,
    ) -> Result<Heard, TalkerError> {
        // The talker's kept aligner, or one with the request's extra dictionaries.
        let extra = std::cell::OnceCell::new();
        let aligner = || -> Result<&crate::align::Aligner, crate::align::AlignError> {
            if request.dicts.is_empty() {
                return self.default_aligner();
            }
            if let Some(a) = extra.get() {
                return Ok(a);
            }
            let loaded = crate::align::Aligner::load_default(&request.dicts)?;
            Ok(extra.get_or_init(|| loaded))
        };
        let hear = |audio: &Path, words: &str| {
            let aligner = aligner().map_err(|e| TalkerError::Align {
                path: audio.to_path_buf(),
                source: Box::new(e),
            })?;
            let phones = self.hear_words(aligner, audio, words, request.accept_mismatch)?;
            Ok::<_, TalkerError>(crate::align::segments(&phones))
        };
        Ok(match &request.speech {
            Speech::Text(text) => {
                let wav = staging.join("speech.wav");
                let aligner = aligner().map_err(|e| TalkerError::Align {
                    path: self.dir.clone(),
                    source: Box::new(e),
                })?;
                let (phones, said) = self.speak(text, request.voice.as_deref(), aligner, &wav)?;
                notes.extend(said);
                (phones, Some(text.clone()), Some(wav), None)
            }
            Speech::Recording { audio, words } => {
                (hear(audio, words)?, Some(words.clone()), Some(audio.clone()), None)
            }
            // (`perform` says how the lips were drawn: by the talker's map, or these phones.)
            Speech::Sound(audio) => {
                let (phones, heard) = self.hear_sound(audio)?;
                (crate::align::segments(&phones), None, Some(audio.clone()), heard)
            }
            Speech::Labels {
                labels,
                tier,
                map,
                audio,
            } => (
                crate::phonemes::read_labels(labels, tier.as_deref(), map)?,
                None,
                audio.clone(),
                None,
            ),
            Speech::Phones { phones, audio } => (phones.clone(), None, audio.clone(), None),
        })
    }

    /// Replaces the synthesised shape and appearance of `utterance` (both variants) by
    /// what `map` predicts from the recording `audio` (from `heard`, its evidence, when the
    /// talker's ear has computed it already); the poses stay.
    fn face_from_sound(
        &self,
        map: &crate::sound_to_face::SoundToFace,
        audio: &Path,
        heard: Option<Evidence>,
        utterance: &mut crate::synth::Utterance,
    ) -> Result<(), TalkerError> {
        let heard = match heard {
            Some(heard) => heard,
            None => {
                let sound = speech_sound(audio)?;
                self.default_aligner()
                    .and_then(|a| a.acoustic_evidence(&sound.samples, sound.rate))
                    .map_err(|e| TalkerError::Align {
                        path: audio.to_path_buf(),
                        source: Box::new(e),
                    })?
            }
        };
        // One prediction for both variants (they share the frame grid).
        let raw = &utterance.synthesis.frames;
        let face = map.predict_utterance(&heard, raw.len(), raw.fps());
        let frames = std::iter::once(&mut utterance.synthesis.frames).chain(utterance.smoothed.as_mut());
        for f in frames {
            map.apply(&face, f, &utterance.target);
        }
        let (sentences, _) = map.learnt_from();
        utterance.method = if map.hears_phones() {
            format!(
                "lips from the sound: the talker's map learnt on {sentences} sentences, {:.0} % of the face, the rest from the phones its ear heard",
                100.0 * crate::sound_to_face::MAP_SHARE
            )
        } else {
            format!("lips from the sound: the talker's map learnt on {sentences} sentences")
        };
        Ok(())
    }

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
