//! A talker: everything needed to make one person speak, in one folder (issue 33).
//!
//! `talker.json` names the parts and holds the synthesis settings chosen on validation:
//!
//! - `model/`: the whole-face model that tracked the footage and draws the face;
//! - `codebook/`: the codebook of the talker's sentences in that model's space;
//! - `footage/`: idle footage, tracked ([`footage`]): the living frame every utterance is
//!   drawn over, only the lips and jaw replaced.
//!
//! [`Talker::say`] is the pipeline from speech (text, a recording with its words, phone labels
//! or phones) to a video with sound, and [`Talker::say_parts`] the same into a folder of parts:
//! `say`, `synth --talker`, the GRID demo and the Python package call them, varying only what
//! a [`SayRequest`] says (the canvas, the method, the smoothing, the model's mouth for A/B). The manifest and its check are in `manifest`, hearing speech in `hearing`,
//! the request and the pipeline in `perform`.

pub mod build;
mod hearing;
mod manifest;
mod perform;

pub use manifest::{
    MANIFEST, MAX_APPEARANCE_GAIN, MAX_TOP_N, Mode, Provenance, Settings, TALKER_VERSION,
    TalkerManifest, Voice, read_manifest,
};
pub use perform::{Canvas, Method, Performance, Real, SayReport, SayRequest, Speech};

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::atomic;
use crate::codebook::{Codebook, CodebookError};
use crate::manifest::ManifestError;
use crate::model::{FaceModel, ModelError};
use crate::phonemes::PhonemeError;
use crate::render::RenderError;
use crate::synth::SynthError;
use crate::synth::output::OutputError;
use crate::video::VideoError;
use crate::footage::{Footage, FootageError};

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
    /// A strict request for phones the codebook lacks ([`SayRequest::strict`]).
    #[error(
        "strict: the codebook of talker {dir} has no example of {phones}; build it from sentences that have them, or let it borrow the nearest phones"
    )]
    Borrowed {
        /// The talker folder.
        dir: PathBuf,
        /// The phones, where they fall and what would stand in.
        phones: String,
    },
    /// The real trajectory to plot could not be read.
    #[error("the real trajectory: {0}")]
    Real(Box<crate::corpus::CorpusError>),
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
        let part = |name: &str| crate::manifest::member(dir, name).map_err(manifest_error);
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
            let path = crate::manifest::member(&self.dir, name)
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
            let path = crate::manifest::member(&self.dir, name)
                .map_err(crate::mouths::MouthsError::Manifest)?;
            crate::mouths::Mouths::load_for(&path, &self.model, &self.model_hash)
        };
        loaded_once(&self.mouths, load).map(Some).map_err(|source| TalkerError::Mouths {
            dir: self.dir.clone(),
            source: Box::new(source),
        })
    }
}
