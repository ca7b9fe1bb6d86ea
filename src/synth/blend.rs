//! Top-N context blending (\[blend\] §5, DESIGN §8).
//!
//! For each target phone p with left context l₁…l_C and right context r₁…r_C, every codebook
//! occurrence j of p is scored `s_j = Σᵢ S(lᵢ, l_ij)/(i+1) + Σᵢ S(rᵢ, r_ij)/(i+1)` (beyond a
//! sentence edge the context is `sil`). The N best are time-warped to the target duration and
//! averaged with weights `s_j / Σ s`; phones are concatenated and sampled at the frame rate.
//!
//! Averaging N examples shrinks the motion: deviations that differ between examples cancel
//! (inner-mouth height s.d. 84 % of real on GRID s1 with N = 5). With `preserve_variance` the
//! shape values' deviations from the utterance's mean b̄ are scaled by one gain
//! `g = √(Σ_t Σ_j w_j ‖x_j(t) − m_j‖² / Σ_t ‖b(t) − b̄‖²)`, where `m_j` is the mean of example
//! j's own sentence — so the blend b moves about its mean as much as the examples move about
//! theirs (their offsets between sentences, which a blend rightly averages, are not put back) —
//! and the appearance values by their own such gain; each gain at least 1 and at most
//! `√N_eff` (`N_eff = 1 / mean_t Σ_j w_j²`, the gain that restores fully independent
//! examples). One gain per group for the whole utterance scales every landmark's motion alike,
//! so the mouth moves as far without its timing changing, and keeps the trajectory as
//! continuous as the plain blend. `appearance_gain` then scales the appearance's deviations
//! once more (a talker's setting, chosen by how often a discriminator tells its recorded-mouth
//! drawing from the recording).

use crate::codebook::{Codebook, Occurrence};
use crate::facespace::Frames;
use crate::options;
use crate::phonemes::{Phone, Segment};

use super::{Chosen, PhoneReport, SynthError, Synthesis, Synthesiser, stand_in, validate_request};

/// Examples blended per phone by default: N = 5 had the best mouth r_pca (eq. 16) and
/// inner-mouth r_h of N = 1/3/5 on GRID s1's validation sentences (BENCHMARKS.md).
pub const DEFAULT_TOP_N: usize = 5;

/// Widest context scored (phones either side).
pub const MAX_CONTEXT: usize = 20;

/// Top-N context blending (\[blend\] §5).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Blend {
    /// Context width C (1 = triphone; 0 scores every occurrence alike).
    pub context: usize,
    /// Examples averaged per phone, N.
    pub top_n: usize,
    /// Scale the blend's deviations from the utterance's mean back to the examples' spread
    /// about their sentences' means (module docs); off: the plain weighted average of
    /// \[blend\] §5.
    pub preserve_variance: bool,
    /// The appearance's deviations from the utterance's mean are then scaled by this (1: as
    /// restored). The restored spread matches the recordings' over a sentence, yet drawn with
    /// recorded mouths a livelier appearance is told from the recording less often (GRID s1's
    /// validation split, [`crate::eval::realism`]): a talker carries its own
    /// ([`crate::talker::Settings::appearance_gain`]).
    pub appearance_gain: f64,
}

impl Default for Blend {
    /// C = 1, N = 3: the source's best setting; variance preserved.
    fn default() -> Self {
        Blend {
            context: 1,
            top_n: 3,
            preserve_variance: true,
            appearance_gain: 1.0,
        }
    }
}

impl Blend {
    /// The per-phoneme mean baseline: no context, every occurrence averaged.
    pub const PHONE_MEAN: Blend = Blend {
        context: 0,
        top_n: usize::MAX,
        preserve_variance: false,
        appearance_gain: 1.0,
    };
}

/// Context phone at `offset` from position `i` (negative: left), `sil` beyond the edges.
fn context(segments: &[Segment], i: usize, offset: isize) -> Phone {
    let j = i as isize + offset;
    if j < 0 || j as usize >= segments.len() {
        Phone::SIL
    } else {
        segments[j as usize].phone
    }
}

/// Context score `s_j` of an occurrence for the target phone at `i` (eq. of \[blend\] §5).
pub fn context_score(
    codebook: &Codebook,
    target: &[Segment],
    i: usize,
    o: Occurrence,
    width: usize,
) -> f64 {
    let source = &codebook.sentences[o.sentence].segments;
    (1..=width)
        .map(|k| {
            let k_i = k as isize;
            (codebook.similarity(context(target, i, -k_i), context(source, o.segment, -k_i))
                + codebook.similarity(context(target, i, k_i), context(source, o.segment, k_i)))
                / (k + 1) as f64
        })
        .sum()
}

/// How much deeper than C the context is read to break ties: C = 1 ties often (every
/// occurrence between the same two phones scores alike).
pub const TIE_CONTEXT: usize = 2;

/// The N best-scoring occurrences of `phone` for target position `i`, best first, with their
/// scores. Ties on the score go to the occurrence whose duration is nearer the target's (by
/// |ln ratio|: less time-warping), then to the better context score read [`TIE_CONTEXT`]
/// phones deeper; never to a sentence's name or its place in the corpus, except as the last
/// resort between occurrences alike in all three.
pub fn select(
    codebook: &Codebook,
    target: &[Segment],
    i: usize,
    phone: Phone,
    blend: &Blend,
) -> Vec<(Occurrence, f64)> {
    let wanted = target[i].duration().max(1e-3);
    let warp = |o: Occurrence| {
        let d = codebook.sentences[o.sentence].segments[o.segment].duration();
        (d.max(1e-3) / wanted).ln().abs()
    };
    let deeper = (blend.context + TIE_CONTEXT).min(MAX_CONTEXT);
    let mut scored: Vec<(Occurrence, f64, f64, f64)> = codebook.occurrences[phone.index()]
        .iter()
        .map(|&o| {
            let score = context_score(codebook, target, i, o, blend.context);
            (o, score, warp(o), f64::NAN)
        })
        .collect();
    let cmp = |a: &(Occurrence, f64, f64, f64), b: &(Occurrence, f64, f64, f64)| {
        b.1.total_cmp(&a.1).then(a.2.total_cmp(&b.2))
    };
    scored.sort_by(cmp);
    // The deeper context is scored only where the first two keys tie at the cut.
    if let Some(last) = scored.get(blend.top_n.saturating_sub(1)).copied()
        && scored.len() > blend.top_n
    {
        for s in scored.iter_mut().filter(|s| cmp(s, &last).is_eq()) {
            s.3 = context_score(codebook, target, i, s.0, deeper);
        }
        scored.sort_by(|a, b| {
            cmp(a, b)
                .then(b.3.total_cmp(&a.3))
                .then((a.0.sentence, a.0.segment).cmp(&(b.0.sentence, b.0.segment)))
        });
    }
    scored.truncate(blend.top_n);
    scored.into_iter().map(|(o, s, ..)| (o, s)).collect()
}

impl Synthesiser for Blend {
    fn name(&self) -> String {
        let lively = if self.appearance_gain == 1.0 {
            String::new()
        } else {
            format!(", appearance ×{}", self.appearance_gain)
        };
        if *self == Blend::PHONE_MEAN {
            "per-phoneme mean".into()
        } else if self.preserve_variance {
            format!("blend C={} N={}{lively}", self.context, self.top_n)
        } else {
            format!("blend C={} N={} plain average{lively}", self.context, self.top_n)
        }
    }

    /// Synthesises a trajectory for `target` by top-N context blending.
    fn synthesise(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
    ) -> Result<Synthesis, SynthError> {
        options::count_in("top-n", self.top_n, 1, usize::MAX)?;
        options::count_in("context width", self.context, 0, MAX_CONTEXT)?;
        validate_request(target, fps)?;
        let dims = codebook.dims();
        let mut warnings = Vec::new();
        let mut phones = Vec::with_capacity(target.len());
        // Per target phone: (occurrence, weight) pairs.
        let mut mixes: Vec<Vec<(Occurrence, f64)>> = Vec::with_capacity(target.len());
        for (i, seg) in target.iter().enumerate() {
            let used =
                stand_in(codebook, seg.phone).ok_or(SynthError::NoFallback { phone: seg.phone })?;
            if used != seg.phone {
                let how = if used.viseme() == seg.phone.viseme() {
                    "its viseme class"
                } else {
                    "the nearest viseme class present, by mouth shape"
                };
                warnings.push(format!(
                    "phone {i} /{}/ at {:.2} s is absent from the codebook: used /{used}/ ({how})",
                    seg.phone, seg.start
                ));
            }
            if seg.duration() <= 0.0 {
                warnings.push(format!(
                    "phone {i} /{}/ has zero length and was skipped",
                    seg.phone
                ));
            }
            let chosen = select(codebook, target, i, used, self);
            let total: f64 = chosen.iter().map(|c| c.1).sum();
            let mix: Vec<(Occurrence, f64)> = chosen
                .iter()
                .map(|&(o, s)| {
                    (
                        o,
                        if total > 0.0 {
                            s / total
                        } else {
                            1.0 / chosen.len() as f64
                        },
                    )
                })
                .collect();
            phones.push(PhoneReport {
                phone: seg.phone,
                used,
                start: seg.start,
                end: seg.end,
                chosen: mix
                    .iter()
                    .zip(&chosen)
                    .map(|(&(o, w), &(_, s))| Chosen {
                        sentence: codebook.sentences[o.sentence].name.clone(),
                        segment: o.segment,
                        score: s,
                        weight: w,
                    })
                    .collect(),
            });
            mixes.push(mix);
        }
        let start = target[0].start;
        let times = super::frame_times(target, fps);
        let mut rows = vec![0f32; times.len() * dims];
        let mut acc = vec![0.0; dims];
        let mut value = vec![0.0; dims];
        // The means of the sentences the mixes draw on (a few of the codebook's hundreds),
        // each found once.
        let mut means = std::collections::HashMap::new();
        if self.preserve_variance {
            for (o, _) in mixes.iter().flatten() {
                means
                    .entry(o.sentence)
                    .or_insert_with(|| codebook.sentence_mean(o.sentence));
            }
        }
        let mut spread = Spread::new(dims);
        let mut seg = 0;
        for (row, &t) in rows.chunks_exact_mut(dims).zip(&times) {
            let t = t + start;
            // The target phone holding t (the last one for the final frame).
            while seg + 1 < target.len() && (t >= target[seg].end || target[seg].duration() <= 0.0)
            {
                seg += 1;
            }
            let s = &target[seg];
            acc.iter_mut().for_each(|a| *a = 0.0);
            for &(o, w) in &mixes[seg] {
                let g = codebook.segment(o);
                let warp = codebook.trajectories[o.sentence]
                    .warp(g.start, g.end, s.duration().max(1e-9))
                    .expect("valid segments");
                warp.eval_into((t - s.start).clamp(0.0, s.duration()), &mut value);
                acc.iter_mut().zip(&value).for_each(|(r, v)| *r += w * v);
                if self.preserve_variance {
                    spread.add_example(w, &value, &means[&o.sentence]);
                }
            }
            spread.add_weights(&mixes[seg]);
            row.iter_mut().zip(&acc).for_each(|(r, a)| *r = *a as f32);
        }
        if self.preserve_variance && !times.is_empty() {
            spread.restore(&mut rows, codebook.layout.shape_range());
            spread.restore(&mut rows, codebook.layout.appearance_range());
        }
        if self.appearance_gain != 1.0 {
            scale_about_mean(&mut rows, dims, codebook.layout.appearance_range(), self.appearance_gain);
        }
        Ok(Synthesis {
            frames: Frames::from_rows(codebook.layout, fps, rows)?,
            phones,
            warnings,
            selection: None,
        })
    }
}

/// Running sums for variance-preserving blending (module docs): per value, the examples'
/// weighted squared deviation from their sentences' means; and Σ_j w_j² per frame.
struct Spread {
    examples: Vec<f64>,
    weight_squares: f64,
    frames: usize,
}

impl Spread {
    fn new(dims: usize) -> Self {
        Spread {
            examples: vec![0.0; dims],
            weight_squares: 0.0,
            frames: 0,
        }
    }

    fn add_example(&mut self, w: f64, value: &[f64], mean: &[f64]) {
        for ((e, v), m) in self.examples.iter_mut().zip(value).zip(mean) {
            *e += w * (v - m) * (v - m);
        }
    }

    fn add_weights(&mut self, mix: &[(Occurrence, f64)]) {
        self.weight_squares += mix.iter().map(|(_, w)| w * w).sum::<f64>();
        self.frames += 1;
    }

    /// Scales the `group` columns of `rows` (frames × values) about their means by the group's
    /// gain `g`, at least 1 (a blend that moves as much as its examples is left alone) and at
    /// most `√N_eff`.
    fn restore(&self, rows: &mut [f32], group: std::ops::Range<usize>) {
        let dims = self.examples.len();
        let cap = (self.frames as f64 / self.weight_squares.max(f64::MIN_POSITIVE))
            .sqrt()
            .max(1.0);
        let means = group_means(rows, dims, group.clone());
        let blend: f64 = rows
            .chunks_exact(dims)
            .map(|r| {
                group
                    .clone()
                    .zip(&means)
                    .map(|(k, m)| (f64::from(r[k]) - m).powi(2))
                    .sum::<f64>()
            })
            .sum();
        let examples: f64 = self.examples[group.clone()].iter().sum();
        let gain = if blend > 0.0 && examples.is_finite() {
            (examples / blend).sqrt().clamp(1.0, cap)
        } else {
            1.0
        };
        scale_about(rows, dims, group, &means, gain);
    }
}

/// The mean of each `group` column of `rows` (frames × `dims` values).
fn group_means(rows: &[f32], dims: usize, group: std::ops::Range<usize>) -> Vec<f64> {
    let n = (rows.len() / dims).max(1) as f64;
    group
        .map(|k| rows.chunks_exact(dims).map(|r| f64::from(r[k])).sum::<f64>() / n)
        .collect()
}

/// Scales the `group` columns of `rows` about `means` by `gain`.
fn scale_about(rows: &mut [f32], dims: usize, group: std::ops::Range<usize>, means: &[f64], gain: f64) {
    for r in rows.chunks_exact_mut(dims) {
        for (k, m) in group.clone().zip(means) {
            r[k] = (m + gain * (f64::from(r[k]) - m)) as f32;
        }
    }
}

/// Scales the `group` columns of `rows` about their own means by `gain`.
fn scale_about_mean(rows: &mut [f32], dims: usize, group: std::ops::Range<usize>, gain: f64) {
    let means = group_means(rows, dims, group.clone());
    scale_about(rows, dims, group, &means, gain);
}
