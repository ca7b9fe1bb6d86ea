//! A corpus from recordings (issue 15): each `NAME.mp4` (or `NAME.y4m`, a frame folder
//! `NAME/`, any video a system ffmpeg reads) beside its `NAME.lab` / `NAME.TextGrid` /
//! `NAME.tsv` is tracked and projected to face-space, its duration checked against its labels,
//! and written as the corpus folder `codebook build` reads, sound carried as `NAME.m4a`.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::{CorpusError, LABEL_EXTENSIONS};
use crate::codec::{self, EncodeOptions, TrackingSummary};
use crate::model::FaceModel;
use crate::phonemes::{self, PhoneMap};
use crate::video::{self, Source};
use crate::{Progress, atomic};

/// Video file extensions looked for (frame folders count too).
const VIDEO_EXTENSIONS: &[&str] = &["mp4", "m4v", "mov", "y4m", "mkv", "avi", "webm"];

/// One recorded sentence as written.
#[derive(Clone, Debug, PartialEq)]
pub struct Recorded {
    /// Its name (the file stem).
    pub name: String,
    /// Frames tracked.
    pub frames: usize,
    /// How tracking went.
    pub tracking: TrackingSummary,
    /// Whether its sound was kept (`NAME.m4a`).
    pub audio: bool,
}

/// The recordings in `dir`: (name, video, labels), sorted by name.
fn recordings(dir: &Path) -> Result<Vec<(String, PathBuf, PathBuf)>, CorpusError> {
    let io = |source| CorpusError::Io {
        path: dir.into(),
        source,
    };
    let mut found = Vec::new();
    for e in std::fs::read_dir(dir).map_err(io)? {
        let path = e.map_err(io)?.path();
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        if name.starts_with('.') {
            continue;
        }
        let is_video = if path.is_dir() {
            true
        } else {
            path.extension()
                .and_then(|x| x.to_str())
                .is_some_and(|x| VIDEO_EXTENSIONS.contains(&x.to_ascii_lowercase().as_str()))
        };
        if !is_video {
            continue;
        }
        let stem = if path.is_dir() {
            name.into_owned()
        } else {
            path.file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned()
        };
        let labels = LABEL_EXTENSIONS
            .iter()
            .map(|x| dir.join(format!("{stem}.{x}")))
            .find(|p| p.is_file())
            .ok_or_else(|| CorpusError::MissingLabels { npy: path.clone() })?;
        found.push((stem, path, labels));
    }
    if found.is_empty() {
        return Err(CorpusError::Empty { dir: dir.into() });
    }
    found.sort();
    Ok(found)
}

/// Tracks and projects every recording in `dir` with `model` (videos in parallel) and writes
/// the corpus folder `out` atomically: `NAME.npy`, the label file, `NAME.m4a` when the video
/// has sound. Labels must end within two frames of the video's duration; every video must
/// have the same frame rate (a codebook has one), which is returned with the sentences.
pub fn from_recordings(
    model: &FaceModel,
    dir: &Path,
    out: &Path,
    options: &EncodeOptions,
    tier: Option<&str>,
    map: &PhoneMap,
    progress: impl FnMut(Progress) + Send,
) -> Result<(f64, Vec<Recorded>), CorpusError> {
    let found = recordings(dir)?;
    let progress = std::sync::Mutex::new(progress);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let encoded = found
        .par_iter()
        .map(|(name, video, labels)| {
            let encode_error = |source| CorpusError::Encode {
                path: video.clone(),
                source: Box::new(source),
            };
            let source =
                Source::open(video).map_err(|e| encode_error(codec::CodecError::Video(e)))?;
            let clip = codec::encode(model, source, options, |_| {})
                .map_err(encode_error)?
                .clip;
            let segments = phonemes::read_labels(labels, tier, map)?;
            let fps = clip.frames.fps();
            let (frames_s, labels_s) = (clip.frames.duration(), segments[segments.len() - 1].end);
            if (frames_s - labels_s).abs() > 2.0 / fps {
                return Err(CorpusError::DurationMismatch {
                    npy: video.clone(),
                    labels: labels.clone(),
                    frames: clip.frames.len(),
                    fps,
                    frames_s,
                    labels_s,
                });
            }
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            (progress.lock().unwrap_or_else(|e| e.into_inner()))(Progress {
                stage: "tracking recordings",
                done: n,
                total: found.len(),
            });
            Ok((name, video, labels, clip))
        })
        .collect::<Result<Vec<_>, CorpusError>>()?;
    let fps = encoded[0].3.frames.fps();
    if let Some((name, ..)) = encoded
        .iter()
        .find(|e| (e.3.frames.fps() - fps).abs() > 1e-9)
    {
        return Err(CorpusError::Io {
            path: dir.join(name),
            source: std::io::Error::other(format!(
                "its frame rate differs from {}'s ({fps} fps): a codebook has one frame rate",
                encoded[0].0
            )),
        });
    }
    let mut written = Vec::with_capacity(encoded.len());
    atomic::replace_dir(
        out,
        "corpus",
        |staged| -> Result<(), CorpusError> {
            for (name, video, labels, clip) in &encoded {
                crate::npy::write(&staged.join(format!("{name}.npy")), clip.frames.values())?;
                let ext = labels.extension().unwrap_or_default().to_string_lossy();
                let copy = staged.join(format!("{name}.{ext}"));
                std::fs::copy(labels, &copy).map_err(|source| CorpusError::Io {
                    path: copy.clone(),
                    source,
                })?;
                let audio = video.is_file()
                    && video::extract_audio(video, &staged.join(format!("{name}.m4a"))).map_err(
                        |e| CorpusError::Encode {
                            path: video.to_path_buf(),
                            source: Box::new(codec::CodecError::Video(e)),
                        },
                    )?;
                written.push(Recorded {
                    name: name.to_string(),
                    frames: clip.frames.len(),
                    tracking: TrackingSummary::of(&clip.tracking),
                    audio,
                });
            }
            Ok(())
        },
        |source| CorpusError::Io {
            path: out.into(),
            source,
        },
    )?;
    Ok((fps, written))
}
