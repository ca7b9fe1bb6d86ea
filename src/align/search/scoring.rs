//! The acoustic model's scores of states: senones from the top Gaussians of each codebook
//! stream (AVX2 where the CPU has it), and every context-independent phone's states at once.

use super::*;

/// Senone scores of one frame, computed on demand: per codebook and stream the top-N
/// Gaussians, per senone the log-sum of weight × density over them, summed over streams.
pub(crate) struct Scorer<'a> {
    pub(crate) model: &'a AcousticModel,
    pub(crate) feat: [f32; FEATURE_DIM],
    pub(crate) frame: u32,
    pub(crate) top: Vec<[(u16, f32); TOP_N]>,
    pub(crate) top_frame: Vec<u32>,
    pub(crate) senone: Vec<f32>,
    pub(crate) senone_frame: Vec<u32>,
    pub(crate) densities: Vec<f32>,
}

impl<'a> Scorer<'a> {
    pub(crate) fn new(model: &'a AcousticModel) -> Self {
        Scorer {
            model,
            feat: [0.0; FEATURE_DIM],
            frame: NONE,
            top: vec![[(0, f32::NEG_INFINITY); TOP_N]; model.n_codebooks * STREAMS],
            top_frame: vec![NONE; model.n_codebooks * STREAMS],
            senone: vec![0.0; model.n_senones],
            senone_frame: vec![NONE; model.n_senones],
            densities: vec![0.0; model.n_density],
        }
    }

    pub(crate) fn set_frame(&mut self, frame: u32, feat: &[f32; FEATURE_DIM]) {
        self.frame = frame;
        self.feat = *feat;
    }

    pub(crate) fn codebook(&mut self, block: usize) -> [(u16, f32); TOP_N] {
        if self.top_frame[block] == self.frame {
            return self.top[block];
        }
        let top = best_densities(self.model, block, &self.feat, &mut self.densities);
        self.top[block] = top;
        self.top_frame[block] = self.frame;
        top
    }

    pub(crate) fn score(&mut self, sen: u16) -> f32 {
        let sen = sen as usize;
        if self.senone_frame[sen] == self.frame {
            return self.senone[sen];
        }
        let model = self.model;
        let total = senone_score(model, sen, |block| self.codebook(block));
        self.senone[sen] = total;
        self.senone_frame[sen] = self.frame;
        total
    }
}

/// The [`TOP_N`] best Gaussians (density, log density) of codebook stream `block` at `feat`,
/// best first (the first of equals first); `scratch` holds the codebook's densities.
pub(crate) fn best_densities(
    m: &AcousticModel,
    block: usize,
    feat: &[f32; FEATURE_DIM],
    scratch: &mut [f32],
) -> [(u16, f32); TOP_N] {
    let nd = m.n_density;
    let stream = block % STREAMS;
    let x: &[f32; STREAM_DIM] = feat[stream * STREAM_DIM..][..STREAM_DIM].try_into().expect("a stream");
    let span = block * nd * STREAM_DIM..(block + 1) * nd * STREAM_DIM;
    densities(scratch, &m.log_norm[block * nd..(block + 1) * nd], x, &m.means[span.clone()], &m.inv_2var[span])
}

/// A senone's log-likelihood: per stream, the log-sum of mixture weight × density over its
/// codebook's best Gaussians (`top` of each codebook stream block), summed over the streams.
pub(crate) fn senone_score(m: &AcousticModel, sen: usize, mut top: impl FnMut(usize) -> [(u16, f32); TOP_N]) -> f32 {
    let cb = m.senone_codebook[sen] as usize;
    let mut total = 0.0;
    for s in 0..STREAMS {
        let best_n = top(cb * STREAMS + s);
        let mixw = &m.log_mixw[s * m.n_density * m.n_senones..];
        let terms = best_n.map(|(d, g)| g + mixw[d as usize * m.n_senones + sen]);
        let best = terms.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        total += best + terms.iter().map(|&t| (t - best).exp()).sum::<f32>().ln();
    }
    total
}

/// Log densities of one codebook's Gaussians at `x` (one stream): `acc[d] = log_norm[d] −
/// Σ_k (x_k − μ_dk)² / (2σ²_dk)`, `means` and `inv_2var` laid out dimension by dimension; and
/// the best [`TOP_N`] of them.
pub(crate) fn densities(
    acc: &mut [f32],
    log_norm: &[f32],
    x: &[f32; STREAM_DIM],
    means: &[f32],
    inv_2var: &[f32],
) -> [(u16, f32); TOP_N] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: this CPU has AVX2 (checked just above).
        return unsafe { densities_avx2(acc, log_norm, x, means, inv_2var) };
    }
    densities_lanes(acc, log_norm, x, means, inv_2var, at_least)
}

/// [`densities_lanes`] compiled for AVX2: the same operations in the same order (no fused
/// multiply-add), so the same densities to the bit; eight comparisons with the bound in one
/// instruction ([`at_least_avx2`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn densities_avx2(
    acc: &mut [f32],
    log_norm: &[f32],
    x: &[f32; STREAM_DIM],
    means: &[f32],
    inv_2var: &[f32],
) -> [(u16, f32); TOP_N] {
    densities_lanes(acc, log_norm, x, means, inv_2var, |eight, bound| at_least_avx2(eight, bound))
}

/// [`at_least`] by AVX: one comparison of eight lanes and their sign bits gathered.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) fn at_least_avx2(eight: &[f32; 8], bound: f32) -> u32 {
    use std::arch::x86_64::{_CMP_GE_OQ, _mm256_cmp_ps, _mm256_loadu_ps, _mm256_movemask_ps, _mm256_set1_ps};
    // SAFETY: `eight` holds the eight floats read.
    let v = unsafe { _mm256_loadu_ps(eight.as_ptr()) };
    _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(v, _mm256_set1_ps(bound))) as u32
}

/// Bit i set where `eight[i] >= bound`.
pub(crate) fn at_least(eight: &[f32; 8], bound: f32) -> u32 {
    (0..8).fold(0u32, |m, i| m | (u32::from(eight[i] >= bound) << i))
}

/// [`densities`] 32 Gaussians at a time, their sums held in registers over every dimension
/// (each Gaussian's terms added in the order of its dimensions).
#[inline(always)]
pub(crate) fn densities_lanes(
    acc: &mut [f32],
    log_norm: &[f32],
    x: &[f32; STREAM_DIM],
    means: &[f32],
    inv_2var: &[f32],
    at_least: impl Fn(&[f32; 8], f32) -> u32,
) -> [(u16, f32); TOP_N] {
    const LANES: usize = 32;
    let nd = acc.len();
    let mut start = 0;
    // Whole groups of 32 with lengths known when compiled, so that no copy is a call.
    while start + LANES <= nd {
        let mut sum: [f32; LANES] = log_norm[start..start + LANES].try_into().expect("32 norms");
        for (k, &xk) in x.iter().enumerate() {
            let off = k * nd + start;
            let mu: &[f32; LANES] = means[off..off + LANES].try_into().expect("32 means");
            let iv: &[f32; LANES] = inv_2var[off..off + LANES].try_into().expect("32 weights");
            for i in 0..LANES {
                let d = xk - mu[i];
                sum[i] -= d * d * iv[i];
            }
        }
        let out: &mut [f32; LANES] = (&mut acc[start..start + LANES]).try_into().expect("32 sums");
        *out = sum;
        start += LANES;
    }
    for (d, a) in acc.iter_mut().enumerate().skip(start) {
        let mut sum = log_norm[d];
        for (k, &xk) in x.iter().enumerate() {
            let diff = xk - means[k * nd + d];
            sum -= diff * diff * inv_2var[k * nd + d];
        }
        *a = sum;
    }
    best_of(acc, at_least)
}

/// The [`TOP_N`] largest of `values` with their indices, largest first, the first of equals
/// first. Only values at least a bound are ranked, one the [`TOP_N`]th largest value cannot be
/// below: the maxima of 32 disjoint sets (every 32nd value), the greatest of them taken away
/// [`TOP_N`] − 1 times (all its equals with it), and the greatest left. Branch-free, so that
/// it runs in vector registers (ranking the 32 maxima one by one was a third of the scoring's
/// time, most of it in mispredicted branches).
#[inline(always)]
pub(crate) fn best_of(values: &[f32], at_least: impl Fn(&[f32; 8], f32) -> u32) -> [(u16, f32); TOP_N] {
    const SETS: usize = 32;
    let insert = |top: &mut [(u16, f32); TOP_N], d: usize, s: f32| {
        if s > top[TOP_N - 1].1 {
            let mut k = TOP_N - 1;
            while k > 0 && top[k - 1].1 < s {
                top[k] = top[k - 1];
                k -= 1;
            }
            top[k] = (d as u16, s);
        }
    };
    let mut bound = f32::NEG_INFINITY;
    if values.len() >= 2 * SETS {
        let mut maxima = [f32::NEG_INFINITY; SETS];
        for row in values.chunks_exact(SETS) {
            for (m, &v) in maxima.iter_mut().zip(row) {
                *m = if v > *m { v } else { *m };
            }
        }
        for (i, &v) in values.chunks_exact(SETS).remainder().iter().enumerate() {
            maxima[i] = if v > maxima[i] { v } else { maxima[i] };
        }
        // At least TOP_N − 1 maxima are taken away before the last round, all at or above what
        // is left: TOP_N values of disjoint sets are at or above the bound.
        for round in 0..TOP_N {
            // Halving, so that the 32 reduce in five vector steps, not 31 in a chain.
            let max = |a: f32, b: f32| if b > a { b } else { a };
            let sixteen: [f32; 16] = std::array::from_fn(|i| max(maxima[i], maxima[i + 16]));
            let eight: [f32; 8] = std::array::from_fn(|i| max(sixteen[i], sixteen[i + 8]));
            let four: [f32; 4] = std::array::from_fn(|i| max(eight[i], eight[i + 4]));
            let greatest = max(max(four[0], four[2]), max(four[1], four[3]));
            if round + 1 == TOP_N {
                bound = greatest;
            } else {
                for m in maxima.iter_mut() {
                    *m = if *m == greatest { f32::NEG_INFINITY } else { *m };
                }
            }
        }
    }
    // A mask of the values at the bound, eight compared at a time, 64 to a word; its set bits
    // ranked in order — one branch a candidate, none a value.
    let mut top = [(0u16, f32::NEG_INFINITY); TOP_N];
    for (w, word) in values.chunks(64).enumerate() {
        let groups = word.chunks_exact(8);
        let rest = groups.remainder();
        let mut mask = rest
            .iter()
            .enumerate()
            .fold(0u64, |m, (i, &s)| m | (u64::from(s >= bound) << (word.len() - rest.len() + i)));
        for (c, eight) in groups.enumerate() {
            let eight: &[f32; 8] = eight.try_into().expect("8 values");
            mask |= u64::from(at_least(eight, bound)) << (8 * c);
        }
        while mask != 0 {
            let i = mask.trailing_zeros() as usize;
            insert(&mut top, 64 * w + i, word[i]);
            mask &= mask - 1;
        }
    }
    top
}

/// Per frame, each context-independent phone's best state score (log-likelihood; fillers
/// included): what the acoustic model hears in that frame, before any search.
pub(crate) fn phone_scores(states: &[Vec<[f32; STATES]>]) -> Vec<Vec<f32>> {
    states
        .iter()
        .map(|row| {
            row.iter()
                .map(|s| s.iter().copied().fold(f32::NEG_INFINITY, f32::max))
                .collect()
        })
        .collect()
}


/// Per frame, the acoustic model's score of each state of each context-independent phone
/// (fillers included): every search over a phone loop and the phones' evidence from one
/// scoring.
pub(crate) fn ci_state_scores(model: &AcousticModel, feats: &[[f32; FEATURE_DIM]]) -> Vec<Vec<[f32; STATES]>> {
    let blocks = model.n_codebooks * STREAMS;
    let mut scratch = vec![0.0; model.n_density];
    let mut top = vec![[(0u16, f32::NEG_INFINITY); TOP_N]; FRAME_BLOCK * blocks];
    let senones: Vec<[u16; STATES]> = (0..model.ci_names.len()).map(|ci| model.context_independent(ci).0).collect();
    let mut scores = Vec::with_capacity(feats.len());
    for chunk in feats.chunks(FRAME_BLOCK) {
        // Codebook by codebook, so that each one's Gaussians stay in the cache over the frames.
        for block in 0..blocks {
            for (t, feat) in chunk.iter().enumerate() {
                top[t * blocks + block] = best_densities(model, block, feat, &mut scratch);
            }
        }
        for t in 0..chunk.len() {
            let top = &top[t * blocks..(t + 1) * blocks];
            scores.push(senones.iter().map(|ci| ci.map(|s| senone_score(model, s.into(), |b| top[b]))).collect());
        }
    }
    scores
}

/// Frames [`ci_state_scores`] scores together.
pub(crate) const FRAME_BLOCK: usize = 64;
