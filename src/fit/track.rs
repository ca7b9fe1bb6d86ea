//! The tracker: frame t starts from frame t−1's fit (DESIGN §4); a lost frame restarts from
//! the mean shape at the last good pose.

use image::RgbImage;

use super::{FitError, FitResult, Fitter};
use crate::model::ModelError;
use crate::shape::{Landmarks, Similarity};

/// Default residual RMS (grey levels) above which a frame counts as lost and is
/// re-initialised: well above the residuals of good fits on the demo clip (BENCHMARKS.md).
pub const DEFAULT_REINIT_ERROR: f64 = 25.0;

/// One tracked frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackedFrame {
    /// The fitted landmarks.
    pub landmarks: Landmarks,
    /// Their pose: the similarity fitting the mean shape onto them.
    pub pose: Similarity,
    /// Projected-out residual RMS (grey levels) of the kept fit.
    pub error: f64,
    /// Gauss–Newton iterations spent, re-initialisation included.
    pub iterations: usize,
    /// The fit from the previous frame failed the error threshold and the frame was
    /// re-initialised from the mean shape at the last good pose.
    pub reinitialised: bool,
    /// Both fits diverged (non-finite values, or landmarks far outside the image): the
    /// previous frame's landmarks are kept, `error` is [`DIVERGED_ERROR`], and the frame
    /// counts as lost. Nothing non-finite ever leaves the tracker.
    pub diverged: bool,
}

/// The residual recorded for a diverged frame: the largest a grey-level RMS can be.
pub const DIVERGED_ERROR: f64 = 255.0;

/// Whether a fit can be kept: a finite residual and landmarks within a few image sizes of the
/// image (a diverging search runs off to 1e32 and beyond).
fn usable(fit: &FitResult, image: &RgbImage) -> bool {
    let limit = 4.0 * f64::from(image.width().max(image.height()));
    fit.error.is_finite()
        && fit.landmarks.points.iter().all(|p| {
            p[0].is_finite() && p[1].is_finite() && p[0].abs() < limit && p[1].abs() < limit
        })
}

/// Tracks a sequence: frame t starts from frame t−1's fit (DESIGN §4).
pub struct Tracker<'m> {
    fitter: Fitter<'m>,
    previous: Landmarks,
    last_good_pose: Similarity,
    /// Residual RMS (grey levels) above which a fit counts as lost.
    pub reinit_error: f64,
}

impl<'m> Tracker<'m> {
    /// A tracker whose first frame starts from `start`.
    pub fn new(fitter: Fitter<'m>, start: Landmarks, reinit_error: f64) -> Result<Self, FitError> {
        let (pose, _) = fitter
            .model
            .shape
            .project(&start)
            .map_err(ModelError::from)?;
        Ok(Tracker {
            fitter,
            previous: start,
            last_good_pose: pose,
            reinit_error,
        })
    }

    /// Fits the next frame from the last one's landmarks.
    pub fn track(&mut self, image: &RgbImage) -> Result<TrackedFrame, FitError> {
        let mut fit = self.fitter.fit(image, &self.previous)?;
        let mut reinitialised = false;
        if !usable(&fit, image) || fit.error > self.reinit_error {
            let shape = &self.fitter.model.shape;
            let start = shape.instance(&self.last_good_pose, &vec![0.0; shape.n_params()]);
            let again = self.fitter.fit(image, &start)?;
            reinitialised = true;
            let better = usable(&again, image) && (!usable(&fit, image) || again.error < fit.error);
            if better {
                fit = FitResult {
                    iterations: fit.iterations + again.iterations,
                    ..again
                };
            }
        }
        let diverged = !usable(&fit, image);
        if diverged {
            fit = FitResult {
                landmarks: self.previous.clone(),
                error: DIVERGED_ERROR,
                ..fit
            };
        }
        let pose = self
            .fitter
            .model
            .shape
            .project(&fit.landmarks)
            .map_err(ModelError::from)?
            .0;
        if !diverged && fit.error <= self.reinit_error {
            self.last_good_pose = pose;
        }
        self.previous = fit.landmarks.clone();
        Ok(TrackedFrame {
            landmarks: fit.landmarks,
            pose,
            error: fit.error,
            iterations: fit.iterations,
            reinitialised,
            diverged,
        })
    }
}
