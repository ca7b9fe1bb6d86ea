//! Subjective evaluation (issue 16): people judge the synthesis, as the source papers did.
//!
//! * A/B rating (DSCQS, \[blend\] §6): a viewer sees two renderings of the same held-out
//!   sentence and scores each on a continuous 1–50 scale (÷10 → the ITU 1–5 scale); the
//!   reference condition (the tracked original) is paired with every other condition, and
//!   smoothed with unsmoothed. Every pair is shown both ways round to every viewer.
//! * Turing test (\[unitsel\]): one clip at a time, "real or synthetic?".
//!
//! [`create()`] renders the stimuli and each viewer's randomised order into a study folder,
//! [`serve`] collects answers into an append-only log (fsync per answer), [`analyse()`] tests
//! them ([`stats`]: Wilcoxon signed-rank, Kruskal–Wallis, exact binomial).

pub mod analyse;
pub mod answers;
pub mod create;
pub mod serve;
pub mod stats;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use analyse::{Report, analyse};
pub use answers::{Answer, AnswerLog, Response};
pub use create::{CreateOptions, Heldout, create};
pub use serve::StudyServer;

/// The manifest's file name.
pub const MANIFEST: &str = "study.json";
/// The answer log's file name.
pub const ANSWERS: &str = "answers.jsonl";
/// The folder of rendered stimuli.
pub const STIMULI: &str = "stimuli";
/// What the manifest's `format` says.
pub const FORMAT: &str = "facespace-study";
/// The study folder version this build reads and writes.
pub const VERSION: u32 = 1;
/// The rating scale's ends (\[blend\] §6: 1–50, ÷10 for the ITU five-grade scale).
pub const SCALE: [f64; 2] = [1.0, 50.0];

/// What can go wrong with a study folder.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum StudyError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A manifest or answer log that is not what this build writes.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A request that cannot make a study.
    #[error("{0}")]
    Design(String),
    /// Synthesis of a stimulus failed.
    #[error("synthesising {sentence} as {condition}: {source}")]
    Synth {
        /// The held-out sentence.
        sentence: String,
        /// The condition.
        condition: Condition,
        /// The cause.
        source: Box<crate::synth::SynthError>,
    },
    /// Rendering or writing a stimulus failed.
    #[error("rendering {path}: {source}")]
    Render {
        /// The stimulus file.
        path: PathBuf,
        /// The cause.
        source: Box<crate::synth::output::OutputError>,
    },
    /// The report's plot could not be written.
    #[error(transparent)]
    Video(#[from] crate::video::VideoError),
    /// The server could not start.
    #[error(transparent)]
    Http(#[from] crate::http::HttpError),
}

impl StudyError {
    fn invalid(path: &Path, message: impl Into<String>) -> Self {
        StudyError::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
}

/// How a stimulus was made.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum Condition {
    /// The held-out sentence's own tracked trajectory, rendered like every other condition
    /// (so the renderer does not give it away).
    Original,
    /// Top-N blending (C = 1) with N examples, smoothed.
    Blend(usize),
    /// Random lips (\[blend\] §6's lower baseline), smoothed.
    RandomLips,
    /// Unit selection, smoothed.
    Unit,
    /// The default blend (C = 1, N = 3), smoothed.
    Smoothed,
    /// The default blend, unsmoothed.
    Unsmoothed,
}

impl Condition {
    /// Whether the stimulus is real footage's trajectory (for the Turing test).
    pub fn is_real(self) -> bool {
        self == Condition::Original
    }
}

impl fmt::Display for Condition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Condition::Original => write!(f, "original"),
            Condition::Blend(n) => write!(f, "blend-n{n}"),
            Condition::RandomLips => write!(f, "random-lips"),
            Condition::Unit => write!(f, "unit"),
            Condition::Smoothed => write!(f, "smoothed"),
            Condition::Unsmoothed => write!(f, "unsmoothed"),
        }
    }
}

impl FromStr for Condition {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s {
            "original" => Condition::Original,
            "random-lips" => Condition::RandomLips,
            "unit" => Condition::Unit,
            "smoothed" => Condition::Smoothed,
            "unsmoothed" => Condition::Unsmoothed,
            _ => match s.strip_prefix("blend-n").map(str::parse::<usize>) {
                Some(Ok(n)) if (1..=50).contains(&n) => Condition::Blend(n),
                _ => {
                    return Err(format!(
                        "unknown condition {s:?}: one of original, blend-nN (N = 1 … 50), random-lips, unit, smoothed, unsmoothed"
                    ));
                }
            },
        })
    }
}

impl TryFrom<String> for Condition {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl From<Condition> for String {
    fn from(c: Condition) -> String {
        c.to_string()
    }
}

/// Which tests a study runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Task {
    /// A/B rating of pairs only.
    Rating,
    /// The Turing test only (needs the original).
    Turing,
    /// The Turing test first (while viewers are naive), then the ratings.
    Both,
}

/// One rendered clip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stimulus {
    /// Its opaque id (the file name says nothing of the condition).
    pub id: String,
    /// The held-out sentence.
    pub sentence: String,
    /// How it was made.
    pub condition: Condition,
    /// Frames rendered.
    pub frames: usize,
    /// Whether the sentence's sound is muxed in.
    pub audio: bool,
}

impl Stimulus {
    /// The file's name inside `stimuli/`.
    pub fn file_name(&self) -> String {
        format!("{}.mp4", self.id)
    }
}

/// One step of a viewer's session.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Trial {
    /// Score both clips of a pair (stimulus ids, in the order shown).
    Rate {
        /// Shown first (left, "A").
        first: String,
        /// Shown second (right, "B").
        second: String,
    },
    /// Real or synthetic?
    Judge {
        /// The clip.
        stimulus: String,
    },
}

impl Trial {
    /// The stimulus ids shown, in order.
    pub fn stimuli(&self) -> Vec<&str> {
        match self {
            Trial::Rate { first, second } => vec![first, second],
            Trial::Judge { stimulus } => vec![stimulus],
        }
    }
}

/// A viewer: an id, the secret in their link, and their trials in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Viewer {
    /// The viewer's id (`v01`, …).
    pub id: String,
    /// The secret in the viewer's link: answers without it are refused.
    pub token: String,
    /// The trials in the order shown.
    pub trials: Vec<Trial>,
}

/// `study.json`: everything the server and the analysis need.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// The tests run.
    pub task: Task,
    /// The conditions, as asked.
    pub conditions: Vec<Condition>,
    /// The rated pairs (each shown both ways round).
    pub pairs: Vec<(Condition, Condition)>,
    /// The held-out sentences.
    pub sentences: Vec<String>,
    /// Smoothing weight λ of every smoothed condition.
    pub smoothing: f64,
    /// Seed of the orders.
    pub seed: u64,
    /// Frames per second of every stimulus.
    pub fps: f64,
    /// The model the stimuli were rendered with.
    pub model_hash: String,
    /// The rendered clips.
    pub stimuli: Vec<Stimulus>,
    /// Every clip's size, width × height: a window of its sentence's frames centred on the
    /// face, [`create::FACE_SHARE`] of it the face's extent.
    #[serde(default)]
    pub canvas: [u32; 2],
    /// Whether the stimuli are drawn over their sentences' own recordings (`NAME.mp4` beside
    /// the held-out sentence) rather than a plain grey.
    #[serde(default)]
    pub over_recordings: bool,
    /// The viewers.
    pub viewers: Vec<Viewer>,
}

impl Manifest {
    /// Reads and checks `dir/study.json`: format, version, and every trial naming a stimulus.
    pub fn load(dir: &Path) -> Result<Manifest, StudyError> {
        let path = dir.join(MANIFEST);
        let text =
            crate::safe_read::read_regular_string(&path).map_err(|source| StudyError::Io {
                path: path.clone(),
                source,
            })?;
        let value: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| StudyError::invalid(&path, format!("not JSON: {e}")))?;
        if value["format"] != FORMAT {
            return Err(StudyError::invalid(
                &path,
                format!("not a facespace study (format {})", value["format"]),
            ));
        }
        if value["version"] != VERSION {
            return Err(StudyError::invalid(
                &path,
                format!(
                    "a study folder of version {}; this facespace reads version {VERSION} (make the study again with this build, or use the build that made it)",
                    value["version"]
                ),
            ));
        }
        let manifest: Manifest =
            serde_json::from_value(value).map_err(|e| StudyError::invalid(&path, e.to_string()))?;
        manifest
            .check()
            .map_err(|m| StudyError::invalid(&path, m))?;
        Ok(manifest)
    }

    fn check(&self) -> Result<(), String> {
        let mut ids = std::collections::HashSet::new();
        for s in &self.stimuli {
            if s.id.is_empty() || !s.id.bytes().all(|b| b.is_ascii_alphanumeric()) {
                return Err(format!("stimulus id {:?} is not alphanumeric", s.id));
            }
            if !ids.insert(s.id.as_str()) {
                return Err(format!("stimulus id {} twice", s.id));
            }
        }
        let mut viewers = std::collections::HashSet::new();
        for v in &self.viewers {
            if !viewers.insert(v.id.as_str()) {
                return Err(format!("viewer {} twice", v.id));
            }
            if v.token.len() < 16 {
                return Err(format!("viewer {}: token too short", v.id));
            }
            for t in &v.trials {
                if let Some(id) = t.stimuli().into_iter().find(|id| !ids.contains(id)) {
                    return Err(format!("viewer {}: unknown stimulus {id}", v.id));
                }
            }
        }
        Ok(())
    }

    /// The stimulus with id `id`.
    pub fn stimulus(&self, id: &str) -> Option<&Stimulus> {
        self.stimuli.iter().find(|s| s.id == id)
    }

    /// The viewer with id `id`.
    pub fn viewer(&self, id: &str) -> Option<&Viewer> {
        self.viewers.iter().find(|v| v.id == id)
    }

    /// A viewer's link on a server at `url` (ending in `/`).
    pub fn link(&self, url: &str, viewer: &Viewer) -> String {
        format!("{url}?viewer={}&token={}", viewer.id, viewer.token)
    }
}
