//! Corpora: sentences of one talker as face-space frames with their phone labels — the raw
//! material of a codebook. A corpus folder holds `NAME.npy` (frames × face-space, float32) with
//! `NAME.lab`, `NAME.TextGrid` or `NAME.tsv` beside it; [`demo`] generates one for the demo
//! talker, whose video has no sound to label.

pub mod demo;
mod recordings;

pub use recordings::{
    DEFAULT_MAX_FAILED, Reading, Recorded, RecordedCorpus, Shard, Skipped, VIDEO_EXTENSIONS, from_recordings,
    merge,
};

use std::path::{Path, PathBuf};

use ndarray::Array2;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::facespace::{FacespaceError, Frames, Layout};
use crate::npy::{self, NpyError};
use crate::phonemes::{self, PhoneMap, PhonemeError, Segment};

/// What can be wrong with a corpus.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CorpusError {
    /// The folder could not be listed.
    #[error("{path}: {source}")]
    Io {
        /// The folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A trajectory file is damaged or of another width.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// A label file is damaged.
    #[error(transparent)]
    Phonemes(#[from] PhonemeError),
    /// Frames that do not fit the layout or rate.
    #[error("{path}: {source}")]
    Frames {
        /// The trajectory file.
        path: PathBuf,
        /// What is wrong.
        source: FacespaceError,
    },
    /// A `corpus.json` that is damaged or records nonsense.
    #[error("{path}: {reason}")]
    Manifest {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the field.
        reason: String,
    },
    /// No sentences in the folder.
    #[error("{dir}: no .npy trajectories with label files")]
    Empty {
        /// The folder.
        dir: PathBuf,
    },
    /// A trajectory without labels.
    #[error(
        "{npy}: no label file of the same name (.lab, .TextGrid or .tsv; beside a video, a .txt transcript is aligned)"
    )]
    MissingLabels {
        /// The trajectory.
        npy: PathBuf,
    },
    /// More recordings failed than the share allowed.
    #[error(
        "{dir}: {failed} of {total} recordings could not be used (more than {:.0} % allowed; --max-failed changes it):\n  {}",
        .max_share * 100.0, .reasons.join("\n  ")
    )]
    TooManyFailed {
        /// The recordings' folder.
        dir: PathBuf,
        /// How many failed.
        failed: usize,
        /// How many there are.
        total: usize,
        /// The share allowed.
        max_share: f64,
        /// Each failure, named.
        reasons: Vec<String>,
    },
    /// A recording's sound could not be aligned to its transcript.
    #[error("{path}: {reason}")]
    Align {
        /// The recording (or the acoustic model).
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// A recording could not be tracked or projected.
    #[error("{}", with_path(path, source))]
    Encode {
        /// The recording.
        path: PathBuf,
        /// The cause.
        source: Box<crate::codec::CodecError>,
    },
    /// Labels and frames of different lengths.
    #[error(
        "{npy} lasts {frames_s:.3} s ({frames} frames at {fps} fps) but {labels} ends at {labels_s:.3} s: more than the {tolerance} s allowed apart (is the frame rate right?)"
    )]
    DurationMismatch {
        /// The trajectory.
        npy: PathBuf,
        /// The labels.
        labels: PathBuf,
        /// Its frames.
        frames: usize,
        /// The frame rate.
        fps: f64,
        /// Seconds of frames.
        frames_s: f64,
        /// Where the labels end.
        labels_s: f64,
        /// The most they may differ, seconds.
        tolerance: f64,
    },
}

/// How far (seconds) labels may end from the frames' end by default: forced-aligner output
/// (ours, pocketsphinx's) ends where the sound does, which can differ from the video's last
/// frame by a few frames.
pub const DEFAULT_TOLERANCE: f64 = 0.2;

/// The corpus folder's record of its frame rate, written by the commands that make corpora.
pub const MANIFEST: &str = "corpus.json";

/// Writes `dir/corpus.json` recording the corpus's frame rate (an error names the file).
pub fn write_manifest(dir: &Path, fps: f64) -> Result<(), (PathBuf, std::io::Error)> {
    let json = serde_json::json!({ "format": "facespace-corpus", "fps": fps });
    let path = dir.join(MANIFEST);
    crate::atomic::write_file(&path, json.to_string().as_bytes()).map_err(|e| (path, e))
}

/// The frame rate `dir/corpus.json` records; `None` only when the folder has no such file.
/// A `corpus.json` that is not a regular file, not JSON, or whose `fps` is missing, not a
/// number or out of range is an error naming the file and the field (a manifest that lies is
/// never taken for an absent one).
pub fn recorded_fps(dir: &Path) -> Result<Option<f64>, CorpusError> {
    let path = dir.join(MANIFEST);
    match std::fs::symlink_metadata(&path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        _ => {}
    }
    let invalid = |reason: String| CorpusError::Manifest {
        path: path.clone(),
        reason,
    };
    let text = crate::safe_read::read_regular_string(&path).map_err(|source| CorpusError::Io {
        path: path.clone(),
        source,
    })?;
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(format!("not JSON ({e})")))?;
    let fps = match value.get("fps") {
        Some(serde_json::Value::Number(n)) => n.as_f64().unwrap_or(f64::NAN),
        Some(other) => {
            let shown: String = other.to_string().chars().take(40).collect();
            return Err(invalid(format!("field \"fps\" is {shown}, not a number")));
        }
        None => return Err(invalid("no field \"fps\" (the corpus's frame rate)".into())),
    };
    crate::facespace::check_fps(fps)
        .map(Some)
        .map_err(|e| invalid(format!("field \"fps\": {e}")))
}

/// One sentence: face-space frames and the phones spoken over them.
#[derive(Clone, Debug, PartialEq)]
pub struct Sentence {
    /// Name (the file stem).
    pub name: String,
    /// Where the frames and labels came from.
    pub source: String,
    /// The face-space frames.
    pub frames: Frames,
    /// The phone intervals, in seconds from the first frame.
    pub segments: Vec<Segment>,
}

/// Photometric normalisation of a corpus's appearance before it becomes a codebook.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Photometric {
    /// The appearance as tracked.
    #[default]
    None,
    /// Each sentence's mean appearance replaced by the corpus's: lighting that drifts between
    /// recording sessions (a constant offset per sentence in appearance space) stops looking
    /// like articulation, and segments of different sentences join without a brightness step.
    Sentence,
}

/// Re-centres every sentence's appearance parameters on the corpus mean (see
/// [`Photometric::Sentence`]): per sentence `b_a(t) − mean_t b_a + mean over all frames`.
/// Pose and shape are untouched, and so is each sentence's motion about its mean.
pub fn recentre_appearance(sentences: &mut [Sentence]) {
    let Some(first) = sentences.first() else {
        return;
    };
    let range = first.frames.layout().appearance_range();
    let dims = range.len();
    let mut grand = vec![0f64; dims];
    let mut means = Vec::with_capacity(sentences.len());
    let mut frames = 0usize;
    for s in sentences.iter() {
        let v = s.frames.values();
        let mut m = vec![0f64; dims];
        for row in v.rows() {
            for (k, &x) in row.iter().skip(range.start).take(dims).enumerate() {
                m[k] += x as f64;
            }
        }
        frames += v.nrows();
        grand.iter_mut().zip(&m).for_each(|(g, &x)| *g += x);
        let n = v.nrows().max(1) as f64;
        means.push(m.into_iter().map(|x| x / n).collect::<Vec<_>>());
    }
    grand.iter_mut().for_each(|g| *g /= frames.max(1) as f64);
    for (s, m) in sentences.iter_mut().zip(&means) {
        let mut v = s.frames.values_mut();
        for mut row in v.rows_mut() {
            for k in 0..dims {
                row[range.start + k] = (row[range.start + k] as f64 - m[k] + grand[k]) as f32;
            }
        }
    }
}

/// Reads a face-space trajectory file (`frames × layout.dims()`, float32) at `fps`.
pub fn read_frames(path: &Path, layout: Layout, fps: f64) -> Result<Frames, CorpusError> {
    // Any width is read, so that a file of another model is reported against the layout.
    let values: Array2<f32> = npy::read_checked(path, &[None, None])?;
    Frames::new(layout, fps, values).map_err(|source| CorpusError::Frames {
        path: path.into(),
        source,
    })
}

/// Label file extensions tried, in order, beside each `.npy`.
pub const LABEL_EXTENSIONS: [&str; 4] = ["lab", "TextGrid", "textgrid", "tsv"];

/// `path: cause`, unless the cause already starts with the path (most do).
fn with_path(path: &Path, cause: &dyn std::fmt::Display) -> String {
    let cause = cause.to_string();
    let shown = path.display().to_string();
    if cause.starts_with(&shown) {
        cause
    } else {
        format!("{shown}: {cause}")
    }
}

/// Reads a corpus folder: every `NAME.npy` (frames × `layout` face-space parameters at `fps`)
/// with `NAME.lab`, `NAME.TextGrid` or `NAME.tsv`. The labels must end within
/// [`DEFAULT_TOLERANCE`] of the frames' duration.
pub fn load(
    dir: &Path,
    fps: f64,
    layout: Layout,
    tier: Option<&str>,
    map: &PhoneMap,
) -> Result<Vec<Sentence>, CorpusError> {
    load_checked(dir, fps, layout, None, tier, map, DEFAULT_TOLERANCE)
}

/// [`load`], also reading encoded clip folders (`NAME.fsp/`, float or quantised, from
/// `facespace encode`) in place of `NAME.npy`; `model_hash` (when given) must be theirs;
/// labels may end up to `tolerance` seconds from the frames' end.
pub fn load_checked(
    dir: &Path,
    fps: f64,
    layout: Layout,
    model_hash: Option<&str>,
    tier: Option<&str>,
    map: &PhoneMap,
    tolerance: f64,
) -> Result<Vec<Sentence>, CorpusError> {
    let io = |source| CorpusError::Io {
        path: dir.into(),
        source,
    };
    let mut files = crate::video::files_with_extension(dir, "npy").map_err(io)?;
    for e in std::fs::read_dir(dir).map_err(io)? {
        let p = e.map_err(io)?.path();
        if p.is_dir() && p.extension().is_some_and(|x| x == "fsp") {
            files.push(p);
        }
    }
    files.sort();
    if files.is_empty() {
        return Err(CorpusError::Empty { dir: dir.into() });
    }
    let mut sentences = Vec::with_capacity(files.len());
    for npy_path in files {
        let labels = LABEL_EXTENSIONS
            .iter()
            .map(|e| npy_path.with_extension(e))
            .find(|p| p.is_file())
            .ok_or_else(|| CorpusError::MissingLabels {
                npy: npy_path.clone(),
            })?;
        let frames = if npy_path.is_dir() {
            let clip =
                crate::codec::Clip::load_for(&npy_path, model_hash, layout).map_err(|source| {
                    CorpusError::Encode {
                        path: npy_path.clone(),
                        source: Box::new(source),
                    }
                })?;
            if (clip.frames.fps() - fps).abs() > 1e-9 {
                return Err(CorpusError::Encode {
                    path: npy_path.clone(),
                    source: Box::new(crate::codec::CodecError::Invalid {
                        path: npy_path.join("meta.json"),
                        message: format!(
                            "the clip is at {} fps, the corpus is read at {fps}",
                            clip.frames.fps()
                        ),
                    }),
                });
            }
            clip.frames
        } else {
            read_frames(&npy_path, layout, fps)?
        };
        let segments = phonemes::read_labels(&labels, tier, map)?;
        let (frames_s, labels_s) = (frames.duration(), segments[segments.len() - 1].end);
        if (frames_s - labels_s).abs() > tolerance {
            return Err(CorpusError::DurationMismatch {
                npy: npy_path,
                labels,
                frames: frames.len(),
                fps,
                frames_s,
                labels_s,
                tolerance,
            });
        }
        let name = npy_path
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let source = format!("{} + {}", npy_path.display(), labels.display());
        sentences.push(Sentence {
            name,
            source,
            frames,
            segments,
        });
    }
    Ok(sentences)
}
