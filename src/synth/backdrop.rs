//! What a synthesised face is drawn over, and the pose it takes from there (DESIGN §7: the
//! pose is never blended). A still frame lends its pose (the face found in it by the AAM
//! search); a video is tracked and lends its pose frame by frame, played forwards then
//! backwards when the utterance is longer — and its landmarks, for region synthesis.

use std::path::Path;

use image::RgbImage;
use thiserror::Error;

use super::Pose;
use crate::Progress;
use crate::codec::{self, CodecError, EncodeOptions};
use crate::fit::{FitError, FitOptions, Fitter};
use crate::model::FaceModel;
use crate::render::Background;
use crate::shape::Landmarks;
use crate::video::{Source, VideoError};

/// What can go wrong preparing a backdrop.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum BackdropError {
    /// The face could not be found in a still frame.
    #[error("finding the face in the background frame: {0}")]
    Fit(#[from] FitError),
    /// The background video could not be tracked.
    #[error("tracking the background video: {0}")]
    Track(#[from] CodecError),
    /// The background video could not be read.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// A background video larger than is held in memory for a loop.
    #[error(
        "{path}: looping its {frames} frames of {width}×{height} needs {mib} MiB in memory (at most {MAX_LOOP_MIB}); use a shorter utterance or a longer background"
    )]
    TooLarge {
        /// The video.
        path: std::path::PathBuf,
        /// Its frames.
        frames: usize,
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
        /// Memory it would take.
        mib: usize,
    },
}

/// Most memory a looped background may take.
pub const MAX_LOOP_MIB: usize = 2048;

/// Where the pose comes from when the background is a video.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PoseMode {
    /// One pose: the first background frame's (drawn over that frame, still).
    Hold,
    /// Each background frame's pose in turn.
    Replay,
}

/// A background with the pose (and landmarks) of the face in it.
pub struct Backdrop {
    /// The pose of every output frame.
    pub pose: Pose,
    /// The tracked landmarks of the background frames, in the order they are shown.
    pub landmarks: Vec<Landmarks>,
    frames: Frames,
}

/// Where a backdrop's frames come from.
enum Frames {
    Still(RgbImage),
    Video(std::path::PathBuf),
    Loop(Vec<RgbImage>),
}

impl Backdrop {
    /// A fresh [`Background`] of these frames, from the first (a video is opened again), so
    /// one backdrop can be rendered under several utterances.
    pub fn background(&self) -> Result<Background, BackdropError> {
        Ok(match &self.frames {
            Frames::Still(image) => Background::Still(image.clone()),
            Frames::Video(path) => Background::Video(Box::new(Source::open(path)?)),
            Frames::Loop(frames) => Background::Loop {
                frames: frames.clone(),
                next: 0,
            },
        })
    }

    /// For a region model (one that knows its articulators), re-fits every variant of
    /// `utterance` so the region's seam lies on this background's face ([`anchor`]); returns
    /// whether it did.
    pub fn anchor_region(
        &self,
        model: &FaceModel,
        utterance: &mut super::Utterance,
    ) -> Result<bool, crate::model::ModelError> {
        let Some(articulators) = model.region.as_ref().and_then(|r| r.articulators()) else {
            return Ok(false);
        };
        anchor(
            model,
            &mut utterance.synthesis.frames,
            &self.landmarks,
            &articulators,
        )?;
        if let Some(smoothed) = &mut utterance.smoothed {
            anchor(model, smoothed, &self.landmarks, &articulators)?;
        }
        utterance
            .pose
            .push_str("; region anchored to the background's face");
        Ok(true)
    }

    /// One image: the face found in it (grid search, then the AAM fit) gives the pose.
    pub fn still(tracker: &FaceModel, image: RgbImage) -> Result<Backdrop, BackdropError> {
        let fitter = Fitter::new(tracker, FitOptions::default(), 2)?;
        let start = fitter.search_start(&image)?;
        let fit = fitter.fit(&image, &start)?;
        let (pose, _) = tracker
            .shape
            .project(&fit.landmarks)
            .map_err(|e| FitError::Model(e.into()))?;
        Ok(Backdrop {
            frames: Frames::Still(image),
            pose: Pose::Hold(pose),
            landmarks: vec![fit.landmarks],
        })
    }

    /// A video, tracked with `tracker`: replayed frame by frame (looping forwards and
    /// backwards past its end) or held at its first frame. `frames` is the number of output
    /// frames to cover.
    pub fn video(
        tracker: &FaceModel,
        path: &Path,
        mode: PoseMode,
        frames: usize,
        options: &EncodeOptions,
        progress: impl FnMut(Progress),
    ) -> Result<Backdrop, BackdropError> {
        let source = Source::open(path)?;
        let (landmarks, tracking) = codec::track_landmarks(tracker, source, options, progress)?;
        let poses: Vec<_> = tracking
            .iter()
            .map(|t| crate::shape::Similarity::from_array(t.pose))
            .collect();
        let first = || -> Result<RgbImage, BackdropError> {
            Source::open(path)?
                .next_frame()?
                .ok_or_else(|| VideoError::NoFrames(path.into()).into())
        };
        Ok(match mode {
            PoseMode::Hold => Backdrop {
                frames: Frames::Still(first()?),
                pose: Pose::Hold(poses[0]),
                landmarks: vec![landmarks[0].clone()],
            },
            PoseMode::Replay if poses.len() >= frames => Backdrop {
                frames: Frames::Video(path.into()),
                pose: Pose::Replay(poses[..frames].to_vec()),
                landmarks: landmarks[..frames].to_vec(),
            },
            PoseMode::Replay => {
                let source = Source::open(path)?;
                let (w, h) = (source.info().width, source.info().height);
                let mib = (poses.len() * (w * h * 3) as usize) >> 20;
                if mib > MAX_LOOP_MIB {
                    return Err(BackdropError::TooLarge {
                        path: path.into(),
                        frames: poses.len(),
                        width: w,
                        height: h,
                        mib,
                    });
                }
                let images = source.collect::<Result<Vec<_>, _>>()?;
                let shown = (0..frames)
                    .map(|t| landmarks[super::ping_pong(t, landmarks.len())].clone())
                    .collect();
                Backdrop {
                    frames: Frames::Loop(images),
                    pose: Pose::Replay(poses),
                    landmarks: shown,
                }
            }
        })
    }
}

/// Region synthesis over a background face (DESIGN §7, \[blend\] §3): every frame's shape is
/// re-fitted, at its (background) pose, to landmarks that take the `articulators` — lips and
/// chin — from the synthesis and every other landmark from the background frame
/// (`background[t]`, the last one repeated), the synthesised articulators first moved by the
/// similarity that best lays the synthesis's other landmarks onto the background's. So the
/// seam of the region sits where the background's face is, and head motion the synthesis
/// carried in its shape does not slide the face against the background.
pub fn anchor(
    model: &FaceModel,
    frames: &mut crate::facespace::Frames,
    background: &[Landmarks],
    articulators: &[u32],
) -> Result<(), crate::model::ModelError> {
    let n = model.shape.n_landmarks();
    let moving: Vec<bool> = (0..n as u32).map(|i| articulators.contains(&i)).collect();
    let fixed: Vec<usize> = (0..n).filter(|&i| !moving[i]).collect();
    let layout = frames.layout();
    for t in 0..frames.len() {
        let Some(bg) = background.get(t).or(background.last()) else {
            return Ok(());
        };
        bg.validate(Some(n), "background landmarks")?;
        let params = frames.params(t);
        let pose = params.pose;
        let synthesised = model.landmarks(params)?.points;
        let from: Vec<_> = fixed.iter().map(|&i| synthesised[i]).collect();
        let to: Vec<_> = fixed.iter().map(|&i| bg.points[i]).collect();
        let onto = crate::shape::align(&from, &to).unwrap_or(crate::shape::Similarity::IDENTITY);
        let composite = Landmarks {
            points: (0..n)
                .map(|i| {
                    if moving[i] {
                        onto.apply(synthesised[i])
                    } else {
                        bg.points[i]
                    }
                })
                .collect(),
        };
        let b = model.shape.project_at(&pose, &composite)?;
        let mut row = frames.values_mut();
        let mut row = row.row_mut(t);
        for (k, v) in layout.shape_range().zip(b) {
            row[k] = v;
        }
    }
    Ok(())
}
