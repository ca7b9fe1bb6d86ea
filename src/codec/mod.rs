//! Video through face-space (DESIGN §1 last line, §12): *encode* tracks every frame with the
//! AAM search and projects it to a face-space point; *decode* reconstructs and renders every
//! point. The clip folder is [`clip`]; quality and size are measured by [`score`].

pub mod clip;
pub mod score;

use std::path::PathBuf;
use std::sync::mpsc;

use image::RgbImage;
use rayon::prelude::*;
use thiserror::Error;

pub use clip::{Clip, FrameTrack, Quantisation};
pub use score::{QualityReport, max_error_sd};

use crate::Progress;
use crate::facespace::{FacespaceError, Frames};
use crate::fit::{self, FitError, FitOptions, Fitter, TrackedFrame, Tracker};
use crate::manifest::ManifestError;
use crate::model::{FaceModel, ModelError};
use crate::npy::NpyError;
use crate::options::{self, InvalidOption};
use crate::render::{self, Background, RenderError, Renderer};
use crate::shape::Landmarks;
use crate::video::{Sink, Source, VideoError};

/// What can go wrong encoding, decoding or scoring a clip.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CodecError {
    /// Reading or writing video failed.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The tracker failed.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// Projection or reconstruction failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// Initial landmarks that do not touch the first frame.
    #[error(
        "the initial landmarks (--init) span ({:.0}, {:.0})–({:.0}, {:.0}), wholly outside the first frame ({width}×{height}): landmarks of another video?",
        lo[0], lo[1], hi[0], hi[1]
    )]
    InitOutside {
        /// Top-left corner of their bounding box.
        lo: [f64; 2],
        /// Bottom-right corner.
        hi: [f64; 2],
        /// The frame's width.
        width: u32,
        /// The frame's height.
        height: u32,
    },
    /// An array could not be written.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// The clip folder is damaged or of another version.
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    /// The clip's layout is not the model's.
    #[error(transparent)]
    Facespace(#[from] FacespaceError),
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The clip's contents do not fit together.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The clip belongs to another model.
    #[error(
        "{path}: encoded with model {clip}, but the model given is {model}; decode with the model it was encoded with"
    )]
    HashMismatch {
        /// The clip folder.
        path: PathBuf,
        /// The clip's model hash.
        clip: String,
        /// The given model's hash.
        model: String,
    },
    /// Unsupported quantisation.
    #[error("quantisation to {0} bits is not supported (8 or 16)")]
    Bits(u32),
    /// A video without frames.
    #[error("{0}: no frames")]
    NoFrames(PathBuf),
    /// The model explains no face in the first frame: almost always a model of someone else.
    /// (The three "no face" errors name no remedy flags: a command that has them adds them,
    /// [`CodecError::is_lost_face`].)
    #[error(
        "{path}: no face this model explains in the first frame (residual {error:.1} grey levels, a face it was built for fits under {threshold}); this model was probably built for another face: build one from your own frames (docs/OWN_TALKER.md)"
    )]
    NoFace {
        /// The video.
        path: PathBuf,
        /// The first frame's residual RMS.
        error: f64,
        /// The threshold it exceeds.
        threshold: f64,
    },
    /// The search diverged on the first frame: no face at all there.
    #[error(
        "{path}: frame 0: the search diverged — there is no face in it at all (a grey, black or damaged frame?)"
    )]
    FirstFrameDiverged {
        /// The video.
        path: PathBuf,
    },
    /// Most frames were lost.
    #[error(
        "{path}: the face was lost on {lost} of {frames} frames (residual above {threshold} grey levels); this model was probably built for another face: build one from your own frames (docs/OWN_TALKER.md)"
    )]
    FaceLost {
        /// The video.
        path: PathBuf,
        /// Frames whose kept fit is above the threshold.
        lost: usize,
        /// Frames tracked.
        frames: usize,
        /// The residual threshold.
        threshold: f64,
    },
    /// An option out of range.
    #[error(transparent)]
    Option(#[from] InvalidOption),
}

impl CodecError {
    /// Whether tracking found no face it could keep: the first frame unexplained or empty, or
    /// the face lost on most frames — what giving the first frame's landmarks or allowing lost
    /// frames gets past.
    pub fn is_lost_face(&self) -> bool {
        matches!(
            self,
            CodecError::NoFace { .. }
                | CodecError::FirstFrameDiverged { .. }
                | CodecError::FaceLost { .. }
        )
    }
}

/// Options of [`track`] and [`encode`].
#[derive(Clone, Debug)]
pub struct EncodeOptions {
    /// Pyramid levels of the search (1–4).
    pub levels: usize,
    /// Residual RMS (grey levels) above which the tracker re-initialises a frame.
    pub reinit_error: f64,
    /// Landmarks of the first frame; `None` searches it on a grid.
    pub init: Option<Landmarks>,
    /// The search's own options.
    pub fit: FitOptions,
    /// Quantise the parameters to 8 or 16 bits per value (over each column's range).
    pub bits: Option<u32>,
    /// Keep going when the first frame has no face the model explains or most frames are
    /// lost (otherwise [`CodecError::NoFace`] / [`CodecError::FaceLost`]).
    pub allow_lost: bool,
    /// Judge the face lost already when most of the first this-many frames are (a background
    /// of someone else fails in a second, not after every frame's re-initialising search);
    /// `None` judges the whole video only.
    pub early_verdict: Option<usize>,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions {
            levels: 2,
            reinit_error: fit::DEFAULT_REINIT_ERROR,
            init: None,
            fit: FitOptions::default(),
            bits: None,
            allow_lost: false,
            early_verdict: None,
        }
    }
}

impl EncodeOptions {
    /// Checks every option against `model` before any frame is read.
    pub fn validate(&self, model: &FaceModel) -> Result<(), CodecError> {
        options::count_in("pyramid levels", self.levels, 1, 4)?;
        options::in_range("re-initialisation error", self.reinit_error, 0.0, 255.0)?;
        if let Some(bits) = self.bits
            && bits != 8
            && bits != 16
        {
            return Err(CodecError::Bits(bits));
        }
        if let Some(l) = &self.init {
            l.validate(Some(model.shape.n_landmarks()), "initial landmarks")
                .map_err(ModelError::from)?;
        }
        Ok(self.fit.validate()?)
    }
}

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
    // A region model tracks with its whole-face tracker (the landmarks are the same).
    let model = model.tracker();
    options.validate(model)?;
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
                let (lo, hi) = l.bounds();
                let (width, height) = first.dimensions();
                if hi[0] < 0.0
                    || hi[1] < 0.0
                    || lo[0] > f64::from(width)
                    || lo[1] > f64::from(height)
                {
                    return Err(CodecError::InitOutside {
                        lo,
                        hi,
                        width,
                        height,
                    });
                }
                l.clone()
            }
            None => fitter.search_start(&first)?,
        };
        let mut tracker = Tracker::new(fitter, start, options.reinit_error)?;
        let mut tracking = Vec::with_capacity(total);
        let mut lost_so_far = 0;
        for frame in std::iter::once(Ok(first)).chain(frames) {
            let frame = frame?;
            let t = tracker.track(&frame)?;
            let lost = t.diverged || t.error > options.reinit_error;
            if t.diverged && tracking.is_empty() && !options.allow_lost {
                return Err(CodecError::FirstFrameDiverged { path: path.clone() });
            }
            if lost && tracking.is_empty() && !options.allow_lost {
                return Err(CodecError::NoFace {
                    path: path.clone(),
                    error: t.error,
                    threshold: options.reinit_error,
                });
            }
            tracking.push(FrameTrack {
                pose: t.pose.to_array(),
                fit_error: t.error,
                reinitialised: t.reinitialised,
                lost,
            });
            // Once most of the known frame count is lost the verdict below is certain: say it
            // now rather than after the rest (a background of someone else fails fast).
            lost_so_far += usize::from(lost);
            let judged = match options.early_verdict {
                Some(n) if tracking.len() == n => Some(n),
                _ if total > 0 => Some(total),
                _ => None,
            };
            if let Some(frames) = judged
                && 2 * lost_so_far > frames
                && !options.allow_lost
            {
                return Err(CodecError::FaceLost {
                    path: path.clone(),
                    lost: lost_so_far,
                    frames: tracking.len(),
                    threshold: options.reinit_error,
                });
            }
            on_frame(frame, &t)?;
            progress(Progress {
                stage: "tracking",
                done: tracking.len(),
                total: total.max(tracking.len()),
            });
        }
        let lost = tracking.iter().filter(|t| t.lost).count();
        if 2 * lost > tracking.len() && !options.allow_lost {
            return Err(CodecError::FaceLost {
                path: path.clone(),
                lost,
                frames: tracking.len(),
                threshold: options.reinit_error,
            });
        }
        Ok(tracking)
    })
}

/// Tracks every frame of `source` and returns each frame's landmarks with the tracking record.
pub fn track_landmarks(
    model: &FaceModel,
    source: Source,
    options: &EncodeOptions,
    progress: impl FnMut(Progress),
) -> Result<(Vec<Landmarks>, Vec<FrameTrack>), CodecError> {
    let mut landmarks = Vec::new();
    let tracking = track(model, source, options, progress, |_, t| {
        landmarks.push(t.landmarks.clone());
        Ok(())
    })?;
    Ok((landmarks, tracking))
}

/// A tracking record in brief.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TrackingSummary {
    /// Frames tracked.
    pub frames: usize,
    /// Mean residual RMS (grey levels).
    pub mean_error: f64,
    /// Median residual RMS.
    pub median_error: f64,
    /// Largest residual RMS.
    pub max_error: f64,
    /// Frames re-initialised.
    pub reinitialised: usize,
    /// Frames whose kept fit is still above the threshold (lost).
    pub lost: usize,
}

impl TrackingSummary {
    /// The summary of a tracking record.
    pub fn of(tracking: &[FrameTrack]) -> Self {
        let n = tracking.len().max(1) as f64;
        TrackingSummary {
            frames: tracking.len(),
            mean_error: tracking.iter().map(|t| t.fit_error).sum::<f64>() / n,
            median_error: crate::plot::median(
                &tracking.iter().map(|t| t.fit_error).collect::<Vec<_>>(),
            ),
            max_error: tracking.iter().map(|t| t.fit_error).fold(0.0, f64::max),
            reinitialised: tracking.iter().filter(|t| t.reinitialised).count(),
            lost: tracking.iter().filter(|t| t.lost).count(),
        }
    }
}

/// An encoded clip and, when quantised, the largest quantisation error in standard
/// deviations of the shape/appearance parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoded {
    /// The clip (quantised if asked).
    pub clip: Clip,
    /// `max |quantised − exact| / σ` over shape and appearance values, when quantised.
    pub quantisation_error_sd: Option<f64>,
}

/// Tracks every frame of `source` and projects it to face-space (projections run in
/// parallel batches while the tracker goes on), then quantises as `options.bits` asks.
pub fn encode(
    model: &FaceModel,
    source: Source,
    options: &EncodeOptions,
    progress: impl FnMut(Progress),
) -> Result<Encoded, CodecError> {
    options.validate(model)?;
    let info = source.info();
    let name = source.path().display().to_string();
    let dims = model.layout().dims();
    let mut params: Vec<f32> = Vec::with_capacity(info.frames.unwrap_or(0) * dims);
    let mut batch: Vec<(RgbImage, Landmarks)> = Vec::with_capacity(render::BATCH);
    let mut project = |batch: &mut Vec<(RgbImage, Landmarks)>| -> Result<(), CodecError> {
        let start = params.len();
        params.resize(start + batch.len() * dims, 0.0);
        params[start..]
            .par_chunks_mut(dims)
            .zip(batch.par_iter())
            .try_for_each(|(row, (image, landmarks))| model.project_into(image, landmarks, row))?;
        batch.clear();
        Ok(())
    };
    let tracking = track(model, source, options, progress, |frame, t| {
        batch.push((frame, t.landmarks.clone()));
        if batch.len() == render::BATCH {
            project(&mut batch)?;
        }
        Ok(())
    })?;
    project(&mut batch)?;
    let exact = Clip {
        frames: Frames::from_rows(model.layout(), info.fps, params)?,
        model_hash: model.hash(),
        width: info.width,
        height: info.height,
        quantisation: None,
        audio: None,
        source: name,
        tracking,
    };
    Ok(match options.bits {
        Some(bits) => {
            let clip = exact.quantised(bits)?;
            let error = max_error_sd(model, &exact.frames, &clip.frames);
            Encoded {
                clip,
                quantisation_error_sd: Some(error),
            }
        }
        None => Encoded {
            clip: exact,
            quantisation_error_sd: None,
        },
    })
}

/// Renders every frame of `clip` into `sink` over `background` (batches rendered in parallel
/// while the previous batch is handed to the sink, whose video encoder is sequential).
pub fn decode(
    renderer: &dyn Renderer,
    clip: &Clip,
    background: Background,
    sink: &mut Sink,
    progress: impl FnMut(Progress),
) -> Result<(), CodecError> {
    let size = background.size();
    if size != (clip.width, clip.height) {
        return Err(RenderError::Size {
            what: "the background".into(),
            found: size,
            expected: (clip.width, clip.height),
        }
        .into());
    }
    render::stream(
        renderer,
        &clip.frames,
        background,
        |frame| Ok::<(), CodecError>(sink.write(&frame)?),
        progress,
    )
}
