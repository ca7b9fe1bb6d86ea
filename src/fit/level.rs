//! One pyramid level of the search: its reference frame and what is precomputed on it — the
//! mean appearance, the orthonormal appearance basis projected out, the steepest-descent
//! images and the inverse Hessian, the motion basis (similarity + shape modes).

use nalgebra::DMatrix;

use super::FitError;
use crate::mesh::{BarycentricMap, ReferenceFrame};
use crate::model::{FaceModel, ModelError};
use crate::shape::Point;
use crate::warp;

/// One pyramid level: its reference frame and the precomputed quantities on it.
pub(super) struct Level {
    /// Image downsampling factor of this level (1, 2, 4, …).
    pub(super) factor: usize,
    pub(super) frame: ReferenceFrame,
    /// The frame's mask as runs for the warp.
    pub(super) runs: warp::Runs,
    /// Mean appearance, grey, one value per mask pixel. The fit's per-pixel data are f32 (the
    /// image's grey levels carry far less precision), their products summed in f64 ([`dot32`]).
    pub(super) a0: Vec<f32>,
    /// Orthonormal grey appearance basis (rows), projected out of the error.
    pub(super) appearance: Vec<Vec<f32>>,
    /// Project-out steepest-descent images: one row of `n_pixels` per motion parameter.
    pub(super) sd: Vec<Vec<f32>>,
    pub(super) h_inv: DMatrix<f64>,
    /// Orthonormal basis of mesh motions in this frame's pixels: 4 similarity + shape
    /// modes, each a `2L` vector.
    pub(super) basis: Vec<Vec<f64>>,
    /// Triangles around each vertex (for composing through the piecewise warp).
    pub(super) vertex_triangles: Vec<Vec<usize>>,
}

fn grey(rgb: &[f32]) -> Vec<f64> {
    rgb.chunks_exact(3)
        .map(|c| (c[0] as f64 + c[1] as f64 + c[2] as f64) / 3.0)
        .collect()
}

/// Dot product with eight independent partial sums, so the compiler can keep them in SIMD
/// lanes (an in-order sum is a dependency chain it may not reorder): the fit's hot loop.
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
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

/// Dot product of f32 rows summed in f64: blocks of 256 products in sixteen f32 lanes (SIMD
/// registers), each block's sum added in f64 — half the memory traffic of f64 rows, and the
/// rounding of a 15 000-pixel sum stays near f64's (a block's partial sums are short).
pub(super) fn dot32(a: &[f32], b: &[f32]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: this CPU has AVX2 (checked just above).
        return unsafe { dot32_avx2(a, b) };
    }
    dot32_lanes(a, b)
}

/// [`dot32_lanes`] compiled for AVX2: its sixteen lanes in two registers instead of four, the
/// same operations in the same order (no fused multiply-add), so the same sum to the bit.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn dot32_avx2(a: &[f32], b: &[f32]) -> f64 {
    dot32_lanes(a, b)
}

#[inline(always)]
fn dot32_lanes(a: &[f32], b: &[f32]) -> f64 {
    const LANES: usize = 16;
    const BLOCK: usize = 256;
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut total = 0f64;
    for (ba, bb) in a.chunks(BLOCK).zip(b.chunks(BLOCK)) {
        let (ca, cb) = (ba.chunks_exact(LANES), bb.chunks_exact(LANES));
        let tail: f32 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
        let mut acc = [0f32; LANES];
        for (x, y) in ca.zip(cb) {
            for i in 0..LANES {
                acc[i] += x[i] * y[i];
            }
        }
        total += acc.iter().map(|&v| f64::from(v)).sum::<f64>() + f64::from(tail);
    }
    total
}

/// f64 rows as f32 (what the fit keeps).
pub(super) fn to_f32(rows: Vec<Vec<f64>>) -> Vec<Vec<f32>> {
    rows.into_iter()
        .map(|r| r.into_iter().map(|v| v as f32).collect())
        .collect()
}

/// f32 values as f64 (the opt-in refinement builds its template in f64).
pub(super) fn to_f64(row: &[f32]) -> Vec<f64> {
    row.iter().map(|&v| f64::from(v)).collect()
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
pub(super) fn scale_points(points: &[Point], s: f64) -> Vec<Point> {
    points
        .iter()
        .map(|p| [(p[0] + 0.5) * s - 0.5, (p[1] + 0.5) * s - 0.5])
        .collect()
}

/// Steepest-descent images `∇T · ∂W/∂p_k` over the mask of `frame`, one row per motion in
/// `basis`; `∇T` by central differences (one-sided at the mask's edge).
pub(super) fn steepest_descent(
    frame: &ReferenceFrame,
    template: &[f64],
    basis: &[Vec<f64>],
) -> Vec<Vec<f64>> {
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
pub(super) fn project_out(rows: &mut [Vec<f64>], appearance: &[Vec<f64>]) {
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
    pub(super) fn new(model: &FaceModel, factor: usize) -> Result<Self, FitError> {
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
                margin: model.placement.margin * s,
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
            runs: warp::Runs::new(&frame),
            frame,
            a0: a0.into_iter().map(|v| v as f32).collect(),
            appearance: to_f32(appearance),
            sd: to_f32(sd),
            h_inv,
            basis,
            vertex_triangles,
        })
    }

    /// RMS of the error image with the appearance subspace projected out: with an
    /// orthonormal basis, `|r|² = |e|² − Σᵢ (aᵢ·e)²` (dot products only, no copy).
    pub(super) fn residual(&self, e: &[f32]) -> f64 {
        let total = dot32(e, e)
            - self
                .appearance
                .iter()
                .map(|a| dot32(a, e).powi(2))
                .sum::<f64>();
        (total.max(0.0) / e.len() as f64).sqrt()
    }

    /// The error image `texture − A₀` in place: the mesh at `points` on `image` warped into
    /// this level's frame, less the mean appearance.
    pub(super) fn error_into(
        &self,
        image: &warp::GreyImage,
        points: &[Point],
        e: &mut [f32],
    ) -> Result<(), FitError> {
        warp::to_reference_grey_into(&self.frame, &self.runs, image, points, e).map_err(ModelError::from)?;
        e.iter_mut().zip(&self.a0).for_each(|(v, a)| *v -= a);
        Ok(())
    }

    /// Maps reference-frame points (one per vertex) through the piecewise affine warp from the
    /// reference mesh to `current`, averaging each vertex over its triangles.
    pub(super) fn compose(&self, moved: &[Point], current: &[Point]) -> Vec<Point> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The f32 dot product against the f64 sum of the same f32 values: within the rounding
    /// of 256-term f32 partial sums (a few units in 1e-6 of the sum of |products|), for
    /// lengths that leave remainders of every kind.
    #[test]
    fn dot32_matches_an_f64_sum() {
        for n in [0usize, 1, 15, 16, 17, 255, 256, 257, 4099, 15_001] {
            let a: Vec<f32> = (0..n).map(|i| ((i * 37 % 101) as f32 - 50.0) * 0.731).collect();
            let b: Vec<f32> = (0..n).map(|i| ((i * 53 % 97) as f32 - 48.0) * 1.37).collect();
            let exact: f64 = a.iter().zip(&b).map(|(&x, &y)| f64::from(x) * f64::from(y)).sum();
            let scale: f64 = a.iter().zip(&b).map(|(&x, &y)| (f64::from(x) * f64::from(y)).abs()).sum();
            let d = dot32(&a, &b);
            assert!((d - exact).abs() <= 5e-6 * scale.max(1.0), "n {n}: {d} vs {exact}");
            // The portable code gives the same sum as what ran (AVX2's where the CPU has it).
            assert_eq!(dot32_lanes(&a, &b).to_bits(), d.to_bits(), "n {n}");
        }
    }
}
