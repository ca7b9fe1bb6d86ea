//! The map's hidden layer: rectified units beside the ridge, learnt on what the ridge leaves
//! (its residuals), so that the map can bend where a linear one cannot — e.g. the lips close
//! at /p b m/ whatever the vowel around. Trained by Adam (Kingma & Ba 2015, Algorithm 1, its
//! default β₁ 0.9, β₂ 0.999, ε 1e-8) over minibatches of standardised inputs, each input
//! dropped out with probability [`DROPOUT`] (Srivastava et al. 2014, inverted scaling), with
//! L2 weight decay. The inputs' standardisation and the outputs' scale are folded into the
//! stored weights: `face += relu([x, 1]·input)·output`.

use nalgebra::DMatrix;

use crate::rng::Rng;

/// Rectified units (GRID s1 validation, inner r_h of the map alone: 256 units 0.872, 512
/// 0.873, the ridge alone 0.843).
pub const UNITS: usize = 256;
/// Passes over the examples (validation: still rising slowly at 12).
pub const EPOCHS: usize = 12;
/// The learning rate halves after each pass from this one on.
const ANNEAL_FROM: usize = 8;
const BATCH: usize = 256;
const LEARNING_RATE: f32 = 1e-3;
/// Validation: 0 overfitted after 4 passes (r_h 0.865 at best), 0.3 went on to 0.872.
pub const DROPOUT: f32 = 0.3;
const WEIGHT_DECAY: f32 = 1e-4;
const SEED: u64 = 34;

/// Rows under which [`Hidden::add_to`] multiplies vectors: a matrix product packs both
/// matrices first (2 MB of the layer's input weights), which a live batch of a frame or two
/// paid for every batch (the live session at 9× real time instead of 13×).
const FEW_ROWS: usize = 8;

/// The learnt layer, standardisation and scales folded in.
#[derive(Clone, Debug)]
pub struct Hidden {
    /// (features + constant) × units.
    pub input: DMatrix<f32>,
    /// Units × outputs.
    pub output: DMatrix<f32>,
}

impl Hidden {
    /// Adds the layer's output for the design rows `x` (features and the constant) to `face`.
    pub fn add_to(&self, x: &DMatrix<f32>, face: &mut DMatrix<f32>) {
        if x.nrows() >= FEW_ROWS {
            let mut a = x * &self.input;
            a.apply(|v| *v = v.max(0.0));
            face.gemm(1.0, &a, &self.output, 1.0);
            return;
        }
        // A live batch's frame or two: products of vectors, without packing the matrices.
        for i in 0..x.nrows() {
            let mut a = self.input.tr_mul(&x.row(i).transpose());
            a.apply(|v| *v = v.max(0.0));
            let out = self.output.tr_mul(&a);
            for (c, v) in out.iter().enumerate() {
                face[(i, c)] += v;
            }
        }
    }
}

/// What the layer learns from: `rows` examples of `features` inputs, each written on demand
/// by `row` (the design without its constant), standardised by `mean` and `scale`, and what
/// it learns to give.
pub struct Examples<'a, F> {
    pub rows: usize,
    pub features: usize,
    pub row: F,
    pub mean: &'a [f32],
    pub scale: &'a [f32],
    pub target: Target<'a>,
}

/// What the layer's outputs learn.
pub enum Target<'a> {
    /// Values: `residual`'s rows by squared error, each output divided by `scale` while
    /// learning (the map's hidden layer).
    Values {
        residual: &'a DMatrix<f32>,
        scale: &'a [f32],
    },
    /// A class per row, `None` for a row not to learn from: the outputs are log-odds
    /// learnt by softmax cross-entropy (a phone classifier).
    Classes {
        labels: &'a [Option<u8>],
        classes: usize,
    },
}

/// The layer's size and how long it learns.
#[derive(Clone, Copy, Debug)]
pub struct Schedule {
    pub units: usize,
    pub epochs: usize,
    /// The learning rate halves after each pass from this one on.
    pub anneal_from: usize,
}

/// The sound-to-face map's layer.
pub const MAP: Schedule = Schedule {
    units: UNITS,
    epochs: EPOCHS,
    anneal_from: ANNEAL_FROM,
};

/// Adam's moments of one parameter array.
struct Adam {
    m: Vec<f32>,
    v: Vec<f32>,
}

impl Adam {
    fn new(n: usize) -> Self {
        Adam {
            m: vec![0.0; n],
            v: vec![0.0; n],
        }
    }

    /// One step of Algorithm 1 on `p` with gradient `g` (plus `decay`·p), step count `t`.
    fn step(&mut self, p: &mut [f32], g: &[f32], decay: f32, rate: f32, t: i32) {
        let (c1, c2) = (1.0 - 0.9f32.powi(t), 1.0 - 0.999f32.powi(t));
        for (((p, &g), m), v) in p.iter_mut().zip(g).zip(&mut self.m).zip(&mut self.v) {
            let g = g + decay * *p;
            *m = 0.9 * *m + 0.1 * g;
            *v = 0.999 * *v + 0.001 * g * g;
            *p -= rate * (*m / c1) / ((*v / c2).sqrt() + 1e-8);
        }
    }
}

/// `aᵀ b`, where `a` is the column-major data of a `rows`-row matrix: one blocked product that
/// reads the transpose through its strides. nalgebra's `tr_mul` takes a dot product per
/// element, and its own products of views with a row stride read out of bounds where a side
/// is under six (its fallback loop).
fn tr_product(a: &[f32], rows: usize, b: &DMatrix<f32>) -> DMatrix<f32> {
    assert_eq!(b.nrows(), rows, "tr_product: mismatched shapes");
    let m = a.len().checked_div(rows).unwrap_or(0);
    assert_eq!(a.len(), rows * m, "tr_product: mismatched shapes");
    let n = b.ncols();
    let mut c = DMatrix::<f32>::zeros(m, n);
    if m > 0 && n > 0 && rows > 0 {
        // SAFETY: `a` holds m columns of `rows` (read as m × rows: row stride `rows`), `b` is
        // rows × n and `c` m × n, both column-major; the shapes are checked above.
        unsafe {
            matrixmultiply::sgemm(
                m,
                rows,
                n,
                1.0,
                a.as_ptr(),
                rows as isize,
                1,
                b.as_ptr(),
                1,
                rows as isize,
                0.0,
                c.as_mut_ptr(),
                1,
                m as isize,
            );
        }
    }
    c
}

/// Adds the row vector `b` to every row of `z`.
fn add_row(z: &mut DMatrix<f32>, b: &DMatrix<f32>) {
    for (mut column, &b) in z.column_iter_mut().zip(b.iter()) {
        column.add_scalar_mut(b);
    }
}

/// Learns the layer on `examples` (module docs), and the bias of its outputs (to add to the
/// ridge's constant); `progress` is told each pass done.
pub fn learn<F: Fn(usize, &mut [f32])>(
    examples: &Examples<'_, F>,
    schedule: Schedule,
    mut progress: impl FnMut(usize),
) -> (Hidden, Vec<f32>) {
    let (n, d) = (examples.rows, examples.features);
    let k = match examples.target {
        Target::Values { residual, .. } => residual.ncols(),
        Target::Classes { classes, .. } => classes,
    };
    let units = schedule.units;
    // Rows without a class teach nothing.
    let taught: Vec<usize> = match examples.target {
        Target::Classes { labels, .. } => (0..n).filter(|&i| labels[i].is_some()).collect(),
        Target::Values { .. } => (0..n).collect(),
    };
    // A feature constant over the examples is left out: it would be scaled without bound.
    let inverse: Vec<f32> = examples
        .scale
        .iter()
        .map(|&s| if s > 1e-6 { 1.0 / s } else { 0.0 })
        .collect();
    let mut rng = Rng::new(SEED);
    let spread = (2.0 / d as f64).sqrt();
    let mut w1 = DMatrix::from_fn(d, units, |_, _| (rng.normal() * spread) as f32);
    let mut b1 = DMatrix::<f32>::zeros(1, units);
    let mut w2 = DMatrix::<f32>::zeros(units, k);
    let mut b2 = DMatrix::<f32>::zeros(1, k);
    let mut adam = [
        Adam::new(d * units),
        Adam::new(units),
        Adam::new(units * k),
        Adam::new(k),
    ];
    let mut order = taught;
    let n = order.len();
    let mut rate = LEARNING_RATE;
    let mut t = 0;
    let keep = 1.0 / (1.0 - DROPOUT);
    // An input is dropped when `rng.uniform() < DROPOUT`, i.e. when its 53 bits fall below
    // this (exact: both sides are scaled by 2⁵³), compared as integers.
    let drop_below = (f64::from(DROPOUT) * (1u64 << 53) as f64).ceil() as u64;
    // Rows of the batch laid out contiguously: xᵀ, features × batch.
    let mut xt = DMatrix::<f32>::zeros(d, BATCH);
    for epoch in 0..schedule.epochs {
        // Fisher–Yates.
        for i in (1..n).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            order.swap(i, j);
        }
        for batch in order.chunks(BATCH) {
            let b = batch.len();
            let mut target = DMatrix::<f32>::zeros(b, k);
            for (r, &i) in batch.iter().enumerate() {
                let column = xt.column_mut(r);
                let row = column.data.into_slice_mut();
                (examples.row)(i, row);
                for (j, v) in row.iter_mut().enumerate() {
                    let dropped = rng.next_u64() >> 11 < drop_below;
                    *v = if dropped {
                        0.0
                    } else {
                        (*v - examples.mean[j]) * inverse[j] * keep
                    };
                }
                match examples.target {
                    Target::Values { residual, scale } => {
                        for c in 0..k {
                            target[(r, c)] = residual[(i, c)] / scale[c];
                        }
                    }
                    Target::Classes { labels, .. } => {
                        if let Some(c) = labels[i] {
                            target[(r, usize::from(c))] = 1.0;
                        }
                    }
                }
            }
            // The batch's rows as xᵀ's columns, read without a transposed copy.
            let mut z = tr_product(&xt.as_slice()[..d * b], d, &w1);
            let xt = xt.columns(0, b);
            add_row(&mut z, &b1);
            let h = z.map(|v| v.max(0.0));
            let mut out = &h * &w2;
            add_row(&mut out, &b2);
            let g = match examples.target {
                // The mean squared error's gradient.
                Target::Values { .. } => (out - target) * (2.0 / b as f32),
                // Softmax cross-entropy's: the probabilities less the one-hot classes.
                Target::Classes { .. } => (softmax_rows(out) - target) * (1.0 / b as f32),
            };
            let gw2 = tr_product(h.as_slice(), b, &g);
            let gb2 = g.row_sum();
            let mut gh = &g * w2.transpose();
            gh.zip_apply(&z, |gh, z| {
                if z <= 0.0 {
                    *gh = 0.0;
                }
            });
            let gw1 = xt * &gh;
            let gb1 = gh.row_sum();
            t += 1;
            adam[0].step(w1.as_mut_slice(), gw1.as_slice(), WEIGHT_DECAY, rate, t);
            adam[1].step(b1.as_mut_slice(), gb1.as_slice(), 0.0, rate, t);
            adam[2].step(w2.as_mut_slice(), gw2.as_slice(), WEIGHT_DECAY, rate, t);
            adam[3].step(b2.as_mut_slice(), gb2.as_slice(), 0.0, rate, t);
        }
        if epoch + 1 >= schedule.anneal_from {
            rate *= 0.5;
        }
        progress(epoch + 1);
    }
    let ones = vec![1.0; k];
    let target_scale = match examples.target {
        Target::Values { scale, .. } => scale,
        Target::Classes { .. } => &ones,
    };
    fold((&w1, &b1), (&w2, &b2), examples.mean, &inverse, target_scale)
}

/// Each row of log-odds as probabilities (shifted by its largest first, so none overflows).
pub fn softmax_rows(mut z: DMatrix<f32>) -> DMatrix<f32> {
    for mut row in z.row_iter_mut() {
        let top = row.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        row.apply(|v| *v = (*v - top).exp());
        let sum = row.sum();
        row.apply(|v| *v /= sum);
    }
    z
}

/// The layer on raw inputs, `relu(((x − mean)·inverse)·w1 + b1)·w2 + b2` with each output
/// times its target scale, as `relu([x, 1]·input)·output` plus the returned bias (which the
/// caller adds to the ridge's constant).
fn fold(
    (w1, b1): (&DMatrix<f32>, &DMatrix<f32>),
    (w2, b2): (&DMatrix<f32>, &DMatrix<f32>),
    mean: &[f32],
    inverse: &[f32],
    target_scale: &[f32],
) -> (Hidden, Vec<f32>) {
    let (d, units) = w1.shape();
    let mut input = DMatrix::<f32>::zeros(d + 1, units);
    for u in 0..units {
        let mut bias = b1[u];
        for j in 0..d {
            let w = w1[(j, u)] * inverse[j];
            input[(j, u)] = w;
            bias -= mean[j] * w;
        }
        input[(d, u)] = bias;
    }
    let output = DMatrix::from_fn(units, w2.ncols(), |u, c| w2[(u, c)] * target_scale[c]);
    let bias = b2.iter().zip(target_scale).map(|(b, s)| b * s).collect();
    (Hidden { input, output }, bias)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Analytic: Adam's first step moves every parameter by the rate against its gradient's
    /// sign (m̂ = g, v̂ = g², so the step is rate·g / (|g| + ε)), decay added to the gradient.
    #[test]
    fn adams_first_step_is_the_rate_against_the_gradients_sign() {
        let mut adam = Adam::new(3);
        let mut p = [1.0f32, -2.0, 0.5];
        adam.step(&mut p, &[0.3, -4.0, 0.0], 0.0, 0.01, 1);
        assert!((p[0] - 0.99).abs() < 1e-6 && (p[1] + 1.99).abs() < 1e-6, "{p:?}");
        assert_eq!(p[2], 0.5);
        let mut p = [2.0f32];
        Adam::new(1).step(&mut p, &[0.0], 0.5, 0.01, 1);
        assert!((p[0] - 1.99).abs() < 1e-6, "decay acts as a gradient: {p:?}");
    }

    /// The folded layer on raw inputs equals the layer on standardised ones, computed here
    /// directly from its definition.
    #[test]
    fn folding_keeps_the_layer_on_raw_inputs() {
        let mut rng = Rng::new(3);
        let (d, units, k) = (5, 7, 3);
        let mut r = |rows, cols| DMatrix::from_fn(rows, cols, |_, _| rng.normal() as f32);
        let (w1, b1, w2, b2) = (r(d, units), r(1, units), r(units, k), r(1, k));
        let x = r(4, d);
        let mean = [0.5f32, -1.0, 2.0, 0.0, 3.0];
        let inverse = [2.0f32, 0.5, 1.0, 0.0, 4.0];
        let target_scale = [10.0f32, 0.1, 1.0];
        let (hidden, bias) = fold((&w1, &b1), (&w2, &b2), &mean, &inverse, &target_scale);
        let with_one = DMatrix::from_fn(4, d + 1, |i, j| if j == d { 1.0 } else { x[(i, j)] });
        let mut folded = DMatrix::from_fn(4, k, |_, c| bias[c]);
        hidden.add_to(&with_one, &mut folded);
        for i in 0..4 {
            for c in 0..k {
                let mut out = b2[c];
                for u in 0..units {
                    let z: f32 = b1[u]
                        + (0..d)
                            .map(|j| (x[(i, j)] - mean[j]) * inverse[j] * w1[(j, u)])
                            .sum::<f32>();
                    out += z.max(0.0) * w2[(u, c)];
                }
                let direct = out * target_scale[c];
                assert!((folded[(i, c)] - direct).abs() < 1e-3 * direct.abs().max(1.0), "{i} {c}");
            }
        }
    }

    /// Against nalgebra's `tr_mul` in f64, over sides under six too (where nalgebra's own
    /// loop takes over from its blocked product), and with no rows at all.
    #[test]
    fn tr_product_is_the_transposes_product() {
        let mut rng = Rng::new(3);
        for (rows, m, n) in [(1, 1, 1), (3, 2, 5), (7, 4, 1), (40, 9, 13), (300, 256, 63)] {
            let a = DMatrix::<f32>::from_fn(rows, m, |_, _| rng.normal() as f32);
            let b = DMatrix::<f32>::from_fn(rows, n, |_, _| rng.normal() as f32);
            let ours = tr_product(a.as_slice(), rows, &b);
            let reference = a.cast::<f64>().tr_mul(&b.cast::<f64>());
            assert_eq!(ours.shape(), (m, n));
            assert!((ours.cast::<f64>() - reference).amax() < 1e-3 * rows as f64);
        }
        assert_eq!(tr_product(&[], 0, &DMatrix::zeros(0, 3)).shape(), (0, 3));
    }

    /// Analytic: softmax of (0, ln 3) is (¼, ¾), and huge log-odds do not overflow.
    #[test]
    fn softmax_rows_are_probabilities() {
        let p = softmax_rows(DMatrix::from_row_slice(2, 2, &[0.0, 3f32.ln(), 1000.0, 1000.0]));
        assert!((p[(0, 0)] - 0.25).abs() < 1e-6 && (p[(0, 1)] - 0.75).abs() < 1e-6);
        assert_eq!((p[(1, 0)], p[(1, 1)]), (0.5, 0.5));
    }

    /// A property: classes by the quadrant of (u, v) — 0 where the signs agree, 1 where
    /// only u is negative, 2 where only v is — are not linearly separable (class 0 holds two
    /// opposite quadrants), yet the layer learns them; and rows without a class are not
    /// learnt from: the quadrant where both are negative is left unlabelled, and is read as
    /// its neighbours 1 or 2, not as the class 0 its rows would have taught.
    #[test]
    fn the_layer_learns_classes_a_linear_map_cannot() {
        let mut rng = Rng::new(5);
        let n = 8000;
        let points: Vec<(f32, f32)> = (0..n)
            .map(|_| (rng.normal() as f32, rng.normal() as f32))
            .collect();
        let class = |(u, v): (f32, f32)| match (u < 0.0, v < 0.0) {
            (true, false) => 1u8,
            (false, true) => 2,
            _ => 0,
        };
        let labels: Vec<Option<u8>> = points
            .iter()
            .map(|&p| (p.0 > 0.0 || p.1 > 0.0).then(|| class(p)))
            .collect();
        // Four noisy copies of each, so that dropping some out still leaves both heard.
        let inputs: Vec<Vec<f32>> = points
            .iter()
            .map(|&(u, v)| {
                (0..8)
                    .map(|j| if j % 2 == 0 { u } else { v } + 0.02 * rng.normal() as f32)
                    .collect()
            })
            .collect();
        let examples = Examples {
            rows: n,
            features: 8,
            row: |i: usize, out: &mut [f32]| out.copy_from_slice(&inputs[i]),
            mean: &[0.0; 8],
            scale: &[1.0; 8],
            target: Target::Classes {
                labels: &labels,
                classes: 3,
            },
        };
        let schedule = Schedule {
            units: 32,
            epochs: 20,
            anneal_from: 15,
        };
        let (hidden, bias) = learn(&examples, schedule, |_| {});
        let with_one = DMatrix::from_fn(n, 9, |i, j| if j == 8 { 1.0 } else { inputs[i][j] });
        let mut logits = DMatrix::from_fn(n, 3, |_, c| bias[c]);
        hidden.add_to(&with_one, &mut logits);
        let mut right = [0usize; 2];
        let mut all = [0usize; 2];
        for (i, &p) in points.iter().enumerate() {
            let row = logits.row(i);
            let best = (0..3).max_by(|&a, &b| row[a].total_cmp(&row[b])).unwrap();
            let labelled = usize::from(labels[i].is_some());
            all[labelled] += 1;
            right[labelled] += usize::from(best as u8 == class(p));
        }
        assert!(right[1] as f64 > 0.95 * all[1] as f64, "{right:?} of {all:?} right");
        // The unlabelled quadrant is read as the classes beside it, 1 or 2, not as 0.
        assert!((right[0] as f64) < 0.3 * all[0] as f64, "{right:?} of {all:?} right");
    }

    /// A property no linear map has: |x| has no linear part, so the ridge leaves all of it;
    /// the layer must take most of it (the inputs are 16 noisy copies of x, so dropping some
    /// out still leaves x heard).
    #[test]
    fn the_layer_learns_what_a_linear_map_cannot() {
        let mut rng = Rng::new(11);
        let n = 8192;
        let x: Vec<f32> = (0..n).map(|_| rng.normal() as f32).collect();
        let inputs: Vec<Vec<f32>> = x
            .iter()
            .map(|&v| (0..16).map(|_| v + 0.05 * rng.normal() as f32).collect())
            .collect();
        let y: Vec<f32> = x.iter().map(|v| v.abs()).collect();
        let mean_y = y.iter().sum::<f32>() / n as f32;
        let residual = DMatrix::from_fn(n, 1, |i, _| y[i] - mean_y);
        let examples = Examples {
            rows: n,
            features: 16,
            row: |i: usize, out: &mut [f32]| out.copy_from_slice(&inputs[i]),
            mean: &[0.0; 16],
            scale: &[1.0; 16],
            target: Target::Values {
                residual: &residual,
                scale: &[0.6],
            },
        };
        let mut passes = 0;
        let (hidden, bias) = learn(&examples, MAP, |done| passes = done);
        assert_eq!(passes, EPOCHS);
        let with_one = DMatrix::from_fn(n, 17, |i, j| if j == 16 { 1.0 } else { inputs[i][j] });
        let mut fitted = DMatrix::from_element(n, 1, bias[0]);
        hidden.add_to(&with_one, &mut fitted);
        let left: f32 = (0..n).map(|i| (residual[(i, 0)] - fitted[(i, 0)]).powi(2)).sum();
        let all: f32 = residual.iter().map(|v| v * v).sum();
        // The ridge leaves all of it; 0.32 is left after these 384 steps (its bias is still
        // on its way: Adam moves a parameter about the rate a step).
        assert!(left < 0.4 * all, "the layer left {:.2} of |x|", left / all);
    }
}
