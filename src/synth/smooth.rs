//! Cubic smoothing spline (Reinsch 1967; Green & Silverman 1994 §2.3): the natural cubic
//! spline `f` minimising `Σ wᵢ (yᵢ − f(xᵢ))² + λ ∫ f''(u)² du` — the criterion of scipy's
//! `make_smoothing_spline`. λ → 0 interpolates; λ → ∞ gives the weighted least-squares line.
//!
//! With `h_i = x_{i+1} − x_i`, the tridiagonal `Q` (n × n−2) and `R` (n−2 × n−2) of Green &
//! Silverman, the second derivatives `γ` at the interior knots solve
//! `(R + λ Qᵀ W⁻¹ Q) γ = Qᵀ y` (symmetric, pentadiagonal: banded Cholesky, O(n)), and the
//! fitted values are `g = y − λ W⁻¹ Q γ`. The factorisation depends only on x, w and λ, so one
//! [`SmoothingSpline`] smooths every dimension of a trajectory.

use thiserror::Error;

/// What can be wrong with a smoothing problem.
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum SmoothError {
    /// Fewer than three knots.
    #[error("a smoothing spline needs at least 3 points, got {0}")]
    TooFewPoints(usize),
    /// Knots out of order (the index of the first offender).
    #[error("knots must increase strictly: x[{0}] does not exceed the knot before it")]
    NotIncreasing(usize),
    /// λ negative or not finite.
    #[error("smoothing weight λ = {0} must be finite and ≥ 0")]
    BadLambda(f64),
    /// A weight not positive and finite (its index).
    #[error("weights must be finite and > 0 (weight {0})")]
    BadWeight(usize),
    /// Values or weights of another length than the knots.
    #[error("{found} values given for {expected} knots")]
    Length {
        /// Knots.
        expected: usize,
        /// Values given.
        found: usize,
    },
}

/// A factorised smoothing problem for fixed knots, weights and λ.
#[derive(Clone, Debug)]
pub struct SmoothingSpline {
    x: Vec<f64>,
    w: Vec<f64>,
    lambda: f64,
    /// Banded Cholesky factor of `R + λ QᵀW⁻¹Q`: diagonal and the two sub-diagonals.
    l0: Vec<f64>,
    l1: Vec<f64>,
    l2: Vec<f64>,
}

impl SmoothingSpline {
    /// Factorises the problem for knots `x`, weights `w` (default 1) and weight `lambda`.
    pub fn new(x: &[f64], w: Option<&[f64]>, lambda: f64) -> Result<Self, SmoothError> {
        let n = x.len();
        if n < 3 {
            return Err(SmoothError::TooFewPoints(n));
        }
        if let Some(i) = (1..n).find(|&i| x[i] <= x[i - 1] || x[i].is_nan()) {
            return Err(SmoothError::NotIncreasing(i));
        }
        if !(lambda >= 0.0 && lambda.is_finite()) {
            return Err(SmoothError::BadLambda(lambda));
        }
        let w = match w {
            Some(w) if w.len() != n => {
                return Err(SmoothError::Length {
                    expected: n,
                    found: w.len(),
                });
            }
            Some(w) => {
                if let Some(i) = w.iter().position(|v| !(*v > 0.0 && v.is_finite())) {
                    return Err(SmoothError::BadWeight(i));
                }
                w.to_vec()
            }
            None => vec![1.0; n],
        };
        let h: Vec<f64> = x.windows(2).map(|p| p[1] - p[0]).collect();
        let m = n - 2;
        // Q's column j (interior knot j+1) has entries at rows j, j+1, j+2.
        let q = |j: usize| [1.0 / h[j], -1.0 / h[j] - 1.0 / h[j + 1], 1.0 / h[j + 1]];
        // A = R + λ QᵀW⁻¹Q as three bands: a0 (diagonal), a1 (first off), a2 (second off).
        let mut a0 = vec![0.0; m];
        let mut a1 = vec![0.0; m];
        let mut a2 = vec![0.0; m];
        for j in 0..m {
            let qj = q(j);
            a0[j] = (h[j] + h[j + 1]) / 3.0
                + lambda * (0..3).map(|r| qj[r] * qj[r] / w[j + r]).sum::<f64>();
            if j + 1 < m {
                let qk = q(j + 1);
                // Rows shared by columns j and j+1: j+1 and j+2.
                a1[j + 1] =
                    h[j + 1] / 6.0 + lambda * (qj[1] * qk[0] / w[j + 1] + qj[2] * qk[1] / w[j + 2]);
            }
            if j + 2 < m {
                let qk = q(j + 2);
                a2[j + 2] = lambda * qj[2] * qk[0] / w[j + 2];
            }
        }
        // Banded Cholesky: A = L Lᵀ with L lower-triangular of bandwidth 2.
        let (mut l0, mut l1, mut l2) = (vec![0.0; m], vec![0.0; m], vec![0.0; m]);
        for i in 0..m {
            if i >= 2 {
                l2[i] = a2[i] / l0[i - 2];
            }
            if i >= 1 {
                let t = if i >= 2 { l2[i] * l1[i - 1] } else { 0.0 };
                l1[i] = (a1[i] - t) / l0[i - 1];
            }
            let d = a0[i] - l1[i] * l1[i] - l2[i] * l2[i];
            l0[i] = d.max(f64::MIN_POSITIVE).sqrt();
        }
        Ok(SmoothingSpline {
            x: x.to_vec(),
            w,
            lambda,
            l0,
            l1,
            l2,
        })
    }

    /// Fitted values at the knots.
    pub fn smooth(&self, y: &[f64]) -> Result<Vec<f64>, SmoothError> {
        let n = self.x.len();
        if y.len() != n {
            return Err(SmoothError::Length {
                expected: n,
                found: y.len(),
            });
        }
        let (x, m) = (&self.x, n - 2);
        let h: Vec<f64> = x.windows(2).map(|p| p[1] - p[0]).collect();
        // Qᵀy.
        let mut b: Vec<f64> = (0..m)
            .map(|j| (y[j + 2] - y[j + 1]) / h[j + 1] - (y[j + 1] - y[j]) / h[j])
            .collect();
        // Forward (L z = b) and back (Lᵀ γ = z) substitution.
        for i in 0..m {
            let mut v = b[i];
            if i >= 1 {
                v -= self.l1[i] * b[i - 1];
            }
            if i >= 2 {
                v -= self.l2[i] * b[i - 2];
            }
            b[i] = v / self.l0[i];
        }
        for i in (0..m).rev() {
            let mut v = b[i];
            if i + 1 < m {
                v -= self.l1[i + 1] * b[i + 1];
            }
            if i + 2 < m {
                v -= self.l2[i + 2] * b[i + 2];
            }
            b[i] = v / self.l0[i];
        }
        let gamma = b;
        // g = y − λ W⁻¹ Q γ.
        let mut g = y.to_vec();
        for (j, gj) in gamma.iter().enumerate() {
            let q = [1.0 / h[j], -1.0 / h[j] - 1.0 / h[j + 1], 1.0 / h[j + 1]];
            for r in 0..3 {
                g[j + r] -= self.lambda * q[r] * gj / self.w[j + r];
            }
        }
        Ok(g)
    }

    /// Smooths every dimension of a `rows × dims` row-major matrix sampled at the knots.
    pub fn smooth_rows(&self, values: &mut [f64], dims: usize) -> Result<(), SmoothError> {
        let n = self.x.len();
        if values.len() != n * dims {
            return Err(SmoothError::Length {
                expected: n * dims,
                found: values.len(),
            });
        }
        let mut column = vec![0.0; n];
        for k in 0..dims {
            for i in 0..n {
                column[i] = values[i * dims + k];
            }
            let g = self.smooth(&column)?;
            for i in 0..n {
                values[i * dims + k] = g[i];
            }
        }
        Ok(())
    }
}
