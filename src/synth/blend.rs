//! Top-N context blending ([blend] §5, DESIGN §8).
//!
//! For each target phone p with left context l₁…l_C and right context r₁…r_C, every codebook
//! occurrence j of p is scored `s_j = Σᵢ S(lᵢ, l_ij)/(i+1) + Σᵢ S(rᵢ, r_ij)/(i+1)` (beyond a
//! sentence edge the context is `sil`). The N best are time-warped to the target duration and
//! averaged with weights `s_j / Σ s`; phones are concatenated and sampled at the frame rate.

use serde::Serialize;
use thiserror::Error;

use crate::codebook::{Codebook, Occurrence};
use crate::phonemes::{Phone, Segment};
use crate::trajectory::frame_times;

#[derive(Debug, Error, PartialEq)]
pub enum SynthError {
    #[error("nothing to synthesise: the target has no phones")]
    Empty,
    #[error("target phone {index} ({phone}) has a negative or non-finite duration")]
    BadSegment { index: usize, phone: Phone },
    #[error("target phones overlap or are out of order at phone {0}")]
    Unsorted(usize),
    #[error(
        "phone {phone} is absent from the codebook and no phone of its viseme class is present"
    )]
    NoFallback { phone: Phone },
    #[error("invalid option: {0}")]
    Options(String),
}

/// Options of [`blend`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct BlendOptions {
    /// Context width C (1 = triphone).
    pub context: usize,
    /// Examples averaged per phone, N.
    pub top_n: usize,
    /// Output frame rate.
    pub fps: f64,
}

impl Default for BlendOptions {
    fn default() -> Self {
        BlendOptions {
            context: 1,
            top_n: 3,
            fps: 25.0,
        }
    }
}

/// One example chosen for a target phone.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Chosen {
    pub sentence: String,
    pub segment: usize,
    pub score: f64,
    pub weight: f64,
}

/// What was done for one target phone.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PhoneReport {
    pub phone: Phone,
    /// The phone whose examples were used (differs from `phone` after a fallback).
    pub used: Phone,
    pub start: f64,
    pub end: f64,
    pub chosen: Vec<Chosen>,
}

/// A synthesised trajectory: frames at `fps` and what was chosen.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Synthesis {
    pub fps: f64,
    pub dims: usize,
    /// `frames × dims`, row-major.
    #[serde(skip)]
    pub frames: Vec<f64>,
    pub phones: Vec<PhoneReport>,
    /// Human-readable notes: fallbacks, skipped zero-length phones.
    pub warnings: Vec<String>,
}

impl Synthesis {
    pub fn n_frames(&self) -> usize {
        self.frames.len() / self.dims
    }

    pub fn times(&self) -> Vec<f64> {
        (0..self.n_frames()).map(|i| i as f64 / self.fps).collect()
    }
}

/// Checks the target: non-empty, finite non-negative durations, in order.
pub fn validate_target(target: &[Segment]) -> Result<(), SynthError> {
    if target.is_empty() {
        return Err(SynthError::Empty);
    }
    for (index, s) in target.iter().enumerate() {
        if !(s.start.is_finite() && s.end.is_finite()) || s.end < s.start || s.start < 0.0 {
            return Err(SynthError::BadSegment {
                index,
                phone: s.phone,
            });
        }
        if index > 0 && s.start < target[index - 1].end - 1e-9 {
            return Err(SynthError::Unsorted(index));
        }
    }
    if target.iter().all(|s| s.duration() <= 0.0) {
        return Err(SynthError::Empty);
    }
    Ok(())
}

/// The phone whose examples stand in for `p`: itself if present, else the most frequent
/// present phone of its viseme class (S has no row for a phone the corpus never shows).
pub fn stand_in(codebook: &Codebook, p: Phone) -> Option<Phone> {
    if !codebook.occurrences[p.index()].is_empty() {
        return Some(p);
    }
    codebook
        .present()
        .into_iter()
        .filter(|q| q.viseme() == p.viseme())
        .max_by_key(|q| (codebook.occurrences[q.index()].len(), std::cmp::Reverse(*q)))
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

/// Context score `s_j` of an occurrence for the target phone at `i` (eq. of [blend] §5).
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

/// The N best-scoring occurrences of `phone` for target position `i`, best first (ties: the
/// earlier occurrence), with their scores.
pub fn select(
    codebook: &Codebook,
    target: &[Segment],
    i: usize,
    phone: Phone,
    options: &BlendOptions,
) -> Vec<(Occurrence, f64)> {
    let mut scored: Vec<(Occurrence, f64)> = codebook.occurrences[phone.index()]
        .iter()
        .map(|&o| (o, context_score(codebook, target, i, o, options.context)))
        .collect();
    scored.sort_by(|a, b| b.1.total_cmp(&a.1));
    scored.truncate(options.top_n);
    scored
}

/// Synthesises a trajectory for `target` by top-N context blending.
pub fn blend(
    codebook: &Codebook,
    target: &[Segment],
    options: &BlendOptions,
) -> Result<Synthesis, SynthError> {
    if options.top_n == 0 || !(options.fps > 0.0 && options.fps.is_finite()) {
        return Err(SynthError::Options(format!(
            "top-n {} and fps {} must be positive",
            options.top_n, options.fps
        )));
    }
    validate_target(target)?;
    let dims = codebook.dims();
    let mut warnings = Vec::new();
    let mut phones = Vec::with_capacity(target.len());
    // Per target phone: (occurrence, weight) pairs.
    let mut mixes: Vec<Vec<(Occurrence, f64)>> = Vec::with_capacity(target.len());
    for (i, seg) in target.iter().enumerate() {
        let used =
            stand_in(codebook, seg.phone).ok_or(SynthError::NoFallback { phone: seg.phone })?;
        if used != seg.phone {
            warnings.push(format!(
                "phone {i} /{}/ is absent from the codebook: used /{used}/ (same viseme class)",
                seg.phone
            ));
        }
        if seg.duration() <= 0.0 {
            warnings.push(format!(
                "phone {i} /{}/ has zero length and was skipped",
                seg.phone
            ));
        }
        let chosen = select(codebook, target, i, used, options);
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
    let (start, end) = (target[0].start, target[target.len() - 1].end);
    let times = frame_times(end - start, options.fps);
    let mut frames = vec![0.0; times.len() * dims];
    let mut value = vec![0.0; dims];
    let mut seg = 0;
    for (row, &t) in frames.chunks_exact_mut(dims).zip(&times) {
        let t = t + start;
        // The target phone holding t (the last one for the final frame).
        while seg + 1 < target.len() && (t >= target[seg].end || target[seg].duration() <= 0.0) {
            seg += 1;
        }
        let s = &target[seg];
        for &(o, w) in &mixes[seg] {
            let g = codebook.segment(o);
            let warp = codebook.trajectories[o.sentence]
                .warp(g.start, g.end, s.duration().max(1e-9))
                .expect("valid segments");
            warp.eval_into((t - s.start).clamp(0.0, s.duration()), &mut value);
            row.iter_mut().zip(&value).for_each(|(r, v)| *r += w * v);
        }
    }
    Ok(Synthesis {
        fps: options.fps,
        dims,
        frames,
        phones,
        warnings,
    })
}
