//! Principal component analysis shared by the shape and appearance models.
//!
//! With fewer samples than dimensions (the appearance case: ~30 images, ~120 000 values)
//! the eigenvectors come from the n×n Gram matrix (the snapshot method, Sirovich 1987);
//! otherwise from the d×d covariance. Both accumulate in f64; the model stores f32.
//! The snapshot method runs on column blocks of the samples (f64 matrix products, blocks in
//! parallel), never holding the centred data whole, and forms only the kept components:
//! 600 textures × 111 426 values in about a second and a few hundred MB.

use nalgebra::{DMatrix, SymmetricEigen};
use ndarray::Array2;
use ndarray::linalg::general_mat_mul;
use rayon::prelude::*;
use thiserror::Error;

use crate::options::InvalidOption;

/// How many components to keep.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Components {
    /// Exactly this many (fewer if the data has lower rank).
    Count(usize),
    /// The fewest that explain `fraction` of the variance, at most `max`.
    Variance {
        /// Fraction of the variance, in (0, 1].
        fraction: f64,
        /// At most this many components.
        max: Option<usize>,
    },
}

impl Components {
    /// Checks the request once, at the API entry.
    pub fn validate(self) -> Result<Self, PcaError> {
        match self {
            Components::Count(0) => Err(InvalidOption::new("components", 0, "at least 1").into()),
            Components::Variance { fraction, .. } if !(fraction > 0.0 && fraction <= 1.0) => {
                Err(InvalidOption::new("variance fraction", fraction, "in (0, 1]").into())
            }
            Components::Variance { max: Some(0), .. } => {
                Err(InvalidOption::new("maximum components", 0, "at least 1").into())
            }
            ok => Ok(ok),
        }
    }
}

/// What can go wrong fitting a PCA model.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PcaError {
    /// Fewer than two samples.
    #[error("PCA needs at least 2 samples, got {0}")]
    TooFewSamples(usize),
    /// Samples of different lengths.
    #[error("sample {index} has {found} values, sample 0 has {expected}")]
    Ragged {
        /// The odd sample (`usize::MAX`: the mean given).
        index: usize,
        /// Sample 0's length.
        expected: usize,
        /// This sample's length.
        found: usize,
    },
    /// A NaN or infinity.
    #[error("sample {index} holds a non-finite value at position {position}")]
    NotFinite {
        /// The sample.
        index: usize,
        /// The value.
        position: usize,
    },
    /// Every sample equal.
    #[error("the samples do not vary: every sample equals the mean")]
    NoVariance,
    /// A component request out of range.
    #[error("invalid component request: {0}")]
    BadComponents(#[from] InvalidOption),
}

/// A linear model `x ≈ mean + componentsᵀ b`.
///
/// `components` holds one orthonormal component per row (row-major, `n_components × dim`),
/// sorted by `variances`, descending. `total_variance` is the variance of the training data
/// about `mean`, so `variance_ratio` tells how much the kept components explain.
#[derive(Clone, Debug, PartialEq)]
pub struct PcaModel {
    /// The mean, `dim` values.
    pub mean: Vec<f32>,
    /// The components, `n_components × dim`, one orthonormal component per row.
    pub components: Vec<f32>,
    /// The variance along each component, descending.
    pub variances: Vec<f32>,
    /// The training data's variance about the mean (every direction).
    pub total_variance: f64,
}

impl PcaModel {
    /// Fits a model about the samples' own mean.
    pub fn fit(samples: &[&[f32]], keep: Components) -> Result<Self, PcaError> {
        keep.validate()?;
        let d = check_samples(samples)?;
        let mut mean = vec![0f64; d];
        for s in samples {
            mean.iter_mut()
                .zip(s.iter())
                .for_each(|(m, &x)| *m += x as f64);
        }
        let n = samples.len() as f64;
        let mean: Vec<f32> = mean.iter().map(|m| (m / n) as f32).collect();
        Self::fit_about(samples, &mean, keep)
    }

    /// Fits a model about a given mean (the Procrustes mean shape, for instance).
    pub fn fit_about(samples: &[&[f32]], mean: &[f32], keep: Components) -> Result<Self, PcaError> {
        let keep = keep.validate()?;
        let d = check_samples(samples)?;
        if mean.len() != d {
            return Err(PcaError::Ragged {
                index: usize::MAX,
                expected: d,
                found: mean.len(),
            });
        }
        let n = samples.len();
        let dof = (n - 1) as f64;
        // Eigen-pairs of the scatter matrix: values (divided by dof below) and, through
        // `vectors(kept)`, the first `kept` unit vectors in data space, rows of a kept × d
        // matrix. Only the kept ones are ever formed.
        let (values, total, vectors): (Vec<f64>, f64, Box<KeptVectors<'_>>) = if n <= d {
            let gram = gram(samples, mean);
            let total = gram.trace();
            let (values, u) = sorted_eigen(gram);
            let vectors = move |kept: usize| snapshot_vectors(samples, mean, &u, kept);
            (values, total, Box::new(vectors))
        } else {
            let mut cov = DMatrix::<f64>::zeros(d, d);
            for s in samples {
                let row: Vec<f64> = s
                    .iter()
                    .zip(mean)
                    .map(|(&x, &m)| x as f64 - m as f64)
                    .collect();
                for i in 0..d {
                    for j in 0..=i {
                        cov[(i, j)] += row[i] * row[j];
                    }
                }
            }
            cov.fill_upper_triangle_with_lower_triangle();
            let total = cov.trace();
            let (values, v) = sorted_eigen(cov);
            let vectors = move |kept: usize| {
                (0..kept)
                    .flat_map(|k| v.column(k).iter().copied().collect::<Vec<_>>())
                    .collect()
            };
            (values, total, Box::new(vectors))
        };
        let values: Vec<f64> = values.iter().map(|l| l / dof).collect();
        let total_variance = total / dof;
        if total_variance <= 0.0 {
            return Err(PcaError::NoVariance);
        }
        // Eigenvalues below this are round-off: the data's rank ends there.
        let rank = values
            .iter()
            .take_while(|&&l| l > values[0] * 1e-10)
            .count();
        let kept = match keep {
            Components::Count(k) => k.min(rank),
            Components::Variance { fraction, max } => {
                let mut sum = 0.0;
                let k = values[..rank]
                    .iter()
                    .position(|l| {
                        sum += l;
                        sum >= fraction * total_variance * (1.0 - 1e-12)
                    })
                    .map_or(rank, |i| i + 1);
                k.min(max.unwrap_or(usize::MAX))
            }
        };
        let components: Vec<f32> = vectors(kept).iter().map(|&x| x as f32).collect();
        Ok(PcaModel {
            mean: mean.to_vec(),
            components,
            variances: values[..kept].iter().map(|&l| l as f32).collect(),
            total_variance,
        })
    }

    /// Values per sample.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Components kept.
    pub fn n_components(&self) -> usize {
        self.variances.len()
    }

    /// Component `k` as a slice of length `dim`.
    pub fn component(&self, k: usize) -> &[f32] {
        &self.components[k * self.dim()..(k + 1) * self.dim()]
    }

    /// Fraction of the training variance the kept components explain.
    pub fn variance_ratio(&self) -> f64 {
        self.variances.iter().map(|&v| v as f64).sum::<f64>() / self.total_variance
    }

    /// `b = P (x − mean)`.
    pub fn project(&self, x: &[f32]) -> Vec<f32> {
        assert_eq!(
            x.len(),
            self.dim(),
            "project: sample length differs from the model's"
        );
        (0..self.n_components())
            .into_par_iter()
            .map(|k| {
                // Eight independent partial sums: SIMD lanes instead of one dependency chain.
                let c = self.component(k);
                let mut acc = [0f64; 8];
                let chunks = x
                    .chunks_exact(8)
                    .zip(self.mean.chunks_exact(8))
                    .zip(c.chunks_exact(8));
                for ((xs, ms), cs) in chunks {
                    for i in 0..8 {
                        acc[i] += (xs[i] - ms[i]) as f64 * cs[i] as f64;
                    }
                }
                let done = x.len() / 8 * 8;
                let tail: f64 = (done..x.len())
                    .map(|i| (x[i] - self.mean[i]) as f64 * c[i] as f64)
                    .sum();
                (acc.iter().sum::<f64>() + tail) as f32
            })
            .collect()
    }

    /// The weighted least-squares projection `b = argmin Σ_i w_i (x_i − mean_i − (Pᵀ b)_i)²`,
    /// i.e. `(P W Pᵀ) b = P W (x − mean)`, factorised once for many samples: equal to
    /// [`Self::project`] for equal weights, and able to favour some values (the lips a viewer
    /// watches) over others when a sample lies off the model's span. `None` when the weights
    /// are not finite and non-negative, or leave `P W Pᵀ` singular.
    pub fn weighted(&self, weights: &[f64]) -> Option<WeightedProjection> {
        let (d, k) = (self.dim(), self.n_components());
        if weights.len() != d || weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) {
            return None;
        }
        let mut normal = DMatrix::<f64>::zeros(k, k);
        for a in 0..k {
            let ca = self.component(a);
            for b in a..k {
                let cb = self.component(b);
                let v: f64 = (0..d)
                    .map(|i| weights[i] * f64::from(ca[i]) * f64::from(cb[i]))
                    .sum();
                normal[(a, b)] = v;
                normal[(b, a)] = v;
            }
        }
        Some(WeightedProjection {
            weights: weights.to_vec(),
            normal: normal.cholesky()?,
        })
    }

    /// `x = mean + Pᵀ b`.
    pub fn reconstruct(&self, b: &[f32]) -> Vec<f32> {
        let mut out = vec![0f32; self.dim()];
        self.reconstruct_into(b, &mut out);
        out
    }

    /// `x = mean + Pᵀ b`, written into `out` (length `dim`).
    pub fn reconstruct_into(&self, b: &[f32], out: &mut [f32]) {
        assert_eq!(
            b.len(),
            self.n_components(),
            "reconstruct: parameter count differs from the model's"
        );
        assert_eq!(
            out.len(),
            self.dim(),
            "reconstruct: output length differs from the model's"
        );
        const CHUNK: usize = 4096;
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(ci, chunk)| {
                let start = ci * CHUNK;
                chunk.copy_from_slice(&self.mean[start..start + chunk.len()]);
                for (k, &bk) in b.iter().enumerate() {
                    let c = &self.component(k)[start..start + chunk.len()];
                    chunk.iter_mut().zip(c).for_each(|(o, &ck)| *o += bk * ck);
                }
            });
    }
}

fn check_samples(samples: &[&[f32]]) -> Result<usize, PcaError> {
    if samples.len() < 2 {
        return Err(PcaError::TooFewSamples(samples.len()));
    }
    let d = samples[0].len();
    for (index, s) in samples.iter().enumerate() {
        if s.len() != d {
            return Err(PcaError::Ragged {
                index,
                expected: d,
                found: s.len(),
            });
        }
        if let Some(position) = s.iter().position(|x| !x.is_finite()) {
            return Err(PcaError::NotFinite { index, position });
        }
    }
    Ok(d)
}

/// Eigen-decomposition of a symmetric matrix, eigenvalues descending (negatives from
/// round-off clamped to 0), eigenvectors as the matching columns.
fn sorted_eigen(m: DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let eig = SymmetricEigen::new(m);
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let values = order.iter().map(|&i| eig.eigenvalues[i].max(0.0)).collect();
    let vectors = DMatrix::from_fn(eig.eigenvectors.nrows(), order.len(), |r, c| {
        eig.eigenvectors[(r, order[c])]
    });
    (values, vectors)
}

/// The first `kept` unit eigenvectors, rows of a kept × d matrix.
type KeptVectors<'a> = dyn Fn(usize) -> Vec<f64> + 'a;

/// Columns per block of the snapshot method's products: a block of every sample in f64
/// stays small (n × 2048 × 8 bytes) however long the samples are.
const BLOCK: usize = 2048;

/// The centred samples' columns `[c0, c1)` as an n × (c1 − c0) f64 matrix.
fn centred_block(samples: &[&[f32]], mean: &[f32], c0: usize, c1: usize) -> Array2<f64> {
    Array2::from_shape_fn((samples.len(), c1 - c0), |(i, j)| {
        f64::from(samples[i][c0 + j]) - f64::from(mean[c0 + j])
    })
}

/// The Gram matrix `G = X Xᵀ` of the centred samples (n × n), accumulated over column blocks
/// by matrix products (in parallel), without ever holding the centred data whole. The blocks
/// are summed in a fixed number of contiguous groups and the groups in order, so the sum — and
/// the model built from it — is the same bit for bit on any number of threads.
fn gram(samples: &[&[f32]], mean: &[f32]) -> DMatrix<f64> {
    const PARTS: usize = 16;
    let (n, d) = (samples.len(), mean.len());
    let blocks = d.div_ceil(BLOCK);
    let group = blocks.div_ceil(PARTS).max(1);
    let groups: Vec<Array2<f64>> = (0..blocks.div_ceil(group))
        .into_par_iter()
        .map(|part| {
            let mut g = Array2::<f64>::zeros((n, n));
            for b in part * group..((part + 1) * group).min(blocks) {
                let x = centred_block(samples, mean, b * BLOCK, ((b + 1) * BLOCK).min(d));
                general_mat_mul(1.0, &x, &x.t(), 1.0, &mut g);
            }
            g
        })
        .collect();
    let mut g = Array2::<f64>::zeros((n, n));
    groups.iter().for_each(|part| g += part);
    // Exactly symmetric, as the eigensolver assumes.
    DMatrix::from_fn(n, n, |i, j| 0.5 * (g[(i, j)] + g[(j, i)]))
}

/// The first `kept` principal directions from the Gram matrix's eigenvectors `u`:
/// `v_k ∝ Xᵀ u_k` (Sirovich's snapshot method), unit length, rows of a kept × d matrix.
fn snapshot_vectors(samples: &[&[f32]], mean: &[f32], u: &DMatrix<f64>, kept: usize) -> Vec<f64> {
    let (n, d) = (samples.len(), mean.len());
    let uk = Array2::from_shape_fn((kept, n), |(k, i)| u[(i, k)]);
    let blocks: Vec<Array2<f64>> = (0..d.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let x = centred_block(samples, mean, b * BLOCK, ((b + 1) * BLOCK).min(d));
            uk.dot(&x)
        })
        .collect();
    let mut v = vec![0f64; kept * d];
    for (b, block) in blocks.iter().enumerate() {
        for k in 0..kept {
            let row = &mut v[k * d + b * BLOCK..k * d + b * BLOCK + block.ncols()];
            row.iter_mut().zip(block.row(k)).for_each(|(o, &x)| *o = x);
        }
    }
    if d > 0 {
        v.chunks_exact_mut(d).for_each(normalise);
    }
    v
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn normalise(v: &mut [f64]) {
    let norm = dot(v, v).sqrt();
    if norm > 0.0 {
        v.iter_mut().for_each(|x| *x /= norm);
    }
}

/// A weighted least-squares projection onto a [`PcaModel`] ([`PcaModel::weighted`]).
pub struct WeightedProjection {
    weights: Vec<f64>,
    normal: nalgebra::Cholesky<f64, nalgebra::Dyn>,
}

impl WeightedProjection {
    /// `b` for the sample `x` (length `dim` of `pca`, the model it was made from).
    pub fn project(&self, pca: &PcaModel, x: &[f32]) -> Vec<f32> {
        let rhs = nalgebra::DVector::<f64>::from_iterator(
            pca.n_components(),
            (0..pca.n_components()).map(|k| {
                let c = pca.component(k);
                (0..x.len())
                    .map(|i| self.weights[i] * f64::from(x[i] - pca.mean[i]) * f64::from(c[i]))
                    .sum()
            }),
        );
        self.normal.solve(&rhs).iter().map(|&v| v as f32).collect()
    }
}
