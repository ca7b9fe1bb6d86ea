//! AAM search (DESIGN §4): project-out inverse compositional fitting (Matthews & Baker 2004,
//! "Active Appearance Models Revisited") over the shape model plus a global similarity.
//!
//! Precomputed once per model, on the mean appearance in the reference frame (greyscale):
//! the steepest-descent images `SD = ∇A₀ · ∂W/∂p` with the appearance variation projected
//! out, and the Hessian `H = SDᵀ SD`. Each iteration warps the image to the reference frame at
//! the current landmarks, takes `Δp = H⁻¹ SDᵀ (I(W) − A₀)`, and composes the inverse
//! increment: the mesh `s₀ − B Δp` is mapped through the current piecewise affine warp
//! (each vertex averaged over its triangles), then projected onto the shape model (pose +
//! parameters, clamped to ±3σ). Greyscale: a third of the work of RGB for the same geometry.

mod level;
mod search;
mod track;

use image::RgbImage;
use nalgebra::{DMatrix, DVector};
use thiserror::Error;

pub use track::{DEFAULT_REINIT_ERROR, TrackedFrame, Tracker};

use crate::model::{FaceModel, ModelError};
use crate::options::{self, InvalidOption};
use crate::shape::{Landmarks, Point};
use crate::warp::GreyImage;
use level::{Level, dot, dot32, project_out, scale_points, steepest_descent, to_f64};

/// What can go wrong in the AAM search.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FitError {
    /// A model without appearance components cannot be searched with.
    #[error("the model has no appearance components to project out")]
    NoAppearance,
    /// The Gauss–Newton system has no solution.
    #[error("the fitting Hessian is singular")]
    Singular,
    /// A frame smaller than any searched face.
    #[error("a {width}×{height} frame is too small to hold the model's face at any searched scale")]
    TooSmall {
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
    },
    /// Landmarks or warps that do not fit the model.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// An option out of range.
    #[error(transparent)]
    Option(#[from] InvalidOption),
}

/// Options of the search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Gauss–Newton iterations per pyramid level at most.
    pub max_iterations: usize,
    /// Stop when no landmark moves more than this (pixels).
    pub tolerance: f64,
    /// Shape parameters are clamped to ±this many standard deviations.
    pub clamp_sd: f64,
    /// Iterations of alternating refinement at full resolution after the project-out
    /// search (0: none). Project-out is biased when the appearance is far from the mean;
    /// each refinement step re-estimates the appearance and linearises about that template.
    pub refine_iterations: usize,
}

impl FitOptions {
    /// Checks every option's range.
    pub fn validate(&self) -> Result<(), InvalidOption> {
        options::count_in("iterations", self.max_iterations, 1, 1000)?;
        options::in_range("tolerance (px)", self.tolerance, 0.0, 100.0)?;
        options::in_range("shape clamp (σ)", self.clamp_sd, f64::MIN_POSITIVE, 100.0)?;
        options::count_in("refinement steps", self.refine_iterations, 0, 1000)?;
        Ok(())
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            max_iterations: 40,
            tolerance: 0.01,
            clamp_sd: 3.0,
            refine_iterations: 0,
        }
    }
}

/// The outcome of one fit.
#[derive(Clone, Debug, PartialEq)]
pub struct FitResult {
    /// The fitted landmarks.
    pub landmarks: Landmarks,
    /// Iterations spent over all levels.
    pub iterations: usize,
    /// RMS of the residual left after projecting out the appearance model (grey levels).
    pub error: f64,
    /// Whether the finest level stopped below the tolerance.
    pub converged: bool,
}

impl FitResult {
    /// Whether the model explains the face it found: a residual at most the tracker's
    /// re-initialisation threshold ([`DEFAULT_REINIT_ERROR`]); NaN counts as unexplained.
    pub fn explained(&self) -> bool {
        matches!(
            self.error.partial_cmp(&DEFAULT_REINIT_ERROR),
            Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
        )
    }
}

/// A fitter: per pyramid level, the precomputed steepest-descent images and Hessian.
pub struct Fitter<'m> {
    model: &'m FaceModel,
    /// Coarsest first; level `k` works on images downsampled by `2^k`.
    levels: Vec<Level>,
    options: FitOptions,
}

impl<'m> Fitter<'m> {
    /// Precomputes `levels` pyramid levels (at least 1; the default is 2).
    pub fn new(model: &'m FaceModel, options: FitOptions, levels: usize) -> Result<Self, FitError> {
        if model.appearance.n_params() == 0 {
            return Err(FitError::NoAppearance);
        }
        let levels: Vec<Level> = (0..levels.max(1))
            .rev()
            .map(|k| Level::new(model, 1 << k))
            .collect::<Result<_, _>>()?;
        Ok(Fitter {
            model,
            levels,
            options,
        })
    }

    /// Fits the model to `image` starting from `init` landmarks, coarse to fine.
    pub fn fit(&self, image: &RgbImage, init: &Landmarks) -> Result<FitResult, FitError> {
        let mut pyramid = vec![GreyImage::from_rgb(image)];
        while pyramid.len() < self.levels.len() {
            let next = pyramid.last().expect("non-empty").half();
            pyramid.push(next);
        }
        let mut current = init.points.clone();
        let mut total = 0;
        let mut last = None;
        for (k, level) in self.levels.iter().enumerate() {
            let img = &pyramid[level.factor.trailing_zeros() as usize];
            let start = Landmarks {
                points: scale_points(&current, 1.0 / level.factor as f64),
            };
            let last_level = k + 1 == self.levels.len();
            let (fitted, iterations, converged, error) = self.fit_level(level, img, &start, last_level)?;
            total += iterations;
            current = scale_points(&fitted.points, level.factor as f64);
            last = Some((converged, error));
        }
        let (converged, error) = last.unwrap_or((false, None));
        let error = error.unwrap_or(f64::INFINITY);
        Ok(FitResult {
            landmarks: Landmarks { points: current },
            iterations: total,
            error,
            converged,
        })
    }

    /// Fits on one level from `init`: the landmarks, iterations, whether the steps converged,
    /// and, when `residual` (only the last level's is reported), the residual RMS.
    fn fit_level(
        &self,
        level: &Level,
        image: &GreyImage,
        init: &Landmarks,
        residual: bool,
    ) -> Result<(Landmarks, usize, bool, Option<f64>), FitError> {
        let mut current = self.constrain(init)?;
        let mut e = vec![0f32; level.frame.n_pixels()];
        let mut iterations = 0;
        let mut converged = false;
        let tolerance = self.options.tolerance / level.factor as f64;
        while iterations < self.options.max_iterations {
            iterations += 1;
            level.error_into(image, &current.points, &mut e)?;
            let b = DVector::from_iterator(level.sd.len(), level.sd.iter().map(|row| dot32(row, &e)));
            let (next, shift) = self.step(level, &current, &(&level.h_inv * b))?;
            current = next;
            if shift < tolerance {
                converged = true;
                break;
            }
        }
        if level.factor == 1 {
            for _ in 0..self.options.refine_iterations {
                iterations += 1;
                level.error_into(image, &current.points, &mut e)?;
                let (next, shift) = self.refine_step(level, &current, &e)?;
                current = next;
                if shift < tolerance {
                    break;
                }
            }
        }
        let residual = if residual {
            level.error_into(image, &current.points, &mut e)?;
            Some(level.residual(&e))
        } else {
            None
        };
        Ok((current, iterations, converged, residual))
    }

    /// Composes the inverse of the increment `dp` (in the level's motion basis) with the
    /// current warp and constrains the result to the shape model; returns it and the largest
    /// landmark move.
    fn step(
        &self,
        level: &Level,
        current: &Landmarks,
        dp: &DVector<f64>,
    ) -> Result<(Landmarks, f64), FitError> {
        let moved: Vec<Point> = level
            .frame
            .landmarks
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let (mut x, mut y) = (p[0], p[1]);
                for (k, basis) in level.basis.iter().enumerate() {
                    x -= dp[k] * basis[2 * v];
                    y -= dp[k] * basis[2 * v + 1];
                }
                [x, y]
            })
            .collect();
        let next = self.constrain(&Landmarks {
            points: level.compose(&moved, &current.points),
        })?;
        let shift = next
            .points
            .iter()
            .zip(&current.points)
            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
            .fold(0.0, f64::max);
        Ok((next, shift))
    }

    /// One alternating step (Tzimiropoulos & Pantic 2013, "alternating inverse
    /// compositional"): the appearance `λ = Aᵀe` of the current warp gives the template
    /// `T = A₀ + Aλ`; steepest-descent images of `T`, with the appearance projected out, give
    /// the Gauss–Newton increment for the residual `e − Aλ`. Costs a fresh Hessian per step.
    fn refine_step(
        &self,
        level: &Level,
        current: &Landmarks,
        e: &[f32],
    ) -> Result<(Landmarks, f64), FitError> {
        let appearance: Vec<Vec<f64>> = level.appearance.iter().map(|a| to_f64(a)).collect();
        let e = to_f64(e);
        let mut template = to_f64(&level.a0);
        let mut residual = e.clone();
        for a in &appearance {
            let lambda = dot(a, &e);
            template
                .iter_mut()
                .zip(a)
                .for_each(|(t, v)| *t += lambda * v);
            residual
                .iter_mut()
                .zip(a)
                .for_each(|(r, v)| *r -= lambda * v);
        }
        let mut sd = steepest_descent(&level.frame, &template, &level.basis);
        project_out(&mut sd, &appearance);
        let m = sd.len();
        let h = DMatrix::from_fn(m, m, |i, j| dot(&sd[i], &sd[j]));
        let b = DVector::from_iterator(m, sd.iter().map(|row| dot(row, &residual)));
        let dp = h.lu().solve(&b).ok_or(FitError::Singular)?;
        self.step(level, current, &dp)
    }

    /// Projects landmarks onto the shape model (pose + parameters clamped to ±clamp_sd σ).
    fn constrain(&self, l: &Landmarks) -> Result<Landmarks, FitError> {
        let shape = &self.model.shape;
        let (pose, mut b) = shape.project(l).map_err(ModelError::from)?;
        for (bk, var) in b.iter_mut().zip(&shape.pca.variances) {
            let limit = self.options.clamp_sd as f32 * var.sqrt();
            *bk = bk.clamp(-limit, limit);
        }
        Ok(shape.instance(&pose, &b))
    }
}
