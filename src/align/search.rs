//! The alignment graph (triphone HMMs of every pronunciation, optional silences) and its
//! Viterbi search with phone-level back-pointers.

use super::frontend::FEATURE_DIM;
use super::model::{AcousticModel, STATES, STREAM_DIM, STREAMS, TOP_N, WordPosition};
use super::{Alignment, FRAMES_PER_SECOND, TimedPhone, TimedWord};

/// Language weight, silence probability and word insertion penalty of the reference
/// alignment (pocketsphinx `-lw 6.5 -silprob 0.1 -wip 0.65`): an optional silence costs
/// `lw · (ln silprob + ln wip)` nats against the acoustic log-likelihood.
const LW: f64 = 6.5;
const SILPROB: f64 = 0.1;
const WIP: f64 = 0.65;
/// Hypotheses more than `−ln 1e-80` below the frame's best are dropped (pocketsphinx
/// `-beam 1e-80`).
const BEAM: f32 = 184.2;

fn silence_cost() -> f32 {
    (LW * (SILPROB.ln() + WIP.ln())) as f32
}

const NONE: u32 = u32::MAX;

/// One phone HMM of the graph.
struct Node {
    senones: [u16; STATES],
    tmat: usize,
    /// CI phone id.
    phone: u8,
    /// (word index, pronunciation) for word phones; `None` for silence.
    word: Option<(usize, usize)>,
}

/// HMMs, their predecessors with the cost of the transition, the entry and final HMMs.
pub(super) struct Graph {
    nodes: Vec<Node>,
    preds: Vec<Vec<(u32, f32)>>,
    start: Vec<(u32, f32)>,
    finals: Vec<u32>,
}

/// The entry and exit HMMs of one pronunciation, keyed by the context they assume.
struct WordEnds {
    /// (left context, first HMM).
    entries: Vec<(usize, u32)>,
    /// (right context, last HMM).
    exits: Vec<(usize, u32)>,
    first: usize,
    last: usize,
}

impl Graph {
    /// A phone loop: every context-independent phone, fillers included (they take the
    /// noises and tones no phone explains, so that music is not read as speech), each
    /// reachable from each with the cost `transition[from][to]` (`from` = the previous
    /// phone's id; the utterance starts as if after silence), entering and leaving anywhere.
    // Node `c` is phone `c`: the index reads the transitions and names the node alike.
    #[allow(clippy::needless_range_loop)]
    pub(super) fn phone_loop(model: &AcousticModel, transition: &[Vec<f32>]) -> Graph {
        let mut g = Graph {
            nodes: Vec::new(),
            preds: Vec::new(),
            start: Vec::new(),
            finals: Vec::new(),
        };
        // Node `c` is CI phone `c`.
        let phones = model.ci_names.len();
        for c in 0..phones {
            let (senones, tmat) = model.context_independent(c);
            let h = g.add(Node {
                senones,
                tmat,
                phone: c as u8,
                word: None,
            });
            g.start.push((h, transition[model.sil][c]));
            g.finals.push(h);
        }
        for b in 0..phones {
            for a in 0..phones {
                g.edge(a as u32, b as u32, transition[a][b]);
            }
        }
        g
    }

    /// The path's HMMs as phones with times (a phone loop's output).
    pub(super) fn phones(&self, model: &AcousticModel, path: &Path, frames: usize) -> Vec<TimedPhone> {
        self.phone_spans(path, frames)
            .into_iter()
            .map(|(phone, start, end)| timed_phone(model, phone, start, end))
            .collect()
    }

    /// The path's HMMs as (CI phone, first frame, end frame).
    pub(super) fn phone_spans(&self, path: &Path, frames: usize) -> Vec<(u8, u32, u32)> {
        path.entries
            .iter()
            .enumerate()
            .map(|(k, &(node, start))| {
                let end = path.entries.get(k + 1).map_or(frames as u32, |e| e.1);
                (self.nodes[node as usize].phone, start, end)
            })
            .collect()
    }

    fn add(&mut self, node: Node) -> u32 {
        self.nodes.push(node);
        self.preds.push(Vec::new());
        (self.nodes.len() - 1) as u32
    }

    fn edge(&mut self, from: u32, to: u32, cost: f32) {
        self.preds[to as usize].push((from, cost));
    }

    /// Words × pronunciations → HMMs with exact cross-word triphone contexts: a word's first
    /// (last) phone is duplicated for each left (right) context it can meet — silence or the
    /// edge phone of each neighbouring pronunciation.
    pub(super) fn build(model: &AcousticModel, words: &[String], prons: &[&[Vec<u8>]]) -> Graph {
        let sil = model.sil;
        let n = words.len();
        let mut g = Graph {
            nodes: Vec::new(),
            preds: Vec::new(),
            start: Vec::new(),
            finals: Vec::new(),
        };
        let contexts = |i: usize, first: bool| -> Vec<usize> {
            let mut c = vec![sil];
            let neighbour = if first {
                i.checked_sub(1)
            } else {
                Some(i + 1).filter(|&j| j < n)
            };
            if let Some(j) = neighbour {
                for p in prons[j] {
                    let ph = if first { *p.last().unwrap() } else { p[0] } as usize;
                    if !c.contains(&ph) {
                        c.push(ph);
                    }
                }
            }
            c
        };
        let mut ends: Vec<Vec<WordEnds>> = Vec::with_capacity(n);
        for (i, variants) in prons.iter().enumerate() {
            let (lcs, rcs) = (contexts(i, true), contexts(i, false));
            let mut word_ends = Vec::new();
            for (v, pron) in variants.iter().enumerate() {
                let p: Vec<usize> = pron.iter().map(|&c| c as usize).collect();
                let len = p.len();
                let node = |g: &mut Graph, base: usize, l: usize, r: usize, pos| {
                    let (senones, tmat) = model.triphone(base, l, r, pos);
                    g.add(Node {
                        senones,
                        tmat,
                        phone: base as u8,
                        word: Some((i, v)),
                    })
                };
                let mut e = WordEnds {
                    entries: Vec::new(),
                    exits: Vec::new(),
                    first: p[0],
                    last: p[len - 1],
                };
                if len == 1 {
                    for &l in &lcs {
                        for &r in &rcs {
                            let h = node(&mut g, p[0], l, r, WordPosition::Single);
                            e.entries.push((l, h));
                            e.exits.push((r, h));
                        }
                    }
                    // One HMM per (l, r): listed under l among the entries and under r among
                    // the exits, so it is entered only from l and left only towards r.
                } else {
                    let firsts: Vec<u32> = lcs
                        .iter()
                        .map(|&l| node(&mut g, p[0], l, p[1], WordPosition::Begin))
                        .collect();
                    let mut tails = firsts.clone();
                    for k in 1..len - 1 {
                        let h = node(&mut g, p[k], p[k - 1], p[k + 1], WordPosition::Internal);
                        for &t in &tails {
                            g.edge(t, h, 0.0);
                        }
                        tails = vec![h];
                    }
                    for &r in &rcs {
                        let h = node(&mut g, p[len - 1], p[len - 2], r, WordPosition::End);
                        for &t in &tails {
                            g.edge(t, h, 0.0);
                        }
                        e.exits.push((r, h));
                    }
                    e.entries = lcs.iter().copied().zip(firsts).collect();
                }
                word_ends.push(e);
            }
            ends.push(word_ends);
        }
        let sil_node = |g: &mut Graph| {
            let (senones, tmat) = model.triphone(sil, sil, sil, WordPosition::Single);
            g.add(Node {
                senones,
                tmat,
                phone: sil as u8,
                word: None,
            })
        };
        let cost = silence_cost();
        for j in 0..=n {
            let s = sil_node(&mut g);
            if j == 0 {
                g.start.push((s, cost));
            } else {
                for e in &ends[j - 1] {
                    for &(r, h) in &e.exits {
                        if r == sil {
                            g.edge(h, s, cost);
                        }
                    }
                }
            }
            if j == n {
                g.finals.push(s);
                for e in &ends[n - 1] {
                    for &(r, h) in &e.exits {
                        if r == sil {
                            g.finals.push(h);
                        }
                    }
                }
                break;
            }
            for e in &ends[j] {
                for &(l, h) in &e.entries {
                    if l != sil {
                        continue;
                    }
                    g.edge(s, h, 0.0);
                    if j == 0 {
                        g.start.push((h, 0.0));
                    }
                }
            }
            if j > 0 {
                // Direct word-to-word transitions, contexts matching on both sides.
                let mut direct = Vec::new();
                for prev in &ends[j - 1] {
                    for next in &ends[j] {
                        for &(r, from) in &prev.exits {
                            if r != next.first {
                                continue;
                            }
                            for &(l, to) in &next.entries {
                                if l == prev.last {
                                    direct.push((from, to));
                                }
                            }
                        }
                    }
                }
                for (from, to) in direct {
                    g.edge(from, to, 0.0);
                }
            }
        }
        g
    }

    /// The path's HMMs → phones and words with times.
    pub(super) fn alignment(
        &self,
        model: &AcousticModel,
        words: &[String],
        path: &Path,
        frames: usize,
    ) -> Alignment {
        let mut phones = Vec::with_capacity(path.entries.len());
        let mut timed_words: Vec<TimedWord> = Vec::new();
        let mut word_of_node: Vec<Option<usize>> = Vec::new();
        for (k, &(node, start)) in path.entries.iter().enumerate() {
            let end = path.entries.get(k + 1).map_or(frames as u32, |e| e.1);
            // Divided, not multiplied by 0.01, so that times read back from files compare equal.
            let (start, end) = (
                start as f64 / FRAMES_PER_SECOND,
                end as f64 / FRAMES_PER_SECOND,
            );
            let n = &self.nodes[node as usize];
            let word = n.word.map(|(i, v)| {
                match timed_words.last_mut() {
                    Some(w) if word_of_node.last().copied().flatten() == Some(i) => w.end = end,
                    _ => timed_words.push(TimedWord {
                        word: words[i].clone(),
                        pronunciation: v,
                        start,
                        end,
                    }),
                }
                timed_words.len() - 1
            });
            word_of_node.push(n.word.map(|(i, _)| i));
            phones.push(TimedPhone {
                phone: model.ci_names[n.phone as usize].clone(),
                start,
                end,
                word,
            });
        }
        Alignment {
            words: timed_words,
            phones,
            frames,
            score_per_frame: path.score / frames.max(1) as f64,
        }
    }
}

/// A phone of a phone loop's path, frames `start..end`; fillers (noises) come out as `SIL`.
pub(super) fn timed_phone(model: &AcousticModel, phone: u8, start: u32, end: u32) -> TimedPhone {
    let phone = if model.is_filler(phone as usize) { model.sil } else { phone as usize };
    TimedPhone {
        phone: model.ci_names[phone].clone(),
        start: start as f64 / FRAMES_PER_SECOND,
        end: end as f64 / FRAMES_PER_SECOND,
        word: None,
    }
}

/// The best path: (HMM, first frame) in order, and its log-likelihood.
pub(super) struct Path {
    entries: Vec<(u32, u32)>,
    /// The path's log-likelihood up to each entry (the frames before it).
    entry_scores: Vec<f64>,
    score: f64,
}

impl Path {
    /// The log-likelihood of the path's first `frame` frames (of `frames`): exact at each
    /// HMM's entry, linear in between (the HMM's frames share its score evenly).
    pub(super) fn up_to(&self, frame: f64, frames: usize) -> f64 {
        let at = |k: usize| -> (f64, f64) {
            match self.entries.get(k) {
                Some(e) => (f64::from(e.1), self.entry_scores[k]),
                None => (frames as f64, self.score),
            }
        };
        let k = self
            .entries
            .iter()
            .rposition(|e| f64::from(e.1) <= frame)
            .unwrap_or(0);
        let ((f0, s0), (f1, s1)) = (at(k), at(k + 1));
        if f1 <= f0 {
            return s1;
        }
        s0 + (s1 - s0) * ((frame - f0) / (f1 - f0)).clamp(0.0, 1.0)
    }
}

/// Senone scores of one frame, computed on demand: per codebook and stream the top-N
/// Gaussians, per senone the log-sum of weight × density over them, summed over streams.
struct Scorer<'a> {
    model: &'a AcousticModel,
    feat: [f32; FEATURE_DIM],
    frame: u32,
    top: Vec<[(u16, f32); TOP_N]>,
    top_frame: Vec<u32>,
    senone: Vec<f32>,
    senone_frame: Vec<u32>,
    densities: Vec<f32>,
}

impl<'a> Scorer<'a> {
    fn new(model: &'a AcousticModel) -> Self {
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

    fn set_frame(&mut self, frame: u32, feat: &[f32; FEATURE_DIM]) {
        self.frame = frame;
        self.feat = *feat;
    }

    fn codebook(&mut self, block: usize) -> [(u16, f32); TOP_N] {
        if self.top_frame[block] == self.frame {
            return self.top[block];
        }
        let top = best_densities(self.model, block, &self.feat, &mut self.densities);
        self.top[block] = top;
        self.top_frame[block] = self.frame;
        top
    }

    fn score(&mut self, sen: u16) -> f32 {
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
fn best_densities(
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
fn senone_score(m: &AcousticModel, sen: usize, mut top: impl FnMut(usize) -> [(u16, f32); TOP_N]) -> f32 {
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
fn densities(
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
fn at_least_avx2(eight: &[f32; 8], bound: f32) -> u32 {
    use std::arch::x86_64::{_CMP_GE_OQ, _mm256_cmp_ps, _mm256_loadu_ps, _mm256_movemask_ps, _mm256_set1_ps};
    // SAFETY: `eight` holds the eight floats read.
    let v = unsafe { _mm256_loadu_ps(eight.as_ptr()) };
    _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(v, _mm256_set1_ps(bound))) as u32
}

/// Bit i set where `eight[i] >= bound`.
fn at_least(eight: &[f32; 8], bound: f32) -> u32 {
    (0..8).fold(0u32, |m, i| m | (u32::from(eight[i] >= bound) << i))
}

/// [`densities`] 32 Gaussians at a time, their sums held in registers over every dimension
/// (each Gaussian's terms added in the order of its dimensions).
#[inline(always)]
fn densities_lanes(
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
fn best_of(values: &[f32], at_least: impl Fn(&[f32; 8], f32) -> u32) -> [(u16, f32); TOP_N] {
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
pub(super) fn phone_scores(states: &[Vec<[f32; STATES]>]) -> Vec<Vec<f32>> {
    states
        .iter()
        .map(|row| {
            row.iter()
                .map(|s| s.iter().copied().fold(f32::NEG_INFINITY, f32::max))
                .collect()
        })
        .collect()
}

/// An HMM's best way out after its last frame: score through the exit transition, and the
/// history of the state it leaves from.
fn best_exit(
    a: &[[f32; STATES + 1]; STATES],
    score: &[f32; STATES],
    hist: &[u32; STATES],
) -> (f32, u32) {
    let mut best = (f32::NEG_INFINITY, NONE);
    for s in 0..STATES {
        let v = score[s] + a[s][STATES];
        if v > best.0 {
            best = (v, hist[s]);
        }
    }
    best
}

/// Frame-synchronous Viterbi over the graph, beam-pruned; phone-level back-pointers.
pub(super) fn viterbi(
    model: &AcousticModel,
    g: &Graph,
    feats: &[[f32; FEATURE_DIM]],
) -> Option<Path> {
    best_path(model, g, feats.iter().map(Emission::Acoustic))
}

/// The search over every frame's `emissions`, beam-pruned; `None` when the beam lost every
/// hypothesis or no final HMM was reached.
fn best_path<'e>(
    model: &AcousticModel,
    g: &Graph,
    emissions: impl Iterator<Item = Emission<'e>>,
) -> Option<Path> {
    let mut decoder = Decoder::new(model, g);
    for emission in emissions {
        decoder.advance(g, emission)?;
    }
    decoder.finish(g)
}

/// What scores a state in one frame of the search.
#[derive(Clone, Copy)]
enum Emission<'a> {
    /// The acoustic model's scores of these features, on demand.
    Acoustic(&'a [f32; FEATURE_DIM]),
    /// Every state of a phone its phone's score (a hybrid recogniser's).
    Phones(&'a [f32]),
    /// The acoustic model's scores of each context-independent phone's states, computed
    /// beforehand ([`ci_state_scores`]; a graph of context-independent phones only).
    States(&'a [[f32; STATES]]),
}

/// Per frame, the acoustic model's score of each state of each context-independent phone
/// (fillers included): every search over a phone loop and the phones' evidence from one
/// scoring.
pub(super) fn ci_state_scores(model: &AcousticModel, feats: &[[f32; FEATURE_DIM]]) -> Vec<Vec<[f32; STATES]>> {
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
const FRAME_BLOCK: usize = 64;

/// [`viterbi`] of a phone loop ([`Graph::phone_loop`]) over scores from [`ci_state_scores`].
pub(super) fn viterbi_states(model: &AcousticModel, g: &Graph, states: &[Vec<[f32; STATES]>]) -> Option<Path> {
    best_path(model, g, states.iter().map(|row| Emission::States(row)))
}

/// [`viterbi`] with every state of a phone scoring that phone's entry of the frame's row of
/// `scores` (frames × context-independent phones) in place of the acoustic model's.
pub(super) fn viterbi_scored(model: &AcousticModel, g: &Graph, scores: &[Vec<f32>]) -> Option<Path> {
    best_path(model, g, scores.iter().map(|row| Emission::Phones(row)))
}

/// The Viterbi search's state between frames, so that features can arrive a few at a time
/// (live phone recognition) as well as all at once ([`viterbi`]).
pub(super) struct Decoder<'m> {
    model: &'m AcousticModel,
    scorer: Scorer<'m>,
    score: Vec<[f32; STATES]>,
    hist: Vec<[u32; STATES]>,
    next: Vec<[f32; STATES]>,
    next_hist: Vec<[u32; STATES]>,
    exit: Vec<(f32, u32)>,
    active: Vec<bool>,
    /// (node, first frame, previous record, score on entry)
    records: Vec<(u32, u32, u32, f32)>,
    start_cost: Vec<f32>,
    /// Frames decoded.
    pub(super) frames: usize,
}

/// Records kept before the unreachable ones are dropped (a live stream runs for hours).
const RECORDS_BEFORE_COMPACTION: usize = 1 << 18;

impl<'m> Decoder<'m> {
    pub(super) fn new(model: &'m AcousticModel, g: &Graph) -> Self {
        let n = g.nodes.len();
        let ninf = f32::NEG_INFINITY;
        let mut start_cost = vec![ninf; n];
        for &(h, c) in &g.start {
            start_cost[h as usize] = c;
        }
        Decoder {
            model,
            scorer: Scorer::new(model),
            score: vec![[ninf; STATES]; n],
            hist: vec![[NONE; STATES]; n],
            next: vec![[ninf; STATES]; n],
            next_hist: vec![[NONE; STATES]; n],
            exit: vec![(ninf, NONE); n],
            active: vec![false; n],
            records: Vec::new(),
            start_cost,
            frames: 0,
        }
    }

    /// One frame of a phone loop's search over its phones' state scores ([`ci_state_scores`]);
    /// `None` when the beam lost every hypothesis.
    pub(super) fn step_states(&mut self, g: &Graph, states: &[[f32; STATES]]) -> Option<()> {
        self.advance(g, Emission::States(states))
    }

    /// One frame of the search, each state scored as `emission` says.
    // States index the transition matrix in both its dimensions and the scores beside it.
    #[allow(clippy::needless_range_loop)]
    fn advance(&mut self, g: &Graph, emission: Emission<'_>) -> Option<()> {
        let model = self.model;
        let n = g.nodes.len();
        let ninf = f32::NEG_INFINITY;
        let t = self.frames;
        if let Emission::Acoustic(feat) = emission {
            self.scorer.set_frame(t as u32, feat);
        }
        // Exits of the previous frame.
        for h in 0..n {
            self.exit[h] = (ninf, NONE);
            if self.active[h] {
                self.exit[h] =
                    best_exit(&model.tmats[g.nodes[h].tmat], &self.score[h], &self.hist[h]);
            }
        }
        let mut best = ninf;
        for h in 0..n {
            let (mut entry, mut entry_hist) = if t == 0 {
                (self.start_cost[h], NONE)
            } else {
                (ninf, NONE)
            };
            for &(p, c) in &g.preds[h] {
                let v = self.exit[p as usize].0 + c;
                if v > entry {
                    entry = v;
                    entry_hist = self.exit[p as usize].1;
                }
            }
            if !self.active[h] && entry == ninf {
                self.next[h] = [ninf; STATES];
                continue;
            }
            let node = &g.nodes[h];
            let a = &model.tmats[node.tmat];
            for j in 0..STATES {
                let (mut v, mut from) = (ninf, NONE);
                for i in 0..=j {
                    let s = self.score[h][i] + a[i][j];
                    if s > v {
                        v = s;
                        from = self.hist[h][i];
                    }
                }
                if j == 0 && entry > v {
                    v = entry;
                    self.records.push((h as u32, t as u32, entry_hist, entry));
                    from = (self.records.len() - 1) as u32;
                }
                if v > ninf {
                    v += match emission {
                        Emission::Phones(scores) => scores[usize::from(node.phone)],
                        Emission::States(scores) => scores[usize::from(node.phone)][j],
                        Emission::Acoustic(_) => self.scorer.score(node.senones[j]),
                    };
                }
                self.next[h][j] = v;
                self.next_hist[h][j] = from;
                best = best.max(v);
            }
        }
        if best == ninf {
            return None;
        }
        let threshold = best - BEAM;
        for h in 0..n {
            let mut any = false;
            for v in self.next[h].iter_mut() {
                if *v < threshold {
                    *v = ninf;
                } else {
                    any = true;
                }
            }
            self.active[h] = any;
        }
        std::mem::swap(&mut self.score, &mut self.next);
        std::mem::swap(&mut self.hist, &mut self.next_hist);
        self.frames += 1;
        if self.records.len() > RECORDS_BEFORE_COMPACTION {
            self.compact();
        }
        Some(())
    }

    /// The best path so far, ending in whichever state scores best now (not necessarily at
    /// an HMM's exit): what a live stream commits from.
    pub(super) fn partial(&self) -> Path {
        let (mut best, mut at) = (f32::NEG_INFINITY, NONE);
        for (h, (score, hist)) in self.score.iter().zip(&self.hist).enumerate() {
            if !self.active[h] {
                continue;
            }
            for (&v, &from) in score.iter().zip(hist) {
                if v > best {
                    (best, at) = (v, from);
                }
            }
        }
        self.trace(at, best)
    }

    /// The best path through the graph's final HMMs after the last frame.
    pub(super) fn finish(&self, g: &Graph) -> Option<Path> {
        let (mut best, mut at) = (f32::NEG_INFINITY, NONE);
        for &h in &g.finals {
            let h = h as usize;
            let (v, from) =
                best_exit(&self.model.tmats[g.nodes[h].tmat], &self.score[h], &self.hist[h]);
            if v > best {
                (best, at) = (v, from);
            }
        }
        (at != NONE).then(|| self.trace(at, best))
    }

    fn trace(&self, mut at: u32, score: f32) -> Path {
        let (mut entries, mut entry_scores) = (Vec::new(), Vec::new());
        while at != NONE {
            let (node, start, prev, entered) = self.records[at as usize];
            entries.push((node, start));
            entry_scores.push(f64::from(entered));
            at = prev;
        }
        entries.reverse();
        entry_scores.reverse();
        Path {
            entries,
            entry_scores,
            score: f64::from(score),
        }
    }

    /// Drops the records no live hypothesis leads back to, renumbering the rest.
    fn compact(&mut self) {
        let mut keep = vec![false; self.records.len()];
        let mut stack: Vec<u32> = self
            .hist
            .iter()
            .zip(&self.active)
            .filter(|(_, a)| **a)
            .flat_map(|(h, _)| h.iter().copied())
            .filter(|&r| r != NONE)
            .collect();
        while let Some(r) = stack.pop() {
            if !std::mem::replace(&mut keep[r as usize], true) {
                let prev = self.records[r as usize].2;
                if prev != NONE {
                    stack.push(prev);
                }
            }
        }
        let mut new_index = vec![NONE; self.records.len()];
        let mut kept = Vec::with_capacity(keep.iter().filter(|&&k| k).count());
        for (r, record) in self.records.iter().enumerate() {
            if keep[r] {
                new_index[r] = kept.len() as u32;
                let prev = if record.2 == NONE { NONE } else { new_index[record.2 as usize] };
                kept.push((record.0, record.1, prev, record.3));
            }
        }
        self.records = kept;
        for (h, active) in self.hist.iter_mut().zip(&self.active) {
            for r in h.iter_mut() {
                *r = if *active && *r != NONE { new_index[*r as usize] } else { NONE };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bounded ranking against a full stable sort, over lengths that are and are not
    /// multiples of the sets and of eight, with many ties (values rounded to a coarse grid, or
    /// to one so coarse that the sets' greatest values are all equal).
    #[test]
    fn best_of_ranks_as_a_full_sort_does() {
        let mut rng = crate::rng::Rng::new(7);
        for len in [1, 3, 8, 31, 64, 100, 128, 130] {
            for k in 0..400 {
                // Every other vector on a grid so coarse that most values tie (three levels).
                let grid = if k % 2 == 0 { 2.0 } else { 0.1 };
                let values: Vec<f32> = (0..len).map(|_| (rng.range(-20.0, 0.0) * grid).round() as f32).collect();
                let mut order: Vec<usize> = (0..len).collect();
                order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
                let mut expected = [(0u16, f32::NEG_INFINITY); TOP_N];
                for (slot, &d) in expected.iter_mut().zip(&order) {
                    *slot = (d as u16, values[d]);
                }
                assert_eq!(best_of(&values, at_least), expected, "{values:?}");
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: this CPU has AVX2 (checked just above).
                    let by_avx = best_of(&values, |e, b| unsafe { at_least_avx2(e, b) });
                    assert_eq!(by_avx, expected, "{values:?}");
                }
            }
        }
    }

    /// Eight comparisons in one AVX instruction as one by one: ties, signed zeros, infinities
    /// and NaN (never at least anything).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn at_least_by_avx_as_one_by_one() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let odd = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, -1.5, 2.0, -1e30];
        for bound in [0.0, -0.0, -1.5, f32::NEG_INFINITY, f32::INFINITY, f32::NAN, 3.0] {
            for shift in 0..8 {
                let eight: [f32; 8] = std::array::from_fn(|i| odd[(i + shift) % 8]);
                // SAFETY: this CPU has AVX2 (checked above).
                let by_avx = unsafe { at_least_avx2(&eight, bound) };
                assert_eq!(by_avx, at_least(&eight, bound), "{eight:?} ≥ {bound}");
            }
        }
    }
}
