//! Continuous face-space trajectories (\[blend\] §4, DESIGN §5): monotone piecewise cubic
//! Hermite interpolation (PCHIP; Fritsch & Carlson 1980, the tangents of scipy's
//! `PchipInterpolator`) through every per-frame sample, per dimension. It never overshoots
//! the data — a natural cubic spline could open the mouth wider than was ever recorded.

use thiserror::Error;

use crate::facespace::Frames;

/// What can be wrong with a trajectory or a segment of one.
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum TrajectoryError {
    /// No samples.
    #[error("a trajectory needs at least one sample")]
    Empty,
    /// Values that do not fill the samples.
    #[error("{values} values do not form {samples} samples of {dims} dimensions")]
    Shape {
        /// Samples (times).
        samples: usize,
        /// Dimensions.
        dims: usize,
        /// Values given.
        values: usize,
    },
    /// Times out of order.
    #[error("sample times must increase strictly: t[{index}] = {time} follows {previous}")]
    NotIncreasing {
        /// The sample.
        index: usize,
        /// Its time.
        time: f64,
        /// The time before it.
        previous: f64,
    },
    /// A NaN or infinity.
    #[error("sample {index} holds a non-finite value")]
    NotFinite {
        /// The sample.
        index: usize,
    },
    /// An empty or reversed segment.
    #[error("segment {start}–{end} s is empty or reversed")]
    BadSegment {
        /// Start, seconds.
        start: f64,
        /// End, seconds.
        end: f64,
    },
    /// A duration that is not positive and finite.
    #[error("target duration {0} s must be positive and finite")]
    BadDuration(f64),
}

/// Samples `values` (`times.len() × dims`, row-major) at `times`, with PCHIP tangents
/// (computed when the trajectory is first evaluated: a loaded codebook's sentences are
/// mostly never evaluated, and computing every tangent was most of its load).
#[derive(Clone, Debug)]
pub struct Trajectory {
    /// Sample times, strictly increasing.
    pub times: Vec<f64>,
    /// Values per sample.
    pub dims: usize,
    /// `times.len() × dims` values, row-major.
    pub values: Vec<f64>,
    slopes: std::sync::OnceLock<Vec<f64>>,
}

impl PartialEq for Trajectory {
    /// The samples decide (the tangents follow from them).
    fn eq(&self, other: &Self) -> bool {
        self.times == other.times && self.dims == other.dims && self.values == other.values
    }
}

impl Trajectory {
    /// A trajectory through `values` at `times`, PCHIP tangents computed per dimension.
    pub fn new(times: Vec<f64>, values: Vec<f64>, dims: usize) -> Result<Self, TrajectoryError> {
        let n = times.len();
        if n == 0 || dims == 0 {
            return Err(TrajectoryError::Empty);
        }
        if values.len() != n * dims {
            return Err(TrajectoryError::Shape {
                samples: n,
                dims,
                values: values.len(),
            });
        }
        if let Some(index) = (0..n).find(|&i| {
            !times[i].is_finite()
                || values[i * dims..(i + 1) * dims]
                    .iter()
                    .any(|v| !v.is_finite())
        }) {
            return Err(TrajectoryError::NotFinite { index });
        }
        if let Some(i) = (1..n).find(|&i| times[i] <= times[i - 1]) {
            return Err(TrajectoryError::NotIncreasing {
                index: i,
                time: times[i],
                previous: times[i - 1],
            });
        }
        Ok(Trajectory {
            times,
            dims,
            values,
            slopes: std::sync::OnceLock::new(),
        })
    }

    /// A face-space sequence, sample `i` at `i / fps` (every column, pose included).
    pub fn from_frames(frames: &Frames) -> Result<Self, TrajectoryError> {
        let values = frames.as_slice().iter().map(|&v| f64::from(v)).collect();
        Self::new(frames.times(), values, frames.layout().dims())
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether there are no samples (never, once built).
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The first sample's time.
    pub fn start(&self) -> f64 {
        self.times[0]
    }

    /// The last sample's time.
    pub fn end(&self) -> f64 {
        self.times[self.len() - 1]
    }

    /// Value at `t` (held constant outside the sampled range).
    pub fn eval(&self, t: f64) -> Vec<f64> {
        let mut out = vec![0.0; self.dims];
        self.eval_into(t, &mut out);
        out
    }

    /// [`Trajectory::eval`] into `out` (`dims` long).
    pub fn eval_into(&self, t: f64, out: &mut [f64]) {
        let n = self.len();
        let dims = self.dims;
        if n == 1 || t <= self.times[0] {
            out.copy_from_slice(&self.values[..dims]);
            return;
        }
        if t >= self.times[n - 1] {
            out.copy_from_slice(&self.values[(n - 1) * dims..]);
            return;
        }
        // The interval [times[i], times[i+1]) holding t.
        let i = self.times.partition_point(|&x| x <= t) - 1;
        let h = self.times[i + 1] - self.times[i];
        let s = (t - self.times[i]) / h;
        let (s2, s3) = (s * s, s * s * s);
        let (h00, h10, h01, h11) = (
            2.0 * s3 - 3.0 * s2 + 1.0,
            s3 - 2.0 * s2 + s,
            -2.0 * s3 + 3.0 * s2,
            s3 - s2,
        );
        let (a, b) = (i * dims, (i + 1) * dims);
        let slopes = self
            .slopes
            .get_or_init(|| pchip_slopes_rows(&self.times, &self.values, dims));
        for (k, o) in out.iter_mut().enumerate() {
            *o = h00 * self.values[a + k]
                + h10 * h * slopes[a + k]
                + h01 * self.values[b + k]
                + h11 * h * slopes[b + k];
        }
    }

    /// Values at each of `times` (`times.len() × dims`).
    pub fn sample(&self, times: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; times.len() * self.dims];
        for (t, row) in times.iter().zip(out.chunks_exact_mut(self.dims)) {
            self.eval_into(*t, row);
        }
        out
    }

    /// Values at `fps` from `start()` to `end()` inclusive of every whole frame.
    pub fn resample(&self, fps: f64) -> Vec<f64> {
        self.sample(
            &frame_times(self.end() - self.start(), fps)
                .iter()
                .map(|t| t + self.start())
                .collect::<Vec<_>>(),
        )
    }

    /// The segment `[start, end]` linearly time-warped to last `duration`: the returned
    /// map evaluates `self` at `start + (t / duration)(end − start)` for `t ∈ [0, duration]`.
    pub fn warp(
        &self,
        start: f64,
        end: f64,
        duration: f64,
    ) -> Result<TimeWarp<'_>, TrajectoryError> {
        if end <= start || !start.is_finite() || !end.is_finite() {
            return Err(TrajectoryError::BadSegment { start, end });
        }
        if !(duration > 0.0 && duration.is_finite()) {
            return Err(TrajectoryError::BadDuration(duration));
        }
        Ok(TimeWarp {
            trajectory: self,
            start,
            rate: (end - start) / duration,
        })
    }
}

/// A segment of a trajectory on a linearly rescaled clock (see [`Trajectory::warp`]).
#[derive(Clone, Copy, Debug)]
pub struct TimeWarp<'a> {
    trajectory: &'a Trajectory,
    start: f64,
    rate: f64,
}

impl TimeWarp<'_> {
    /// The value at warped time `t` into `out`.
    pub fn eval_into(&self, t: f64, out: &mut [f64]) {
        self.trajectory.eval_into(self.start + t * self.rate, out);
    }

    /// Values at each of the warped `times`.
    pub fn sample(&self, times: &[f64]) -> Vec<f64> {
        self.trajectory.sample(
            &times
                .iter()
                .map(|t| self.start + t * self.rate)
                .collect::<Vec<_>>(),
        )
    }
}

/// Frame times `0, 1/fps, …` up to `duration` (inclusive within 1e-9 s).
pub fn frame_times(duration: f64, fps: f64) -> Vec<f64> {
    let n = (duration * fps + 1e-9).floor() as usize + 1;
    (0..n).map(|i| i as f64 / fps).collect()
}

/// PCHIP derivatives at the knots, as scipy's `PchipInterpolator`: weighted harmonic mean
/// of the neighbouring secants where they agree in sign, 0 at extrema and flats, and the
/// one-sided three-point end condition limited to keep monotonicity.
pub fn pchip_slopes(x: &[f64], y: &[f64], d: &mut [f64]) {
    let n = x.len();
    if n == 1 {
        d[0] = 0.0;
        return;
    }
    let h = |i: usize| x[i + 1] - x[i];
    let m = |i: usize| (y[i + 1] - y[i]) / h(i);
    if n == 2 {
        d[0] = m(0);
        d[1] = m(0);
        return;
    }
    for (i, di) in d.iter_mut().enumerate().take(n - 1).skip(1) {
        let (m0, m1) = (m(i - 1), m(i));
        *di = if m0 == 0.0 || m1 == 0.0 || sign(m0) != sign(m1) {
            0.0
        } else {
            let (w1, w2) = (2.0 * h(i) + h(i - 1), h(i) + 2.0 * h(i - 1));
            (w1 + w2) / (w1 / m0 + w2 / m1)
        };
    }
    d[0] = edge_slope(h(0), h(1), m(0), m(1));
    d[n - 1] = edge_slope(h(n - 2), h(n - 3), m(n - 2), m(n - 3));
}

/// [`pchip_slopes`] of every column of the row-major `values` (`x.len()` × `dims`) at once,
/// the same numbers: each secant computed once and the rows walked in memory order (a
/// codebook's load is mostly this).
pub fn pchip_slopes_rows(x: &[f64], values: &[f64], dims: usize) -> Vec<f64> {
    let n = x.len();
    let mut d = vec![0.0; n * dims];
    if n < 2 {
        return d;
    }
    let h: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    let mut m = vec![0.0; (n - 1) * dims];
    for i in 0..n - 1 {
        let (row, next) = (&values[i * dims..(i + 1) * dims], &values[(i + 1) * dims..(i + 2) * dims]);
        for ((mk, a), b) in m[i * dims..(i + 1) * dims].iter_mut().zip(row).zip(next) {
            *mk = (b - a) / h[i];
        }
    }
    if n == 2 {
        d[..dims].copy_from_slice(&m[..dims]);
        d[dims..].copy_from_slice(&m[..dims]);
        return d;
    }
    for i in 1..n - 1 {
        let (w1, w2) = (2.0 * h[i] + h[i - 1], h[i] + 2.0 * h[i - 1]);
        for k in 0..dims {
            let (m0, m1) = (m[(i - 1) * dims + k], m[i * dims + k]);
            d[i * dims + k] = if m0 == 0.0 || m1 == 0.0 || sign(m0) != sign(m1) {
                0.0
            } else {
                (w1 + w2) / (w1 / m0 + w2 / m1)
            };
        }
    }
    for k in 0..dims {
        let m_at = |i: usize| m[i * dims + k];
        d[k] = edge_slope(h[0], h[1], m_at(0), m_at(1));
        d[(n - 1) * dims + k] = edge_slope(h[n - 2], h[n - 3], m_at(n - 2), m_at(n - 3));
    }
    d
}

/// −1, 0 or 1 (`f64::signum` gives 1 for +0, which would change the end condition).
fn sign(x: f64) -> i8 {
    (x > 0.0) as i8 - (x < 0.0) as i8
}

fn edge_slope(h0: f64, h1: f64, m0: f64, m1: f64) -> f64 {
    let d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1);
    if sign(d) != sign(m0) {
        0.0
    } else if sign(m0) != sign(m1) && d.abs() > 3.0 * m0.abs() {
        3.0 * m0
    } else {
        d
    }
}
