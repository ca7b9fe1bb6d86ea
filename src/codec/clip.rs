//! The clip folder (DESIGN §12): `meta.json` and `params.npy` — frames × `[pose | b_s | b_a]`,
//! float32 — or, quantised, `params_u16.npy` / `params_u8.npy` with each column's range in
//! `meta.json` (`value = min + q·(max − min)/(2^bits − 1)`), `tracking.npy` (frames × 2
//! uint16: the fit's residual in hundredths of a grey level, saturating; flags, bit 0
//! re-initialised, bit 1 lost — the pose is the parameters' first four columns), plus
//! `audio.m4a` when the input had sound. Version 1 kept the tracking record in `meta.json`
//! (read still).

use std::path::{Path, PathBuf};

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use super::CodecError;
use crate::facespace::{Frames, Layout, POSE_DIMS};
use crate::manifest;
use crate::model::FaceModel;
use crate::npy;
use crate::{atomic, video};

/// The clip folder format.
pub const FORMAT: &str = "facespace-clip";
/// The clip folder version this build writes (and the newest it reads; it reads 1 too).
pub const VERSION: u32 = 2;
const META: &str = "meta.json";
const TRACKING: &str = "tracking.npy";
const AUDIO: &str = "audio.m4a";
/// Frames a clip may declare (a cap for damaged manifests: ten hours at 100 fps).
const MAX_FRAMES: usize = 3_600_000;
/// Most pixels a clip's canvas may have (4096 × 4096): decoding holds a few frames of it.
pub const MAX_CANVAS_PIXELS: u64 = 1 << 24;

/// `meta.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ClipMeta {
    format: String,
    version: u32,
    model_hash: String,
    fps: f64,
    width: u32,
    height: u32,
    frames: usize,
    layout: Layout,
    quantisation: Option<Quantisation>,
    audio: Option<String>,
    source: String,
    /// Version 1 only: the tracking record (version 2 keeps it in `tracking.npy`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    tracking: Vec<FrameTrack>,
}

/// How the tracker fared on one frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameTrack {
    /// Similarity `[s·cosθ, s·sinθ, tx, ty]` (also columns 0–3 of the parameters).
    pub pose: [f64; POSE_DIMS],
    /// Residual RMS of the fit (grey levels).
    pub fit_error: f64,
    /// Whether the frame was re-initialised after a lost fit.
    pub reinitialised: bool,
    /// Whether the kept fit is still above the re-initialisation threshold (the face lost).
    #[serde(default)]
    pub lost: bool,
}

/// Uniform scalar quantisation of each column over its range in the clip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quantisation {
    /// 8 or 16.
    pub bits: u32,
    /// Per column, the smallest value.
    pub min: Vec<f32>,
    /// Per column, the largest value.
    pub max: Vec<f32>,
}

/// An encoded clip: face-space frames and what else decoding needs.
#[derive(Clone, Debug, PartialEq)]
pub struct Clip {
    /// The face-space points, one per video frame.
    pub frames: Frames,
    /// [`FaceModel::hash`] of the model that encoded it; decoding checks it.
    pub model_hash: String,
    /// Video width.
    pub width: u32,
    /// Video height.
    pub height: u32,
    /// Quantisation, if the parameters are stored as integers.
    pub quantisation: Option<Quantisation>,
    /// The audio file in the folder, if the input had sound.
    pub audio: Option<String>,
    /// The input encoded.
    pub source: String,
    /// Per frame, how the tracker fared.
    pub tracking: Vec<FrameTrack>,
}

impl Clip {
    /// The clip as it decodes after quantising every column to `bits` (8 or 16) over its
    /// range; [`Clip::save`] then stores the integers.
    pub fn quantised(&self, bits: u32) -> Result<Clip, CodecError> {
        if bits != 8 && bits != 16 {
            return Err(CodecError::Bits(bits));
        }
        let dims = self.frames.layout().dims();
        let (mut min, mut max) = (vec![f32::INFINITY; dims], vec![f32::NEG_INFINITY; dims]);
        for row in self.frames.values().rows() {
            for (k, &v) in row.iter().enumerate() {
                min[k] = min[k].min(v);
                max[k] = max[k].max(v);
            }
        }
        let q = Quantisation { bits, min, max };
        let codes = q.encode(self.frames.as_slice());
        let frames = Frames::from_rows(self.frames.layout(), self.frames.fps(), q.decode(&codes))?;
        Ok(Clip {
            frames,
            quantisation: Some(q),
            ..self.clone()
        })
    }

    /// Bytes of the parameter stream as stored (values, plus the range table if quantised).
    pub fn stream_bytes(&self) -> usize {
        let values = self.frames.len() * self.frames.layout().dims();
        match &self.quantisation {
            Some(q) => values * (q.bits as usize / 8) + 8 * self.frames.layout().dims(),
            None => values * 4,
        }
    }

    /// Saves the clip folder atomically; `audio_from` (the input video) gives `audio.m4a`
    /// when it has sound. A non-empty folder is replaced only if it is a clip facespace
    /// wrote, with nothing added since.
    pub fn save(&self, dir: &Path, audio_from: Option<&Path>) -> Result<(), CodecError> {
        let io = |source| CodecError::Io {
            path: dir.into(),
            source,
        };
        atomic::replace_dir(
            dir,
            "clip",
            |staged| {
                let mut meta = ClipMeta {
                    format: FORMAT.into(),
                    version: VERSION,
                    model_hash: self.model_hash.clone(),
                    fps: self.frames.fps(),
                    width: self.width,
                    height: self.height,
                    frames: self.frames.len(),
                    layout: self.frames.layout(),
                    quantisation: self.quantisation.clone(),
                    audio: None,
                    source: self.source.clone(),
                    tracking: Vec::new(),
                };
                if self.tracking.len() != self.frames.len() {
                    return Err(CodecError::Invalid {
                        path: dir.into(),
                        message: format!(
                            "{} frames with {} tracking records",
                            self.frames.len(),
                            self.tracking.len()
                        ),
                    });
                }
                let record: Vec<u16> = self
                    .tracking
                    .iter()
                    .flat_map(|t| {
                        let error = (t.fit_error * 100.0).round().clamp(0.0, 65535.0) as u16;
                        [error, u16::from(t.reinitialised) | u16::from(t.lost) << 1]
                    })
                    .collect();
                let record = Array2::from_shape_vec((self.tracking.len(), 2), record)
                    .expect("tracking shape");
                npy::write(&staged.join(TRACKING), record.view())?;
                let shape = (meta.frames, meta.layout.dims());
                match &meta.quantisation {
                    Some(q) => {
                        let codes = q.encode(self.frames.as_slice());
                        let name = format!("params_u{}.npy", q.bits);
                        if q.bits == 8 {
                            let bytes: Vec<u8> = codes.iter().map(|&c| c as u8).collect();
                            let a = Array2::from_shape_vec(shape, bytes).expect("clip shape");
                            npy::write(&staged.join(name), a.view())?;
                        } else {
                            let a = Array2::from_shape_vec(shape, codes).expect("clip shape");
                            npy::write(&staged.join(name), a.view())?;
                        }
                    }
                    None => npy::write(&staged.join("params.npy"), self.frames.values())?,
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

    /// Loads a clip folder and checks it against `model` (hash, layout) and itself (format,
    /// frame count, frame rate, finite values, codes within their bits).
    pub fn load(dir: &Path, model: &FaceModel) -> Result<Clip, CodecError> {
        Self::load_for(dir, Some(&model.hash()), model.layout())
    }

    /// [`Clip::load`] against a model known by its hash (`None`: not checked, only the
    /// layout) and layout — for readers that hold a codebook rather than the model.
    pub fn load_for(dir: &Path, hash: Option<&str>, layout: Layout) -> Result<Clip, CodecError> {
        crate::atomic::read_consistent(dir, || Self::load_for_once(dir, hash, layout))
    }

    fn load_for_once(dir: &Path, hash: Option<&str>, layout: Layout) -> Result<Clip, CodecError> {
        let meta_path = dir.join(META);
        let (mut meta, version): (ClipMeta, u32) =
            manifest::read_versions(&meta_path, FORMAT, 1..=VERSION)?;
        let invalid = |message: String| CodecError::Invalid {
            path: meta_path.clone(),
            message,
        };
        if let Some(hash) = hash
            && meta.model_hash != hash
        {
            return Err(CodecError::HashMismatch {
                path: dir.into(),
                clip: meta.model_hash,
                model: hash.into(),
            });
        }
        layout.expect(meta.layout)?;
        crate::facespace::check_fps(meta.fps).map_err(|e| invalid(e.to_string()))?;
        for (name, side) in [("width", meta.width), ("height", meta.height)] {
            crate::options::count_in(name, side as usize, 1, video::y4m::MAX_SIDE)
                .map_err(|e| invalid(e.to_string()))?;
        }
        let pixels = u64::from(meta.width) * u64::from(meta.height);
        if pixels > MAX_CANVAS_PIXELS {
            return Err(invalid(format!(
                "a {}×{} canvas is {pixels} pixels (at most {MAX_CANVAS_PIXELS}: one RGB frame stays under {} MB)",
                meta.width,
                meta.height,
                (MAX_CANVAS_PIXELS * 3) >> 20
            )));
        }
        let dims = meta.layout.dims();
        if meta.frames > MAX_FRAMES {
            return Err(invalid(format!(
                "{} frames (at most {MAX_FRAMES})",
                meta.frames
            )));
        }
        let tracking_flags: Option<Array2<u16>> = if version >= 2 {
            if !meta.tracking.is_empty() {
                return Err(invalid(
                    "a version-2 clip keeps its tracking in tracking.npy".into(),
                ));
            }
            Some(manifest::read_array(
                dir,
                TRACKING,
                &[Some(meta.frames), Some(2)],
            )?)
        } else {
            None
        };
        if version < 2 && meta.tracking.len() != meta.frames {
            return Err(invalid(format!(
                "{} frames with {} tracking records",
                meta.frames,
                meta.tracking.len()
            )));
        }
        let shape = [Some(meta.frames), Some(dims)];
        let (array, values): (PathBuf, Vec<f32>) = match &meta.quantisation {
            None => {
                let a: Array2<f32> = manifest::read_array(dir, "params.npy", &shape)?;
                (dir.join("params.npy"), a.into_raw_vec_and_offset().0)
            }
            Some(q) => {
                if q.min.len() != dims || q.max.len() != dims || !(q.bits == 8 || q.bits == 16) {
                    return Err(invalid(
                        "quantisation table does not match the layout".into(),
                    ));
                }
                if let Some(k) =
                    (0..dims).find(|&k| q.min[k].partial_cmp(&q.max[k]).is_none_or(|o| o.is_gt()))
                {
                    return Err(invalid(format!(
                        "quantisation range of column {k} is empty or not finite ({} to {})",
                        q.min[k], q.max[k]
                    )));
                }
                let name = format!("params_u{}.npy", q.bits);
                let codes: Vec<u16> = if q.bits == 8 {
                    let a: Array2<u8> = manifest::read_array(dir, &name, &shape)?;
                    a.iter().map(|&c| u16::from(c)).collect()
                } else {
                    let a: Array2<u16> = manifest::read_array(dir, &name, &shape)?;
                    a.into_raw_vec_and_offset().0
                };
                if let Some(&c) = codes.iter().find(|&&c| u32::from(c) >= 1 << q.bits) {
                    return Err(invalid(format!("code {c} exceeds {} bits", q.bits)));
                }
                (dir.join(name), q.decode(&codes))
            }
        };
        let frames =
            Frames::from_rows(meta.layout, meta.fps, values).map_err(|e| CodecError::Invalid {
                path: array,
                message: e.to_string(),
            })?;
        if let Some(audio) = &meta.audio {
            // A plain name of the folder, and a regular file: a FIFO there would block the
            // decoder (or ffmpeg) forever.
            let path = manifest::member(dir, audio)?;
            crate::safe_read::open_regular(&path).map_err(|e| CodecError::Invalid {
                path: path.clone(),
                message: format!("the clip's audio: {e}"),
            })?;
        }
        if let Some(record) = tracking_flags {
            meta.tracking = record
                .rows()
                .into_iter()
                .enumerate()
                .map(|(i, r)| FrameTrack {
                    pose: frames.params(i).pose.to_array(),
                    fit_error: f64::from(r[0]) / 100.0,
                    reinitialised: r[1] & 1 != 0,
                    lost: r[1] & 2 != 0,
                })
                .collect();
        }
        Ok(Clip {
            frames,
            model_hash: meta.model_hash,
            width: meta.width,
            height: meta.height,
            quantisation: meta.quantisation,
            audio: meta.audio,
            source: meta.source,
            tracking: meta.tracking,
        })
    }

    /// Bytes the clip folder takes on disk (every regular file in it, manifests included).
    pub fn disk_bytes(dir: &Path) -> Result<u64, CodecError> {
        let io = |source| CodecError::Io {
            path: dir.into(),
            source,
        };
        let mut total = 0;
        for e in std::fs::read_dir(dir).map_err(io)? {
            let meta = e.map_err(io)?.metadata().map_err(io)?;
            if meta.is_file() {
                total += meta.len();
            }
        }
        Ok(total)
    }

    /// The clip folder's audio file, if any.
    pub fn audio_path(&self, dir: &Path) -> Option<PathBuf> {
        self.audio.as_ref().map(|a| dir.join(a))
    }
}

impl Quantisation {
    fn step(&self, k: usize) -> f32 {
        let levels = ((1u32 << self.bits) - 1) as f32;
        (self.max[k] - self.min[k]) / levels
    }

    /// Each value as its code (column by column over `params`, frames × dims).
    pub fn encode(&self, params: &[f32]) -> Vec<u16> {
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
