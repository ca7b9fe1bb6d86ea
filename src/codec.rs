//! Video through face-space (DESIGN §1 last line, §11): *encode* tracks every frame with the
//! AAM search and projects it to a face-space point; *decode* reconstructs and renders every
//! point. A clip folder (`clip.fsp/`) holds `meta.json` and `params.npy` — frames ×
//! `[pose (4) | b_s | b_a]`, float32 — or, quantised, `params_u16.npy` / `params_u8.npy` with
//! each column's range in `meta.json` (`value = min + q·(max − min)/(2^bits − 1)`), plus
//! `audio.m4a` when the input had sound.

use std::path::{Path, PathBuf};
use std::sync::mpsc;

use image::{Rgb, RgbImage};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::codebook::Layout;
use crate::fit::{FitError, FitOptions, Fitter, TrackedFrame, Tracker};
use crate::model::{FaceModel, ModelError};
use crate::npy::{self, NpyError};
use crate::render::Compositor;
use crate::shape::Landmarks;
use crate::video::{self, Sink, Source, VideoError};
use crate::{Progress, atomic};

pub const FORMAT: &str = "facespace-clip";
pub const VERSION: u32 = 1;
const META: &str = "meta.json";
const AUDIO: &str = "audio.m4a";

#[derive(Debug, Error)]
pub enum CodecError {
    #[error(transparent)]
    Video(#[from] VideoError),
    #[error(transparent)]
    Fit(#[from] FitError),
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Npy(#[from] NpyError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error(
        "{path}: encoded with model {clip}, but the model given is {model}; decode with the model it was encoded with"
    )]
    HashMismatch {
        path: PathBuf,
        clip: String,
        model: String,
    },
    #[error("quantisation to {0} bits is not supported (8 or 16)")]
    Bits(u32),
    #[error("{0}: no frames")]
    NoFrames(PathBuf),
}

/// What `meta.json` says of a clip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipMeta {
    pub format: String,
    pub version: u32,
    /// [`FaceModel::hash`] of the model that encoded it; decoding checks it.
    pub model_hash: String,
    pub fps: f64,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub layout: Layout,
    pub quantisation: Option<Quantisation>,
    /// The audio file in the folder, if the input had sound.
    pub audio: Option<String>,
    pub source: String,
    /// Per frame: the pose and how the tracker fared.
    pub tracking: Vec<FrameTrack>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameTrack {
    /// Similarity `[s·cosθ, s·sinθ, tx, ty]` (also columns 0–3 of the parameters).
    pub pose: [f64; 4],
    /// Residual RMS of the fit (grey levels).
    pub fit_error: f64,
    pub reinitialised: bool,
}

/// Uniform scalar quantisation of each column over its range in the clip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quantisation {
    pub bits: u32,
    pub min: Vec<f32>,
    pub max: Vec<f32>,
}

/// An encoded clip: its description and its face-space points (frames × dims, row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct Clip {
    pub meta: ClipMeta,
    pub params: Vec<f32>,
}

/// Options of [`encode`].
#[derive(Clone, Debug)]
pub struct EncodeOptions {
    pub levels: usize,
    /// Residual RMS above which the tracker re-initialises a frame.
    pub reinit_error: f64,
    /// Landmarks of the first frame; `None` searches it on a grid.
    pub init: Option<Landmarks>,
    pub fit: FitOptions,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions {
            levels: 2,
            reinit_error: 25.0,
            init: None,
            fit: FitOptions::default(),
        }
    }
}

/// Frames projected together (in parallel) while the tracker goes on.
const BATCH: usize = 32;

/// Tracks every frame of `source` (DESIGN §4 `Tracker`): frames are decoded on a second
/// thread while the tracker, sequential because each frame starts from the last, runs.
/// `on_frame` receives every frame with its fit; returns the per-frame tracking record.
pub fn track(
    model: &FaceModel,
    source: Source,
    options: &EncodeOptions,
    mut progress: impl FnMut(Progress),
    mut on_frame: impl FnMut(RgbImage, &TrackedFrame) -> Result<(), CodecError>,
) -> Result<Vec<FrameTrack>, CodecError> {
    let path = source.path().to_path_buf();
    let total = source.info().frames.unwrap_or(0);
    let fitter = Fitter::new(model, options.fit, options.levels)?;
    std::thread::scope(|scope| {
        let (tx, rx) = mpsc::sync_channel::<Result<RgbImage, VideoError>>(16);
        scope.spawn(move || {
            for frame in source {
                if tx.send(frame).is_err() {
                    break;
                }
            }
        });
        let mut frames = rx.into_iter();
        let first = frames
            .next()
            .ok_or_else(|| CodecError::NoFrames(path.clone()))??;
        let start = match &options.init {
            Some(l) => {
                l.validate(Some(model.shape.n_landmarks()), "initial landmarks")
                    .map_err(ModelError::from)?;
                l.clone()
            }
            None => fitter.search_start(&first)?,
        };
        let mut tracker = Tracker::new(fitter, start, options.reinit_error)?;
        let mut tracking = Vec::with_capacity(total);
        for frame in std::iter::once(Ok(first)).chain(frames) {
            let frame = frame?;
            let t = tracker.track(&frame)?;
            let pose = model
                .shape
                .project(&t.landmarks)
                .map_err(ModelError::from)?
                .0;
            tracking.push(FrameTrack {
                pose: pose.to_array(),
                fit_error: t.error,
                reinitialised: t.reinitialised,
            });
            on_frame(frame, &t)?;
            progress(Progress {
                stage: "tracking",
                done: tracking.len(),
                total: total.max(tracking.len()),
            });
        }
        Ok(tracking)
    })
}

/// Tracks every frame of `source` and projects it to face-space (projections run in
/// parallel batches while the tracker goes on).
pub fn encode(
    model: &FaceModel,
    source: Source,
    options: &EncodeOptions,
    progress: impl FnMut(Progress),
) -> Result<Clip, CodecError> {
    let info = source.info();
    let name = source.path().display().to_string();
    let mut params: Vec<f32> = Vec::with_capacity(info.frames.unwrap_or(0) * model.n_params());
    let mut batch: Vec<(RgbImage, Landmarks)> = Vec::with_capacity(BATCH);
    let mut project = |batch: &mut Vec<(RgbImage, Landmarks)>| -> Result<(), CodecError> {
        let rows: Vec<Vec<f32>> = batch
            .par_iter()
            .map(|(image, landmarks)| Ok(model.project(image, landmarks)?.to_vector()))
            .collect::<Result<_, ModelError>>()?;
        params.extend(rows.into_iter().flatten());
        batch.clear();
        Ok(())
    };
    let tracking = track(model, source, options, progress, |frame, t| {
        batch.push((frame, t.landmarks.clone()));
        if batch.len() == BATCH {
            project(&mut batch)?;
        }
        Ok(())
    })?;
    project(&mut batch)?;
    Ok(Clip {
        meta: ClipMeta {
            format: FORMAT.into(),
            version: VERSION,
            model_hash: model.hash(),
            fps: info.fps,
            width: info.width,
            height: info.height,
            frames: tracking.len(),
            layout: Layout::of(model),
            quantisation: None,
            audio: None,
            source: name,
            tracking,
        },
        params,
    })
}

impl Clip {
    pub fn dims(&self) -> usize {
        self.meta.layout.dims()
    }

    /// Face-space row of frame `i`.
    pub fn frame(&self, i: usize) -> &[f32] {
        &self.params[i * self.dims()..(i + 1) * self.dims()]
    }

    /// The clip as it decodes after quantising every column to `bits` (8 or 16) over its
    /// range; [`Clip::save`] then stores the integers.
    pub fn quantised(&self, bits: u32) -> Result<Clip, CodecError> {
        if bits != 8 && bits != 16 {
            return Err(CodecError::Bits(bits));
        }
        let dims = self.dims();
        let (mut min, mut max) = (vec![f32::INFINITY; dims], vec![f32::NEG_INFINITY; dims]);
        for row in self.params.chunks_exact(dims) {
            for (k, &v) in row.iter().enumerate() {
                min[k] = min[k].min(v);
                max[k] = max[k].max(v);
            }
        }
        let q = Quantisation { bits, min, max };
        let codes = q.encode(&self.params);
        let mut meta = self.meta.clone();
        meta.quantisation = Some(q.clone());
        Ok(Clip {
            meta,
            params: q.decode(&codes),
        })
    }

    /// Bytes of the parameter stream as stored (values, plus the range table if quantised).
    pub fn stream_bytes(&self) -> usize {
        match &self.meta.quantisation {
            Some(q) => self.params.len() * (q.bits as usize / 8) + 8 * self.dims(),
            None => self.params.len() * 4,
        }
    }

    /// Saves the clip folder atomically; `audio_from` (the input video) gives `audio.m4a`
    /// when it has sound. A non-empty folder without `meta.json` is never replaced.
    pub fn save(&self, dir: &Path, audio_from: Option<&Path>) -> Result<(), CodecError> {
        let io = |source| CodecError::Io {
            path: dir.into(),
            source,
        };
        atomic::replace_dir(
            dir,
            META,
            |staged| {
                let mut meta = self.meta.clone();
                match &meta.quantisation {
                    Some(q) => {
                        let codes = q.encode(&self.params);
                        let shape = [meta.frames, self.dims()];
                        let name = format!("params_u{}.npy", q.bits);
                        if q.bits == 8 {
                            let bytes: Vec<u8> = codes.iter().map(|&c| c as u8).collect();
                            npy::write(&staged.join(name), &shape, &bytes)?;
                        } else {
                            npy::write(&staged.join(name), &shape, &codes)?;
                        }
                    }
                    None => npy::write(
                        &staged.join("params.npy"),
                        &[meta.frames, self.dims()],
                        &self.params,
                    )?,
                }
                if let Some(input) = audio_from
                    && video::extract_audio(input, &staged.join(AUDIO))?
                {
                    meta.audio = Some(AUDIO.into());
                }
                let json = serde_json::to_vec_pretty(&meta).expect("meta serialises");
                atomic::write_file(&staged.join(META), &json).map_err(io)?;
                Ok(())
            },
            io,
        )
    }

    /// Loads a clip folder and checks it against `model` (hash, parameter count) and itself
    /// (format, frame count, finite values).
    pub fn load(dir: &Path, model: &FaceModel) -> Result<Clip, CodecError> {
        let meta_path = dir.join(META);
        let invalid = |message: String| CodecError::Invalid {
            path: meta_path.clone(),
            message,
        };
        let text = std::fs::read(&meta_path).map_err(|source| CodecError::Io {
            path: meta_path.clone(),
            source,
        })?;
        let meta: ClipMeta = serde_json::from_slice(&text)
            .map_err(|e| invalid(format!("not a clip description ({e})")))?;
        if meta.format != FORMAT || meta.version != VERSION {
            return Err(invalid(format!(
                "format {} version {}; this build reads {FORMAT} version {VERSION}",
                meta.format, meta.version
            )));
        }
        if meta.model_hash != model.hash() {
            return Err(CodecError::HashMismatch {
                path: dir.into(),
                clip: meta.model_hash,
                model: model.hash(),
            });
        }
        let dims = meta.layout.dims();
        if meta.layout != Layout::of(model) {
            return Err(invalid(format!(
                "{dims} parameters per frame, the model has {}",
                model.n_params()
            )));
        }
        if meta.tracking.len() != meta.frames || !(meta.fps.is_finite() && meta.fps > 0.0) {
            return Err(invalid("frame count or frame rate is inconsistent".into()));
        }
        let (array_path, shape, params) = match &meta.quantisation {
            None => {
                let p = dir.join("params.npy");
                let a = npy::read::<f32>(&p)?;
                (p, a.shape, a.data)
            }
            Some(q) => {
                if q.min.len() != dims || q.max.len() != dims || !(q.bits == 8 || q.bits == 16) {
                    return Err(invalid(
                        "quantisation table does not match the layout".into(),
                    ));
                }
                let p = dir.join(format!("params_u{}.npy", q.bits));
                let (shape, codes) = if q.bits == 8 {
                    let a = npy::read::<u8>(&p)?;
                    (a.shape, a.data.into_iter().map(u16::from).collect())
                } else {
                    let a = npy::read::<u16>(&p)?;
                    (a.shape, a.data)
                };
                if let Some(&c) = codes.iter().find(|&&c| u32::from(c) >= 1 << q.bits) {
                    return Err(invalid(format!("code {c} exceeds {} bits", q.bits)));
                }
                (p, shape, q.decode(&codes))
            }
        };
        if shape != [meta.frames, dims] {
            return Err(CodecError::Invalid {
                path: array_path,
                message: format!("shape {shape:?}, expected [{}, {dims}]", meta.frames),
            });
        }
        if let Some(i) = params.iter().position(|v| !v.is_finite()) {
            return Err(CodecError::Invalid {
                path: array_path,
                message: format!("value {i} is not finite"),
            });
        }
        Ok(Clip { meta, params })
    }

    /// The clip folder's audio file, if any.
    pub fn audio_path(&self, dir: &Path) -> Option<PathBuf> {
        self.meta.audio.as_ref().map(|a| dir.join(a))
    }
}

impl Quantisation {
    fn step(&self, k: usize) -> f32 {
        let levels = ((1u32 << self.bits) - 1) as f32;
        (self.max[k] - self.min[k]) / levels
    }

    fn encode(&self, params: &[f32]) -> Vec<u16> {
        let dims = self.min.len();
        params
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let k = i % dims;
                let step = self.step(k);
                if step > 0.0 {
                    ((v - self.min[k]) / step).round() as u16
                } else {
                    0
                }
            })
            .collect()
    }

    fn decode(&self, codes: &[u16]) -> Vec<f32> {
        let dims = self.min.len();
        codes
            .iter()
            .enumerate()
            .map(|(i, &c)| {
                let k = i % dims;
                self.min[k] + f32::from(c) * self.step(k)
            })
            .collect()
    }
}

/// What decoded faces are drawn over.
pub enum Background {
    /// A flat grey canvas of the clip's size.
    Plain,
    /// The frames of a video (normally the original), face blended with a feathered edge.
    Frames(Box<Source>, Compositor),
}

/// Renders every frame of `clip` into `sink`: a second thread renders batches of frames in
/// parallel while this one hands the previous batch to the sink (whose video encoder is
/// sequential).
pub fn decode(
    model: &FaceModel,
    clip: &Clip,
    background: Background,
    sink: &mut Sink,
    mut progress: impl FnMut(Progress),
) -> Result<(), CodecError> {
    let n = clip.meta.frames;
    std::thread::scope(|scope| {
        let (tx, rx) = mpsc::sync_channel::<Result<Vec<RgbImage>, CodecError>>(1);
        scope.spawn(move || {
            let mut background = background;
            let mut done = 0;
            while done < n {
                let batch = render_batch(model, clip, &mut background, done);
                let failed = batch.is_err();
                done += batch.as_ref().map_or(0, Vec::len);
                if tx.send(batch).is_err() || failed {
                    break;
                }
            }
        });
        let mut done = 0;
        for batch in rx {
            for f in &batch? {
                sink.write(f)?;
            }
            done += BATCH.min(n - done);
            progress(Progress {
                stage: "decoding",
                done,
                total: n,
            });
        }
        Ok(())
    })
}

/// Frames `start..start + BATCH` of the clip, rendered in parallel over their backgrounds.
fn render_batch(
    model: &FaceModel,
    clip: &Clip,
    background: &mut Background,
    start: usize,
) -> Result<Vec<RgbImage>, CodecError> {
    let (w, h) = (clip.meta.width, clip.meta.height);
    let count = BATCH.min(clip.meta.frames - start);
    let canvases: Vec<RgbImage> = match background {
        Background::Plain => vec![RgbImage::from_pixel(w, h, Rgb([96, 96, 96])); count],
        Background::Frames(source, _) => (0..count)
            .map(|_| {
                source
                    .next_frame()?
                    .ok_or_else(|| CodecError::NoFrames(source.path().into()))
            })
            .collect::<Result<_, _>>()?,
    };
    if let Some(c) = canvases.first()
        && c.dimensions() != (w, h)
    {
        return Err(CodecError::Invalid {
            path: match background {
                Background::Frames(s, _) => s.path().into(),
                Background::Plain => PathBuf::new(),
            },
            message: format!("background is {:?}, the clip {w}×{h}", c.dimensions()),
        });
    }
    let compositor = match background {
        Background::Frames(_, c) => Some(&*c),
        Background::Plain => None,
    };
    Ok(canvases
        .into_par_iter()
        .enumerate()
        .map(|(k, mut canvas)| {
            let row = clip.frame(start + k);
            match compositor {
                Some(c) => c.draw(model, row, &mut canvas)?,
                None => {
                    model.render_into(&model.params_from_vector(row)?, &mut canvas)?;
                }
            }
            Ok(canvas)
        })
        .collect::<Result<_, ModelError>>()?)
}
