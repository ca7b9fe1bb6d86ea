//! The phoneme similarity matrix S (\[blend\] §4.2) and distance matrix M (\[unitsel\] eq. 5),
//! computed from a codebook's trajectories (DESIGN §7).

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use super::{Codebook, N, Occurrence};

/// Constants of S and M (DESIGN §7); every one configurable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimilarityOptions {
    /// Equidistant samples per phone occurrence (the source: 5).
    pub samples: usize,
    /// γ of `S = exp(−γ D)`; `None`: 1 / median off-diagonal D.
    pub gamma: Option<f64>,
    /// Weight parameters by their variance (`w_k`); else uniformly.
    pub variance_weights: bool,
    /// Scale distances by each phone's context variability (`v_i`); else `v = 1`.
    pub context_weights: bool,
    /// Let the shape parameters count in S (`false`: appearance alone, to see what shape
    /// changes).
    #[serde(default = "yes")]
    pub use_shape: bool,
    /// β₂ of M's weights `γ_k = exp(β₂ |k − K|)`, k counting appearance parameters from 1.
    pub beta2: f64,
    /// K of M: the leading appearance parameters M uses (at most; fewer if the model has
    /// fewer), and the centre of its weights.
    pub k_centre: usize,
}

impl Default for SimilarityOptions {
    fn default() -> Self {
        SimilarityOptions {
            samples: 5,
            gamma: None,
            variance_weights: true,
            context_weights: true,
            use_shape: true,
            beta2: 0.1,
            k_centre: 12,
        }
    }
}

fn yes() -> bool {
    true
}

/// Per-parameter weights on squared raw differences, indexed over `layout.params_range()`
/// (DESIGN §7, our reading of \[blend\]'s `w_k`): each parameter is standardised by its
/// s.d. over the codebook's frames and weighted by its share of its own model's variance,
/// shape and appearance each summing to ½. On raw values that is `½ / V_model` for every
/// parameter of a model of total variance `V_model` — so shape counts as much as appearance,
/// whose values are orders of magnitude larger. `variance_weights: false`: uniform `1/d` on
/// raw values (the naive reading, kept for comparison).
pub fn parameter_weights(cb: &Codebook) -> Vec<f64> {
    let layout = cb.layout;
    let range = layout.params_range();
    let d = range.len();
    if !cb.options.variance_weights {
        let from = if cb.options.use_shape {
            0
        } else {
            layout.shape
        };
        return (0..d)
            .map(|k| {
                if k >= from {
                    1.0 / (d - from) as f64
                } else {
                    0.0
                }
            })
            .collect();
    }
    let (mut sum, mut sq, mut n) = (vec![0.0; d], vec![0.0; d], 0.0);
    for t in &cb.trajectories {
        for row in t.values.chunks_exact(t.dims) {
            for (k, &v) in row[range.clone()].iter().enumerate() {
                sum[k] += v;
                sq[k] += v * v;
            }
            n += 1.0;
        }
    }
    let var: Vec<f64> = (0..d)
        .map(|k| (sq[k] / n - (sum[k] / n).powi(2)).max(0.0))
        .collect();
    let blocks = [0..layout.shape, layout.shape..d];
    let totals: Vec<f64> = blocks
        .iter()
        .enumerate()
        .map(|(i, b)| {
            if i == 0 && !cb.options.use_shape {
                0.0
            } else {
                var[b.clone()].iter().sum()
            }
        })
        .collect();
    let share = 1.0 / totals.iter().filter(|&&t| t > 0.0).count().max(1) as f64;
    let mut w = vec![0.0; d];
    for (block, &total) in blocks.iter().zip(&totals) {
        if total > 0.0 {
            w[block.clone()].iter_mut().for_each(|x| *x = share / total);
        }
    }
    w
}

/// An occurrence sampled at `samples` equidistant points over its duration, shape and
/// appearance parameters only (`samples × d`).
fn occurrence_samples(cb: &Codebook, o: Occurrence) -> Vec<f64> {
    let g = cb.segment(o);
    let n = cb.options.samples;
    let times: Vec<f64> = (0..n)
        .map(|j| g.start + g.duration() * j as f64 / (n - 1) as f64)
        .collect();
    let all = cb.trajectories[o.sentence].sample(&times);
    all.chunks_exact(cb.dims())
        .flat_map(|row| row[cb.layout.params_range()].to_vec())
        .collect()
}

/// S (\[blend\] §4.2, DESIGN §7): `D_ij = v_i v_j Σ_k w_k Σ_t (P̄_i[t,k] − P̄_j[t,k])²`,
/// `S = exp(−γ D)`. `v_i`: the mean w-weighted area between phone i's occurrences and its
/// mean trajectory, normalised to mean 1 over present phones (phones seen once get 1).
pub(super) fn similarity_matrix(cb: &Codebook) -> Array2<f64> {
    let w = parameter_weights(cb);
    let d = w.len();
    let n = cb.options.samples;
    let present = cb.present();
    let mut means = vec![vec![0.0; n * d]; N];
    let mut spread = vec![f64::NAN; N];
    for &p in &present {
        let occ = &cb.occurrences[p.index()];
        let samples: Vec<Vec<f64>> = occ.iter().map(|&o| occurrence_samples(cb, o)).collect();
        let mean = &mut means[p.index()];
        for s in &samples {
            mean.iter_mut()
                .zip(s)
                .for_each(|(m, v)| *m += v / samples.len() as f64);
        }
        if samples.len() > 1 {
            let area = |s: &Vec<f64>| -> f64 {
                s.chunks_exact(d)
                    .zip(mean.chunks_exact(d))
                    .map(|(a, b)| (0..d).map(|k| w[k] * (a[k] - b[k]).abs()).sum::<f64>())
                    .sum::<f64>()
                    / n as f64
            };
            spread[p.index()] = samples.iter().map(area).sum::<f64>() / samples.len() as f64;
        }
    }
    let seen: Vec<f64> = spread.iter().copied().filter(|v| v.is_finite()).collect();
    let mean_spread = seen.iter().sum::<f64>() / seen.len().max(1) as f64;
    let v: Vec<f64> = spread
        .iter()
        .map(|&s| {
            if cb.options.context_weights && s.is_finite() && mean_spread > 0.0 {
                s / mean_spread
            } else {
                1.0
            }
        })
        .collect();
    let mut dist = Array2::<f64>::zeros((N, N));
    for &a in &present {
        for &b in &present {
            let (ma, mb) = (&means[a.index()], &means[b.index()]);
            let sq: f64 = ma
                .chunks_exact(d)
                .zip(mb.chunks_exact(d))
                .map(|(x, y)| (0..d).map(|k| w[k] * (x[k] - y[k]).powi(2)).sum::<f64>())
                .sum();
            dist[[a.index(), b.index()]] = v[a.index()] * v[b.index()] * sq;
        }
    }
    let gamma = cb.options.gamma.unwrap_or_else(|| {
        let mut off: Vec<f64> = present
            .iter()
            .flat_map(|a| {
                present
                    .iter()
                    .filter(move |b| *b != a)
                    .map(|b| dist[[a.index(), b.index()]])
            })
            .collect();
        off.sort_by(f64::total_cmp);
        let median = off.get(off.len() / 2).copied().unwrap_or(1.0);
        if median > 0.0 { 1.0 / median } else { 1.0 }
    });
    let mut s = Array2::<f64>::eye(N);
    for &a in &present {
        for &b in &present {
            s[[a.index(), b.index()]] = (-gamma * dist[[a.index(), b.index()]]).exp();
        }
    }
    s
}

/// M (\[unitsel\] eq. 5): `M(i,j) = sqrt(Σ_{k=1..K} γ_k (A_i,k − A_j,k)² / Σ_k γ_k)` over the
/// first K mean appearance parameters `A_i` of the frames labelled i, `K = min(k_centre,
/// appearance parameters)` (the reduced dimension; 12 by default), `γ_k = exp(β₂ |k − K|)`:
/// the leading, most reliable components weigh most and the noisy tail is left out.
pub(super) fn distance_matrix(cb: &Codebook) -> Array2<f64> {
    let range = cb.layout.appearance_range();
    let na = range.len().min(cb.options.k_centre);
    let range = range.start..range.start + na;
    let mut sums = vec![vec![0.0; na]; N];
    let mut counts = vec![0usize; N];
    for (s, t) in cb.sentences.iter().zip(&cb.trajectories) {
        for (i, row) in t.values.chunks_exact(t.dims).enumerate() {
            let time = t.times[i];
            if let Some(g) = s.segments.iter().find(|g| time >= g.start && time < g.end) {
                let p = g.phone.index();
                sums[p]
                    .iter_mut()
                    .zip(&row[range.clone()])
                    .for_each(|(a, v)| *a += v);
                counts[p] += 1;
            }
        }
    }
    let gk: Vec<f64> = (1..=na)
        .map(|k| (cb.options.beta2 * (k as f64 - na as f64).abs()).exp())
        .collect();
    let gsum: f64 = gk.iter().sum();
    let mut m = Array2::<f64>::zeros((N, N));
    for a in 0..N {
        for b in 0..N {
            if counts[a] == 0 || counts[b] == 0 || na == 0 {
                continue;
            }
            let sq: f64 = (0..na)
                .map(|k| {
                    gk[k] * (sums[a][k] / counts[a] as f64 - sums[b][k] / counts[b] as f64).powi(2)
                })
                .sum();
            m[[a, b]] = (sq / gsum).sqrt();
        }
    }
    m
}
