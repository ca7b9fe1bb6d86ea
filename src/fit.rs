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

use image::RgbImage;
use nalgebra::{DMatrix, DVector};
use thiserror::Error;

use crate::mesh::{BarycentricMap, ReferenceFrame};
use crate::model::{FaceModel, ModelError};
use crate::shape::{Landmarks, Point};
use crate::warp::{self, GreyImage};

#[derive(Debug, Error)]
pub enum FitError {
    #[error("the model has no appearance components to project out")]
    NoAppearance,
    #[error("the fitting Hessian is singular")]
    Singular,
    #[error("a {width}×{height} frame is too small to hold the model's face at any searched scale")]
    TooSmall { width: u32, height: u32 },
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// Options of the search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
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
    pub landmarks: Landmarks,
    pub iterations: usize,
    /// RMS of the residual left after projecting out the appearance model (grey levels).
    pub error: f64,
    pub converged: bool,
}

/// A fitter: per pyramid level, the precomputed steepest-descent images and Hessian.
pub struct Fitter<'m> {
    model: &'m FaceModel,
    /// Coarsest first; level `k` works on images downsampled by `2^k`.
    levels: Vec<Level>,
    options: FitOptions,
}

/// One pyramid level: its reference frame and the precomputed quantities on it.
struct Level {
    /// Image downsampling factor of this level (1, 2, 4, …).
    factor: usize,
    frame: ReferenceFrame,
    /// Mean appearance, grey, one value per mask pixel.
    a0: Vec<f64>,
    /// Orthonormal grey appearance basis (rows), projected out of the error.
    appearance: Vec<Vec<f64>>,
    /// Project-out steepest-descent images: one row of `n_pixels` per motion parameter.
    sd: Vec<Vec<f64>>,
    h_inv: DMatrix<f64>,
    /// Orthonormal basis of mesh motions in this frame's pixels: 4 similarity + shape
    /// modes, each a `2L` vector.
    basis: Vec<Vec<f64>>,
    /// Triangles around each vertex (for composing through the piecewise warp).
    vertex_triangles: Vec<Vec<usize>>,
}

fn grey(rgb: &[f32]) -> Vec<f64> {
    rgb.chunks_exact(3)
        .map(|c| (c[0] as f64 + c[1] as f64 + c[2] as f64) / 3.0)
        .collect()
}

/// Dot product with eight independent partial sums, so the compiler can keep them in SIMD
/// lanes (an in-order sum is a dependency chain it may not reorder): the fit's hot loop.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut acc = [0.0f64; 8];
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// Gram–Schmidt: orthonormal versions of the vectors, dropping (near) dependent ones.
fn orthonormalise(vectors: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::new();
    for mut v in vectors {
        let norm0 = dot(&v, &v).sqrt();
        for u in &out {
            let p = dot(&v, u);
            v.iter_mut().zip(u).for_each(|(a, b)| *a -= p * b);
        }
        let norm = dot(&v, &v).sqrt();
        if norm > 1e-8 * norm0.max(1e-300) {
            v.iter_mut().for_each(|a| *a /= norm);
            out.push(v);
        }
    }
    out
}

/// Pixel-centre coordinates scaled by `1/factor` (and back with `1/factor` = factor).
fn scale_points(points: &[Point], s: f64) -> Vec<Point> {
    points
        .iter()
        .map(|p| [(p[0] + 0.5) * s - 0.5, (p[1] + 0.5) * s - 0.5])
        .collect()
}

/// Steepest-descent images `∇T · ∂W/∂p_k` over the mask of `frame`, one row per motion in
/// `basis`; `∇T` by central differences (one-sided at the mask's edge).
fn steepest_descent(frame: &ReferenceFrame, template: &[f64], basis: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (w, h) = (frame.width, frame.height);
    let mut img = vec![f64::NAN; w * h];
    for (p, v) in frame.pixels.iter().zip(template) {
        img[p.y as usize * w + p.x as usize] = *v;
    }
    let value = |x: i64, y: i64| -> Option<f64> {
        (x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h)
            .then(|| img[y as usize * w + x as usize])
            .filter(|v| v.is_finite())
    };
    let diff = |x: i64, y: i64, dx: i64, dy: i64, centre: f64| match (
        value(x + dx, y + dy),
        value(x - dx, y - dy),
    ) {
        (Some(a), Some(b)) => (a - b) / 2.0,
        (Some(a), None) => a - centre,
        (None, Some(b)) => centre - b,
        (None, None) => 0.0,
    };
    let n = frame.n_pixels();
    let mut sd = vec![vec![0.0; n]; basis.len()];
    for (i, px) in frame.pixels.iter().enumerate() {
        let (x, y) = (px.x as i64, px.y as i64);
        let (gx, gy) = (diff(x, y, 1, 0, template[i]), diff(x, y, 0, 1, template[i]));
        let tri = frame.triangles[px.triangle as usize];
        for (k, b) in basis.iter().enumerate() {
            // ∂W/∂p_k at this pixel: the barycentric mix of the vertices' motions.
            let (mut dx, mut dy) = (0.0, 0.0);
            for (j, &v) in tri.iter().enumerate() {
                dx += px.bary[j] as f64 * b[2 * v as usize];
                dy += px.bary[j] as f64 * b[2 * v as usize + 1];
            }
            sd[k][i] = gx * dx + gy * dy;
        }
    }
    sd
}

/// Removes the span of the orthonormal rows `appearance` from each row of `rows`.
fn project_out(rows: &mut [Vec<f64>], appearance: &[Vec<f64>]) {
    for row in rows {
        for a in appearance {
            let p = dot(row, a);
            row.iter_mut().zip(a).for_each(|(r, v)| *r -= p * v);
        }
    }
}

impl Level {
    /// Builds level `factor` from the model: the reference frame is the model's scaled by
    /// `1/factor`; grey templates are box-sampled from the full-resolution textures.
    fn new(model: &FaceModel, factor: usize) -> Result<Self, FitError> {
        let full = &model.frame;
        let s = 1.0 / factor as f64;
        let frame = if factor == 1 {
            full.clone()
        } else {
            let placement = crate::mesh::Placement {
                scale: model.placement.scale * s,
                offset: [
                    (model.placement.offset[0] + 0.5) * s - 0.5,
                    (model.placement.offset[1] + 0.5) * s - 0.5,
                ],
            };
            ReferenceFrame::place(&model.shape.mean(), full.triangles.clone(), placement)
                .map_err(ModelError::from)?
        };
        // A full-resolution texture → this level's grey texture (mean of the factor² block).
        let resample = |texture: &[f32]| -> Result<Vec<f64>, FitError> {
            if factor == 1 {
                return Ok(grey(texture));
            }
            let img = warp::texture_to_image(full, texture).map_err(ModelError::from)?;
            let (w, h) = (full.width, full.height);
            Ok(frame
                .pixels
                .iter()
                .map(|p| {
                    let mut sum = 0.0;
                    for dy in 0..factor {
                        for dx in 0..factor {
                            let (x, y) = (
                                (p.x as usize * factor + dx).min(w - 1),
                                (p.y as usize * factor + dy).min(h - 1),
                            );
                            let i = (y * w + x) * 3;
                            sum += (img[i] + img[i + 1] + img[i + 2]) as f64 / 3.0;
                        }
                    }
                    sum / (factor * factor) as f64
                })
                .collect())
        };
        let a0 = resample(&model.appearance.pca.mean)?;
        let appearance = orthonormalise(
            (0..model.appearance.n_params())
                .map(|k| resample(model.appearance.pca.component(k)))
                .collect::<Result<_, _>>()?,
        );
        let l = frame.landmarks.len();
        let c = crate::shape::centroid(&frame.landmarks);
        let mut basis = vec![
            frame
                .landmarks
                .iter()
                .flat_map(|p| [p[0] - c[0], p[1] - c[1]])
                .collect::<Vec<f64>>(),
            frame
                .landmarks
                .iter()
                .flat_map(|p| [-(p[1] - c[1]), p[0] - c[0]])
                .collect(),
            (0..l).flat_map(|_| [1.0, 0.0]).collect(),
            (0..l).flat_map(|_| [0.0, 1.0]).collect(),
        ];
        for k in 0..model.shape.n_params() {
            basis.push(
                model
                    .shape
                    .pca
                    .component(k)
                    .iter()
                    .map(|&v| v as f64)
                    .collect(),
            );
        }
        let basis = orthonormalise(basis);
        let mut sd = steepest_descent(&frame, &a0, &basis);
        project_out(&mut sd, &appearance);
        let m = sd.len();
        let h_inv = DMatrix::from_fn(m, m, |i, j| dot(&sd[i], &sd[j]))
            .try_inverse()
            .ok_or(FitError::Singular)?;
        let mut vertex_triangles = vec![Vec::new(); l];
        for (t, tri) in frame.triangles.iter().enumerate() {
            tri.iter()
                .for_each(|&v| vertex_triangles[v as usize].push(t));
        }
        Ok(Level {
            factor,
            frame,
            a0,
            appearance,
            sd,
            h_inv,
            basis,
            vertex_triangles,
        })
    }

    /// RMS of the error image with the appearance subspace projected out: with an
    /// orthonormal basis, `|r|² = |e|² − Σᵢ (aᵢ·e)²` (dot products only, no copy).
    fn residual(&self, e: &[f64]) -> f64 {
        let total = dot(e, e)
            - self
                .appearance
                .iter()
                .map(|a| dot(a, e).powi(2))
                .sum::<f64>();
        (total.max(0.0) / e.len() as f64).sqrt()
    }

    /// Maps reference-frame points (one per vertex) through the piecewise affine warp from the
    /// reference mesh to `current`, averaging each vertex over its triangles.
    fn compose(&self, moved: &[Point], current: &[Point]) -> Vec<Point> {
        moved
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
                for &t in &self.vertex_triangles[v] {
                    let tri = self.frame.triangles[t];
                    let [a, b, c] = tri.map(|i| self.frame.landmarks[i as usize]);
                    if let Some(map) = BarycentricMap::new(a, b, c) {
                        let l = map.at(*p);
                        let [ca, cb, cc] = tri.map(|i| current[i as usize]);
                        sx += l[0] * ca[0] + l[1] * cb[0] + l[2] * cc[0];
                        sy += l[0] * ca[1] + l[1] * cb[1] + l[2] * cc[1];
                        n += 1.0;
                    }
                }
                if n > 0.0 {
                    [sx / n, sy / n]
                } else {
                    current[v]
                }
            })
            .collect()
    }
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
        for level in &self.levels {
            let img = &pyramid[level.factor.trailing_zeros() as usize];
            let start = Landmarks {
                points: scale_points(&current, 1.0 / level.factor as f64),
            };
            let (fitted, iterations, converged, error) = self.fit_level(level, img, &start)?;
            total += iterations;
            current = scale_points(&fitted.points, level.factor as f64);
            last = Some((converged, error));
        }
        let (converged, error) = last.unwrap_or((false, f64::INFINITY));
        Ok(FitResult {
            landmarks: Landmarks { points: current },
            iterations: total,
            error,
            converged,
        })
    }

    fn fit_level(
        &self,
        level: &Level,
        image: &GreyImage,
        init: &Landmarks,
    ) -> Result<(Landmarks, usize, bool, f64), FitError> {
        let frame = &level.frame;
        let mut current = self.constrain(init)?;
        let mut texture = vec![0f32; frame.n_pixels()];
        let error_at =
            |current: &Landmarks, texture: &mut Vec<f32>| -> Result<Vec<f64>, FitError> {
                warp::to_reference_grey_into(frame, image, &current.points, texture)
                    .map_err(ModelError::from)?;
                Ok(texture
                    .iter()
                    .zip(&level.a0)
                    .map(|(&i, a)| i as f64 - a)
                    .collect())
            };
        let mut iterations = 0;
        let mut converged = false;
        let tolerance = self.options.tolerance / level.factor as f64;
        while iterations < self.options.max_iterations {
            iterations += 1;
            let e = error_at(&current, &mut texture)?;
            let b = DVector::from_iterator(level.sd.len(), level.sd.iter().map(|row| dot(row, &e)));
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
                let e = error_at(&current, &mut texture)?;
                let (next, shift) = self.refine_step(level, &current, &e)?;
                current = next;
                if shift < tolerance {
                    break;
                }
            }
        }
        let e = error_at(&current, &mut texture)?;
        Ok((current, iterations, converged, level.residual(&e)))
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
        e: &[f64],
    ) -> Result<(Landmarks, f64), FitError> {
        let mut template = level.a0.clone();
        let mut residual = e.to_vec();
        for a in &level.appearance {
            let lambda = dot(a, e);
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
        project_out(&mut sd, &level.appearance);
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

impl Fitter<'_> {
    /// A first-frame start with no landmarks: the mean shape tried on a grid of positions
    /// (steps of a tenth of the face width) and scales (0.6–1.5 of the model's reference
    /// size) one octave below the coarsest pyramid level, scored by the projected-out
    /// residual against the mean appearance; the best dozen distinct places are each fitted
    /// on the coarsest level, and the lowest residual wins. Costs a few hundred warps of a
    /// few thousand pixels and twelve coarse fits.
    pub fn search_start(&self, image: &RgbImage) -> Result<Landmarks, FitError> {
        const SHORTLIST: usize = 12;
        // One octave below the coarsest level; built here, as only a first frame needs it.
        let search = Level::new(self.model, 2 * self.levels[0].factor)?;
        let grey = GreyImage::from_rgb(image);
        let mut candidates = self.grid_scores(&search, &grey)?;
        if candidates.is_empty() {
            return Err(FitError::TooSmall {
                width: image.width(),
                height: image.height(),
            });
        }
        // The best few *distinct* places (non-maximum suppression): neighbours of one
        // wrong minimum would otherwise fill the shortlist.
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut shortlist: Vec<(f64, Vec<Point>)> = Vec::with_capacity(SHORTLIST);
        for c in candidates {
            let (lo, hi) = Landmarks {
                points: c.1.clone(),
            }
            .bounds();
            let centre = crate::shape::centroid(&c.1);
            let apart = shortlist.iter().all(|k| {
                let other = crate::shape::centroid(&k.1);
                (centre[0] - other[0]).hypot(centre[1] - other[1]) > 0.25 * (hi[0] - lo[0])
            });
            if apart {
                shortlist.push(c);
                if shortlist.len() == SHORTLIST {
                    break;
                }
            }
        }
        let candidates = shortlist;
        let (level, ratio) = (&self.levels[0], search.factor as f64);
        let coarse = downsample(grey, level.factor);
        let mut best = (f64::INFINITY, Vec::new());
        for (_, placed) in candidates {
            let start = Landmarks {
                points: scale_points(&placed, ratio / level.factor as f64),
            };
            let (fitted, _, _, r) = self.fit_level(level, &coarse, &start)?;
            if r < best.0 {
                best = (r, fitted.points);
            }
        }
        Ok(Landmarks {
            points: scale_points(&best.1, level.factor as f64),
        })
    }

    /// Residual of the mean shape at every grid position and scale on `level`'s image.
    fn grid_scores(
        &self,
        level: &Level,
        grey: &GreyImage,
    ) -> Result<Vec<(f64, Vec<Point>)>, FitError> {
        let coarse = downsample(grey.clone(), level.factor);
        let mean = self.model.shape.mean();
        let mut texture = vec![0f32; level.frame.n_pixels()];
        let mut out = Vec::new();
        let base = self.model.placement.scale / level.factor as f64;
        for scale in [0.6, 0.75, 0.9, 1.05, 1.25, 1.5] {
            let s = base * scale;
            let pts: Vec<Point> = mean.iter().map(|p| [s * p[0], s * p[1]]).collect();
            let (lo, hi) = Landmarks {
                points: pts.clone(),
            }
            .bounds();
            let step = (0.1 * (hi[0] - lo[0])).max(1.0);
            let (w, h) = (coarse.width as f64, coarse.height as f64);
            let mut cy = -lo[1];
            while cy + hi[1] <= h {
                let mut cx = -lo[0];
                while cx + hi[0] <= w {
                    let placed: Vec<Point> = pts.iter().map(|p| [p[0] + cx, p[1] + cy]).collect();
                    out.push((level.score(&coarse, &placed, &mut texture)?, placed));
                    cx += step;
                }
                cy += step;
            }
        }
        Ok(out)
    }
}

/// `image` halved until it is `factor` times smaller.
fn downsample(mut image: GreyImage, factor: usize) -> GreyImage {
    let mut f = 1;
    while f < factor {
        image = image.half();
        f *= 2;
    }
    image
}

impl Level {
    /// Projected-out residual of the mean appearance with the mesh at `placed` on `image`.
    fn score(
        &self,
        image: &GreyImage,
        placed: &[Point],
        texture: &mut [f32],
    ) -> Result<f64, FitError> {
        warp::to_reference_grey_into(&self.frame, image, placed, texture)
            .map_err(ModelError::from)?;
        let e: Vec<f64> = texture
            .iter()
            .zip(&self.a0)
            .map(|(&i, a)| i as f64 - a)
            .collect();
        Ok(self.residual(&e))
    }
}

/// One tracked frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackedFrame {
    pub landmarks: Landmarks,
    /// Projected-out residual RMS (grey levels) of the kept fit.
    pub error: f64,
    pub iterations: usize,
    /// The fit from the previous frame failed the error threshold and the frame was
    /// re-initialised from the mean shape at the last good pose.
    pub reinitialised: bool,
}

/// Tracks a sequence: frame t starts from frame t−1's fit (DESIGN §4).
pub struct Tracker<'m> {
    fitter: Fitter<'m>,
    previous: Landmarks,
    last_good_pose: crate::shape::Similarity,
    /// Residual RMS (grey levels) above which a fit counts as lost.
    pub reinit_error: f64,
}

impl<'m> Tracker<'m> {
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

    pub fn track(&mut self, image: &RgbImage) -> Result<TrackedFrame, FitError> {
        let mut fit = self.fitter.fit(image, &self.previous)?;
        let mut reinitialised = false;
        if fit.error > self.reinit_error {
            let shape = &self.fitter.model.shape;
            let start = shape.instance(&self.last_good_pose, &vec![0.0; shape.n_params()]);
            let again = self.fitter.fit(image, &start)?;
            reinitialised = true;
            if again.error < fit.error {
                fit = FitResult {
                    iterations: fit.iterations + again.iterations,
                    ..again
                };
            }
        }
        if fit.error <= self.reinit_error {
            self.last_good_pose = self
                .fitter
                .model
                .shape
                .project(&fit.landmarks)
                .map_err(ModelError::from)?
                .0;
        }
        self.previous = fit.landmarks.clone();
        Ok(TrackedFrame {
            landmarks: fit.landmarks,
            error: fit.error,
            iterations: fit.iterations,
            reinitialised,
        })
    }
}
