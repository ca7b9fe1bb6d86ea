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
use crate::{Progress, align, atomic, audio};

/// A recording's own sound aligned to its transcript → phone segments.
fn align_transcript(
    aligner: &align::Aligner,
    video: &Path,
    transcript: &Path,
    accept_mismatch: bool,
) -> Result<Vec<phonemes::Segment>, CorpusError> {
    let fail = |reason: String| CorpusError::Align {
        path: video.to_owned(),
        reason,
    };
    let text =
        crate::safe_read::read_regular_string(transcript).map_err(|source| CorpusError::Io {
            path: transcript.to_owned(),
            source,
        })?;
    // The recording's own sound: its audio track, or for a frame folder (or a silent video)
    // a `NAME.wav` / `NAME.m4a` beside it.
    let beside = ["wav", "m4a"]
        .iter()
        .map(|x| transcript.with_extension(x))
        .find(|p| p.is_file());
    let sound = beside.as_deref().unwrap_or(video);
    let speech = audio::read(sound, align::frontend::SAMPLE_RATE, align::MAX_SECONDS)
        .map_err(|e| fail(e.to_string()))?;
    let phones = aligner
        .hear(&speech.samples, speech.rate, Some(&text), accept_mismatch)
        .map_err(|e| fail(format!("aligning {}: {e}", transcript.display())))?;
    Ok(align::segments(&phones))
}

/// Video file extensions looked for (frame folders count too).
pub const VIDEO_EXTENSIONS: &[&str] = &["mp4", "m4v", "mov", "y4m", "mkv", "avi", "webm"];

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

/// Where a recording's phone timings come from.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Timings {
    /// A label file (`.lab`, `.TextGrid`, `.tsv`).
    Labels(PathBuf),
    /// A transcript (`NAME.txt`) to align on the recording's sound.
    Transcript(PathBuf),
}

/// The recordings in `dir`: (name, video, timings), sorted by name.
fn recordings(dir: &Path) -> Result<Vec<(String, PathBuf, Timings)>, CorpusError> {
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
            .map(Timings::Labels)
            .or_else(|| {
                let txt = dir.join(format!("{stem}.txt"));
                txt.is_file().then_some(Timings::Transcript(txt))
            })
            .ok_or_else(|| CorpusError::MissingLabels { npy: path.clone() })?;
        found.push((stem, path, labels));
    }
    if found.is_empty() {
        return Err(CorpusError::Empty { dir: dir.into() });
    }
    found.sort();
    Ok(found)
}

/// A recording left out of the corpus, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Skipped {
    /// Its name.
    pub name: String,
    /// What was wrong with it (the error, naming the file and frame where known).
    pub reason: String,
}

/// What [`from_recordings`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedCorpus {
    /// The corpus's frame rate.
    pub fps: f64,
    /// The sentences written.
    pub sentences: Vec<Recorded>,
    /// The recordings left out.
    pub skipped: Vec<Skipped>,
}

/// One part of a corpus made on many machines: the recordings whose place in name order is
/// `index` modulo `count` (a job array hands each task its index; [`merge`] joins the parts
/// into the folder one run over everything writes, file for file).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This part, from 0.
    pub index: usize,
    /// How many parts.
    pub count: usize,
}

impl Default for Shard {
    /// The whole corpus.
    fn default() -> Self {
        Shard { index: 0, count: 1 }
    }
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `K/N` with 0 ≤ K < N (e.g. `$SLURM_ARRAY_TASK_ID/8`).
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || {
            format!(
                "{s:?}: expected K/N with 0 ≤ K < N (the task's index from 0, and the task count)"
            )
        };
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (
            k.trim().parse::<usize>().map_err(|_| bad())?,
            n.trim().parse::<usize>().map_err(|_| bad())?,
        );
        if count == 0 || index >= count || count > 100_000 {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

/// Share of recordings that may fail before the whole corpus is refused (`--max-failed`).
pub const DEFAULT_MAX_FAILED: f64 = 0.10;

/// How [`from_recordings`] reads the recordings' timings, and how much failure it takes.
#[derive(Clone, Debug)]
pub struct Reading {
    /// TextGrid tier of the label files (default: "phones" or "phonemes").
    pub tier: Option<String>,
    /// Another phone set's labels to ARPAbet.
    pub map: PhoneMap,
    /// Share of recordings that may fail before the whole corpus is refused.
    pub max_failed: f64,
    /// Seconds the labels may end from the video's end.
    pub tolerance: f64,
    /// Which part of the recordings to make.
    pub shard: Shard,
    /// Align transcripts even when they do not seem to be what is said (by default such a
    /// recording fails, naming its worst words).
    pub accept_mismatch: bool,
}

impl Default for Reading {
    fn default() -> Self {
        Reading {
            tier: None,
            map: PhoneMap::default(),
            max_failed: DEFAULT_MAX_FAILED,
            tolerance: super::DEFAULT_TOLERANCE,
            shard: Shard::default(),
            accept_mismatch: false,
        }
    }
}

/// Tracks and projects every recording in `dir` with `model` (videos in parallel) and writes
/// the corpus folder `out` atomically: `NAME.npy`, the label file, `NAME.m4a` when the video
/// has sound, and `corpus.json` with the frame rate. Labels must end within `reading.tolerance`
/// seconds of the video's duration; every video must have the same frame rate (a codebook
/// has one). A recording that cannot be used (damaged
/// frames, a face lost, labels that do not fit, a transcript whose words do not fit the sound) is left out and named in the result, unless
/// more than `reading.max_failed` of them fail: then nothing is written and every failure is named.
/// With a `reading.shard` other than the whole, only that part of the recordings is made (the share
/// that may fail counts within it).
pub fn from_recordings(
    model: &FaceModel,
    dir: &Path,
    out: &Path,
    options: &EncodeOptions,
    reading: &Reading,
    progress: impl FnMut(Progress) + Send,
) -> Result<RecordedCorpus, CorpusError> {
    let Reading {
        tier,
        map,
        max_failed,
        tolerance,
        shard,
        accept_mismatch,
    } = reading;
    let (tier, max_failed, tolerance, shard) = (tier.as_deref(), *max_failed, *tolerance, *shard);
    let found: Vec<_> = recordings(dir)?
        .into_iter()
        .enumerate()
        .filter(|(i, _)| i % shard.count == shard.index)
        .map(|(_, f)| f)
        .collect();
    if found.is_empty() {
        return Err(CorpusError::Empty { dir: dir.into() });
    }
    // The aligner is loaded once, and only when some recording has just a transcript.
    let aligner = if found.iter().any(|f| matches!(f.2, Timings::Transcript(_))) {
        Some(
            align::Aligner::load_default(&[]).map_err(|e| CorpusError::Align {
                path: align::default_model_dir(),
                reason: e.to_string(),
            })?,
        )
    } else {
        None
    };
    let progress = std::sync::Mutex::new(progress);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<Result<_, CorpusError>> = found
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
            let segments = match labels {
                Timings::Labels(path) => phonemes::read_labels(path, tier, map)?,
                Timings::Transcript(path) => {
                    let aligner = aligner.as_ref().expect("loaded for transcripts");
                    align_transcript(aligner, video, path, *accept_mismatch)?
                }
            };
            let fps = clip.frames.fps();
            let (frames_s, labels_s) = (clip.frames.duration(), segments[segments.len() - 1].end);
            if (frames_s - labels_s).abs() > tolerance {
                let (Timings::Labels(labels) | Timings::Transcript(labels)) = labels;
                return Err(CorpusError::DurationMismatch {
                    npy: video.clone(),
                    labels: labels.clone(),
                    frames: clip.frames.len(),
                    fps,
                    frames_s,
                    labels_s,
                    tolerance,
                });
            }
            Ok((name, video, labels, segments, clip))
        })
        .inspect(|_| {
            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            (progress.lock().unwrap_or_else(|e| e.into_inner()))(Progress {
                stage: "tracking recordings",
                done: n,
                total: found.len(),
            });
        })
        .collect();
    let mut encoded = Vec::with_capacity(results.len());
    let mut skipped = Vec::new();
    for ((name, ..), result) in found.iter().zip(results) {
        match result {
            Ok(e) => encoded.push(e),
            Err(e) => skipped.push(Skipped {
                name: name.clone(),
                reason: e.to_string(),
            }),
        }
    }
    if encoded.is_empty() || skipped.len() as f64 > max_failed * found.len() as f64 {
        return Err(CorpusError::TooManyFailed {
            dir: dir.into(),
            failed: skipped.len(),
            total: found.len(),
            max_share: max_failed,
            reasons: skipped
                .iter()
                .map(|s| format!("{}: {}", s.name, s.reason))
                .collect(),
        });
    }
    let fps = encoded[0].4.frames.fps();
    if let Some(odd) = encoded
        .iter()
        .find(|e| (e.4.frames.fps() - fps).abs() > 1e-9)
    {
        return Err(CorpusError::Io {
            path: odd.1.to_path_buf(),
            source: std::io::Error::other(format!(
                "{} fps, but {} is at {fps} fps: a codebook has one frame rate (convert it, or leave it out)",
                odd.4.frames.fps(),
                encoded[0].1.display()
            )),
        });
    }
    let mut written = Vec::with_capacity(encoded.len());
    write_corpus(out, fps, |staged| {
        for (name, video, labels, segments, clip) in &encoded {
            crate::npy::write(&staged.join(format!("{name}.npy")), clip.frames.values())?;
            match labels {
                Timings::Labels(labels) => {
                    let ext = labels.extension().unwrap_or_default().to_string_lossy();
                    let copy = staged.join(format!("{name}.{ext}"));
                    std::fs::copy(labels, &copy).map_err(|source| CorpusError::Io {
                        path: copy.clone(),
                        source,
                    })?;
                }
                Timings::Transcript(_) => {
                    phonemes::write_labels(&staged.join(format!("{name}.lab")), segments)?;
                }
            }
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
    })?;
    Ok(RecordedCorpus {
        fps,
        sentences: written,
        skipped,
    })
}

/// Joins corpus folders made as [`Shard`]s of one folder of recordings into `out`: every
/// file of every part (their `corpus.json` must agree on the frame rate, and no name may come
/// twice), written atomically like a corpus of one run — so the result equals, file for
/// file, the corpus one run over all the recordings writes. Returns the frame rate and how
/// many files were joined.
pub fn merge(parts: &[PathBuf], out: &Path) -> Result<(f64, usize), CorpusError> {
    let mut fps: Option<(f64, &Path)> = None;
    let mut files: std::collections::BTreeMap<String, PathBuf> = Default::default();
    for part in parts {
        let io = |source| CorpusError::Io {
            path: part.clone(),
            source,
        };
        let recorded = super::recorded_fps(part)?.ok_or_else(|| CorpusError::Manifest {
            path: part.join(super::MANIFEST),
            reason: "missing: every part must be a corpus folder written by `corpus from-videos`"
                .into(),
        })?;
        match fps {
            Some((f, first)) if (f - recorded).abs() > 1e-9 => {
                return Err(CorpusError::Manifest {
                    path: part.join(super::MANIFEST),
                    reason: format!(
                        "field \"fps\": {recorded}, but {} records {f}: the parts are of different corpora",
                        first.display()
                    ),
                });
            }
            Some(_) => {}
            None => fps = Some((recorded, part)),
        }
        for e in std::fs::read_dir(part).map_err(io)? {
            let e = e.map_err(io)?;
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') || name == super::MANIFEST {
                continue;
            }
            if !e.file_type().map_err(io)?.is_file() {
                return Err(io(std::io::Error::other(format!(
                    "{name} is not a regular file: not a corpus part"
                ))));
            }
            if let Some(other) = files.insert(name.clone(), e.path()) {
                return Err(io(std::io::Error::other(format!(
                    "{name} is also in {}: the parts overlap",
                    other.parent().unwrap_or(Path::new("")).display()
                ))));
            }
        }
    }
    let Some((fps, _)) = fps else {
        return Err(CorpusError::Empty { dir: out.into() });
    };
    write_corpus(out, fps, |staged| {
        for (name, from) in &files {
            let to = staged.join(name);
            std::fs::copy(from, &to).map_err(|source| CorpusError::Io { path: to, source })?;
        }
        Ok(())
    })?;
    Ok((fps, files.len()))
}

/// Writes the corpus folder `out` atomically ([`atomic::replace_dir`]): its `corpus.json`
/// recording `fps`, and what `fill` puts beside it.
fn write_corpus(
    out: &Path,
    fps: f64,
    fill: impl FnOnce(&Path) -> Result<(), CorpusError>,
) -> Result<(), CorpusError> {
    atomic::replace_dir(
        out,
        "corpus",
        |staged| {
            super::write_manifest(staged, fps)
                .map_err(|(path, source)| CorpusError::Io { path, source })?;
            fill(staged)
        },
        |source| CorpusError::Io {
            path: out.into(),
            source,
        },
    )
}
