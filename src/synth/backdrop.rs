//! What a synthesised face is drawn over, and the pose it takes from there (DESIGN §7: the
//! pose is never blended). A still frame lends its pose (the face found in it by the AAM
//! search); a video is tracked and lends its pose frame by frame — one shorter than the
//! utterance extended as a talker's footage is (stretches joined where they match, never
//! backwards) — and its landmarks, for region synthesis; a talker's footage lends its living
//! frame ([`Backdrop::footage`]).

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

/// A background video is judged lost when most of its first this-many frames are (0.4 s at
/// 25 fps): each lost frame costs a re-initialising search, so a model of someone else over a
/// long background would otherwise search for seconds before the verdict.
pub const EARLY_VERDICT_FRAMES: usize = 10;

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
    /// The synthesis failed.
    #[error(transparent)]
    Synth(#[from] super::SynthError),
    /// The synthesis could not be fitted to the background's face.
    #[error("fitting the synthesis to the background's face: {0}")]
    Anchor(#[from] crate::model::ModelError),
}

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
    /// The background's face-space trajectory (every frame tracked, projected into the
    /// tracker's space, in recorded order): the real trajectory when the background is the
    /// utterance's own take.
    pub tracked: crate::facespace::Frames,
    /// [`FaceModel::hash`] of the tracker: `tracked` is in its space.
    pub tracker_hash: String,
    /// For footage (a talker's, or a video shorter than the utterance): which frame is shown
    /// when, and where stretches join.
    pub plan: Option<crate::footage::Plan>,
    frames: Frames,
}

/// Where a backdrop's frames come from.
enum Frames {
    Still(RgbImage),
    Video(std::path::PathBuf),
    Footage(crate::footage::Shown),
}

impl Backdrop {
    /// A fresh [`Background`] of these frames, from the first (a video is opened again), so
    /// one backdrop can be rendered under several utterances.
    pub fn background(&self) -> Result<Background, BackdropError> {
        Ok(match &self.frames {
            Frames::Still(image) => Background::Still(image.clone()),
            Frames::Video(path) => Background::Video(Box::new(Source::open(path)?)),
            Frames::Footage(shown) => Background::Frames(Box::new(shown.fresh())),
        })
    }

    /// A talker's living frame: the footage frames `plan` shows, with the poses, landmarks
    /// and face-space points tracked when the talker was built (nothing is tracked now).
    pub fn footage(
        footage: &crate::footage::Footage,
        plan: &crate::footage::Plan,
    ) -> Result<Backdrop, crate::facespace::FacespaceError> {
        let layout = footage.tracked.layout();
        let mut rows = Vec::with_capacity(plan.frames.len() * layout.dims());
        let mut landmarks = Vec::with_capacity(plan.frames.len());
        for (&g, mix) in plan.frames.iter().zip(&plan.mix) {
            // A dissolve's frames are the weighted mean of its two frames' (poses too:
            // similarities a pixel or two apart, which the mean keeps a similarity).
            let (other, w) = mix.unwrap_or((g, 0.0));
            let lerp = |a: f64, b: f64| a + f64::from(w) * (b - a);
            rows.extend(
                footage
                    .tracked
                    .row(g)
                    .iter()
                    .zip(footage.tracked.row(other))
                    .map(|(&a, &b)| lerp(f64::from(a), f64::from(b)) as f32),
            );
            let (a, b) = (&footage.landmarks[g].points, &footage.landmarks[other].points);
            landmarks.push(crate::shape::Landmarks {
                points: a
                    .iter()
                    .zip(b)
                    .map(|(p, q)| [lerp(p[0], q[0]), lerp(p[1], q[1])])
                    .collect(),
            });
        }
        let tracked = crate::facespace::Frames::from_rows(layout, footage.fps, rows)?;
        Ok(Backdrop {
            pose: Pose::Replay((0..tracked.len()).map(|t| tracked.params(t).pose).collect()),
            landmarks,
            tracked,
            tracker_hash: footage.model_hash.clone(),
            plan: Some(plan.clone()),
            frames: Frames::Footage(footage.shown(plan)),
        })
    }

    /// `request` synthesised by `synthesiser` from `codebook` at this background's poses and
    /// fitted to it ([`Backdrop::fit`]): what every utterance drawn over a real frame goes
    /// through (`say`, which may first draw the lips from the sound, `synth`, the demo).
    pub fn synthesise(
        &self,
        synthesiser: &dyn super::Synthesiser,
        codebook: &crate::codebook::Codebook,
        model: &FaceModel,
        request: super::Request,
    ) -> Result<super::Utterance, BackdropError> {
        let request = super::Request {
            pose: self.pose.clone(),
            ..request
        };
        let mut utterance = super::synthesise(synthesiser, codebook, request)?;
        self.fit(model, codebook, &mut utterance)?;
        Ok(utterance)
    }

    /// Fits a synthesis to this background: everything but the lips and chin anchored to its
    /// face ([`Backdrop::anchor_region`]), re-lit to its take ([`Backdrop::match_lighting`]).
    pub fn fit(
        &self,
        model: &FaceModel,
        codebook: &crate::codebook::Codebook,
        utterance: &mut super::Utterance,
    ) -> Result<(), BackdropError> {
        self.anchor_region(model, utterance)?;
        self.match_lighting(model, codebook, utterance);
        Ok(())
    }

    /// For a model that knows its articulators ([`FaceModel::articulators`]: a region model,
    /// or a whole 68-point face), re-fits every variant of `utterance` so that everything but
    /// the lips and chin lies where this background's face has it ([`anchor`]) — a region's
    /// seam on the background's face, and a full face's eyes, brows, nose and jaw line at the
    /// background's head pose instead of another take's; returns whether it did.
    pub fn anchor_region(
        &self,
        model: &FaceModel,
        utterance: &mut super::Utterance,
    ) -> Result<bool, crate::model::ModelError> {
        let Some(articulators) = model.articulators() else {
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
            .push_str("; all but lips and chin anchored to the background's face");
        Ok(true)
    }

    /// Re-lights synthesis from a codebook whose appearance was re-centred per sentence
    /// ([`Photometric::Sentence`](crate::corpus::Photometric::Sentence)): every variant's
    /// appearance moves by (this background's tracked mean − the codebook's mean), so the face
    /// takes this take's lighting instead of the corpus average — exactly undoing the
    /// re-centring when the background is the sentence's own take. Only when the background
    /// was tracked with `model` itself (the same appearance space); returns whether it did.
    pub fn match_lighting(
        &self,
        model: &FaceModel,
        codebook: &crate::codebook::Codebook,
        utterance: &mut super::Utterance,
    ) -> bool {
        let Some(shift) = self.lighting_shift(model, codebook) else {
            return false;
        };
        if utterance.synthesis.frames.layout() != self.tracked.layout() {
            return false;
        }
        relight(&mut utterance.synthesis.frames, &shift);
        if let Some(smoothed) = &mut utterance.smoothed {
            relight(smoothed, &shift);
        }
        utterance
            .pose
            .push_str("; appearance re-lit to the background's mean");
        true
    }

    /// What [`Backdrop::match_lighting`] adds to every appearance vector: this background's
    /// tracked mean − the codebook's mean; `None` when the codebook was not re-centred per
    /// sentence or the background was tracked in another model's space.
    pub fn lighting_shift(
        &self,
        model: &FaceModel,
        codebook: &crate::codebook::Codebook,
    ) -> Option<Vec<f32>> {
        if codebook.photometric != crate::corpus::Photometric::Sentence
            || self.tracker_hash != model.hash()
            || self.tracked.layout() != model.layout()
            || self.tracked.is_empty()
        {
            return None;
        }
        let range = self.tracked.layout().appearance_range();
        let corpus = codebook.appearance_mean();
        let here = self.tracked.values();
        let n = here.nrows() as f64;
        Some(
            range
                .zip(&corpus)
                .map(|(k, c)| {
                    (here.column(k).iter().map(|&x| f64::from(x)).sum::<f64>() / n - c) as f32
                })
                .collect(),
        )
    }

    /// One image (read from `path`): the face found in it (grid search, then the AAM fit)
    /// gives the pose. A fit the model cannot explain (residual above the tracker's
    /// re-initialisation threshold) is a lost face, as on a video's first frame.
    pub fn still(tracker: &FaceModel, path: &Path) -> Result<Backdrop, BackdropError> {
        let image = crate::video::read_frame(path)?;
        // A region model finds the face with its whole-face tracker.
        let fitter = Fitter::new(tracker.tracker(), FitOptions::default(), 2)?;
        let start = fitter.search_start(&image)?;
        let fit = fitter.fit(&image, &start)?;
        if !fit.explained() {
            return Err(CodecError::NoFace {
                path: path.into(),
                error: fit.error,
                threshold: crate::fit::DEFAULT_REINIT_ERROR,
            }
            .into());
        }
        let (pose, _) = tracker
            .shape
            .project(&fit.landmarks)
            .map_err(|e| FitError::Model(e.into()))?;
        let mut row = vec![0f32; tracker.layout().dims()];
        tracker
            .project_into(&image, &fit.landmarks, &mut row)
            .map_err(FitError::Model)?;
        let tracked = crate::facespace::Frames::from_rows(tracker.layout(), 1.0, row)
            .map_err(CodecError::from)?;
        Ok(Backdrop {
            frames: Frames::Still(image),
            pose: Pose::Hold(pose),
            landmarks: vec![fit.landmarks],
            tracked,
            tracker_hash: tracker.hash(),
            plan: None,
        })
    }

    /// A video, tracked with `tracker`: replayed frame by frame (a video shorter than the
    /// utterance extended as a talker's footage is: stretches joined where they match, never
    /// backwards) or held at its first frame. `frames` is the number of output
    /// frames to cover. Only the frames shown are tracked — the first `frames`, or the first
    /// one when held — so a long video costs no more than its part under the utterance, and
    /// a background of someone else fails as soon as those frames are lost.
    pub fn video(
        tracker: &FaceModel,
        path: &Path,
        mode: PoseMode,
        frames: usize,
        options: &EncodeOptions,
        progress: impl FnMut(Progress),
    ) -> Result<Backdrop, BackdropError> {
        let needed = match mode {
            PoseMode::Hold => 1,
            PoseMode::Replay => frames.max(1),
        };
        let source = Source::open(path)?.limit(needed);
        let fps = source.info().fps;
        let dims = tracker.layout().dims();
        // A background of someone else is judged on its first frames, not after them all.
        let options = &EncodeOptions {
            early_verdict: Some(EARLY_VERDICT_FRAMES),
            ..options.clone()
        };
        let (mut landmarks, mut values, mut thumbs) = (Vec::new(), Vec::<f32>::new(), Vec::new());
        let size = (source.info().width, source.info().height);
        let tracking = codec::track(tracker, source, options, progress, |image, t| {
            let start = values.len();
            values.resize(start + dims, 0.0);
            tracker.project_into(&image, &t.landmarks, &mut values[start..])?;
            landmarks.push(t.landmarks.clone());
            thumbs.push(crate::footage::thumbnail(&image));
            Ok(())
        })?;
        let tracked = crate::facespace::Frames::from_rows(tracker.layout(), fps, values)
            .map_err(CodecError::from)?;
        let tracker_hash = tracker.hash();
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
                tracked,
                tracker_hash,
                plan: None,
            },
            PoseMode::Replay if poses.len() >= frames => Backdrop {
                frames: Frames::Video(path.into()),
                pose: Pose::Replay(poses[..frames].to_vec()),
                landmarks: landmarks[..frames].to_vec(),
                tracked,
                tracker_hash,
                plan: None,
            },
            PoseMode::Replay => {
                // Shorter than the speech: extended as a talker's footage is — stretches
                // joined where they match, never played backwards.
                let footage = crate::footage::Footage::of_video(
                    path,
                    size,
                    tracker_hash,
                    landmarks,
                    tracked,
                    &thumbs,
                );
                let plan = footage.best_plan(frames, 0);
                Backdrop::footage(&footage, &plan).map_err(CodecError::from)?
            }
        })
    }
}

/// How much the articulators (lips and chin) weigh, all together, against all the other
/// landmarks together when [`anchor`] re-fits a shape: the lips are what the viewer watches
/// and what synthesis made, while the rest only has to keep the region's seam on the
/// background's face. Chosen on GRID s1's validation split through `say` (BENCHMARKS "Say"):
/// with equal weight per landmark (27 of 68: a total of 0.66) the shape model's compromise
/// between the synthesised lips and another take's face took their motion from 0.90× to
/// 0.87× of real; 1 keeps it (0.895×); 3 adds the footage's own jitter (0.98×).
pub const ARTICULATOR_WEIGHT_TOTAL: f64 = 1.0;

/// Adds `shift` to every frame's appearance ([`Backdrop::lighting_shift`]).
pub fn relight(frames: &mut crate::facespace::Frames, shift: &[f32]) {
    let range = frames.layout().appearance_range();
    let mut v = frames.values_mut();
    for mut row in v.rows_mut() {
        for (k, d) in range.clone().zip(shift) {
            row[k] += d;
        }
    }
}

/// Region synthesis over a background face (DESIGN §7, \[blend\] §3): every frame's shape is
/// re-fitted, at its (background) pose, by weighted least squares ([`ARTICULATOR_WEIGHT_TOTAL`])
/// to landmarks that take the `articulators` — lips and
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
    let weight = ARTICULATOR_WEIGHT_TOTAL * fixed.len() as f64 / articulators.len().max(1) as f64;
    let weights: Vec<f64> = moving
        .iter()
        .flat_map(|&m| [if m { weight } else { 1.0 }; 2])
        .collect();
    let projection = model
        .shape
        .pca
        .weighted(&weights)
        .ok_or_else(|| crate::shape::ShapeError::Degenerate {
            what: "the shape model weighted to the articulators".into(),
        })?;
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
        let b = model
            .shape
            .project_at_weighted(&pose, &composite, &projection)?;
        let mut row = frames.values_mut();
        let mut row = row.row_mut(t);
        for (k, v) in layout.shape_range().zip(b) {
            row[k] = v;
        }
    }
    Ok(())
}
