//! The talker's own ear: a classifier of the acoustic model's context-independent phones
//! from the map's evidence windows (±100 ms and ±300 ms heard unheard words no better:
//! BENCHMARKS "The talker's own ear"), learnt on the codebook's recordings and their aligned
//! phones. The general acoustic model was trained on American read speech; one hidden layer
//! learnt on an hour of this talker hears their own phones far better — in the words their
//! recordings hold: on words it never heard it does worse than the general model
//! (BENCHMARKS "The talker's own ear"). Its posteriors over
//! the phones' priors are scaled likelihoods `ln P(q | x) − ln P(q)` that replace the
//! acoustic model's in the phone loop: the hybrid recogniser of Bourlard & Morgan
//! (Connectionist Speech Recognition, 1994, ch. 7).

use nalgebra::DMatrix;

use super::network::{self, Hidden, Schedule, Target};
use super::{Heard, window_into};
use crate::align::WordFit;
use crate::align::model::AcousticModel;
use crate::phonemes::Segment;

/// Units, passes and annealing: not tuned — the map's layer's units, half its passes (there
/// are four times the examples); the first choice gave PER 6.8 % on GRID s1's validation
/// split.
pub const SCHEDULE: Schedule = Schedule {
    units: 256,
    epochs: 6,
    anneal_from: 4,
};

/// The phone bigram's weight and the phone insertion penalty of the loop the classifier's
/// scores go through (GRID s1 validation: PER 6.8 % at 0.5 / 0, 7.3 % with no bigram at
/// all, 8.8 % at 1.5 / −2 — the classifier's ±200 ms window already hears the context).
pub const LOOP_WEIGHT: f64 = 0.5;
/// See [`LOOP_WEIGHT`].
pub const LOOP_PENALTY: f64 = 0.0;

/// How much of the worst word's fit joins the whole recording's in [`ear_fit`].
pub const WORST_WORD_WEIGHT: f64 = 0.1;
/// How much of the general acoustic model's whole-recording fit ([`crate::align::WordFit`]
/// against its own free loop) joins the ear's in [`ear_fit`]: two hearings judge the words.
/// The weight and [`LEAST_FIT`] are the line with the widest margin between GRID s1
/// validation's true transcripts and other sentences' (each fit in units of its s.d. over
/// them), its threshold midway between the closest of each (BENCHMARKS "The talker's own ear").
pub const GENERAL_FIT_WEIGHT: f64 = 0.75;
/// Least [`ear_fit`] of words that match their sound, nats per frame.
pub const LEAST_FIT: f64 = -0.040;

/// Who judges given words where a talker's ear may ([`ear_matches`]).
pub const EAR_JUDGE: &str = "the talker's own ear beside the general acoustic model";

/// Fewest examples of a phone in the talker's recordings for its ear to judge words holding
/// it (issue 66): a classifier learnt on none or a handful of a phone cannot say whether it
/// was said, so words with such a phone are judged by the general model alone. A floor set
/// before any measurement, not tuned: GRID s1 has hundreds of every phone his words hold.
pub const EAR_LEAST_EXAMPLES: usize = 5;

/// How well words fit their sound, heard by the classifier (`ear`) and by the general
/// acoustic model (`general`): the ear's whole-recording fit plus [`WORST_WORD_WEIGHT`] times
/// its worst word's (one wrong word among right ones pulls the whole little, itself much),
/// plus [`GENERAL_FIT_WEIGHT`] times the general model's whole-recording fit.
pub fn ear_fit(ear: &WordFit, general: &WordFit) -> f64 {
    let worst = ear.words.iter().copied().fold(f64::INFINITY, f64::min);
    let worst = if worst.is_finite() { WORST_WORD_WEIGHT * worst } else { 0.0 };
    ear.overall + worst + GENERAL_FIT_WEIGHT * general.overall
}

/// Whether words match their sound as the classifier and the general model hear them:
/// [`ear_fit`] at least [`LEAST_FIT`].
pub fn ear_matches(ear: &WordFit, general: &WordFit) -> bool {
    ear_fit(ear, general) >= LEAST_FIT
}

/// Every `STRIDE`-th 10 ms frame is an example: neighbours say almost the same.
const STRIDE: usize = 2;

/// Frames a phone needs in the examples to be heard at all; a rarer one scores
/// [`UNHEARD`] (its prior is too poorly known to divide by).
const LEAST_FRAMES: usize = 20;
/// The score of a phone the classifier never learnt (fillers among them).
const UNHEARD: f32 = -1e4;

/// A learnt classifier (see the module).
#[derive(Clone, Debug)]
pub struct PhoneClassifier {
    /// The layer, standardisation folded in: log-odds `relu([x, 1]·input)·output + bias`.
    pub(super) hidden: Hidden,
    /// Per phone: the outputs' bias, then `ln P(q)` ([`UNHEARD`] where unheard), as rows.
    pub(super) bias_and_prior: DMatrix<f32>,
}

/// The context-independent phone of each 10 ms frame of `frames` under `segments` (its
/// middle inside the segment), `None` outside them or for a phone the acoustic model lacks.
pub fn frame_labels(segments: &[Segment], frames: usize, model: &AcousticModel) -> Vec<Option<u8>> {
    let ci: Vec<Option<u8>> = segments
        .iter()
        .map(|s| {
            let name = if s.phone == crate::phonemes::Phone::SIL { "SIL" } else { s.phone.name() };
            model.ci(name).map(|c| c as u8)
        })
        .collect();
    let mut at = 0;
    (0..frames)
        .map(|t| {
            let middle = (t as f64 + 0.5) * crate::align::FRAME_SECONDS;
            while at < segments.len() && segments[at].end <= middle {
                at += 1;
            }
            segments
                .get(at)
                .filter(|s| s.start <= middle)
                .and_then(|_| ci[at])
        })
        .collect()
}

impl PhoneClassifier {
    /// Learns the classifier over `classes` phones on `heard` (each sentence's evidence and
    /// frame labels), its inputs standardised by `mean` and `scale`; `progress` is told each
    /// pass.
    pub(super) fn learn(
        heard: &[Heard],
        classes: usize,
        (mean, scale): (&[f32], &[f32]),
        progress: impl FnMut(usize),
    ) -> PhoneClassifier {
        let index: Vec<(usize, usize)> = heard
            .iter()
            .enumerate()
            .flat_map(|(s, h)| (0..h.labels.len()).step_by(STRIDE).map(move |t| (s, t)))
            .collect();
        let labels: Vec<Option<u8>> = index.iter().map(|&(s, t)| heard[s].labels[t]).collect();
        let examples = network::Examples {
            rows: index.len(),
            features: mean.len(),
            row: |i: usize, out: &mut [f32]| {
                let (s, t) = index[i];
                window_into(&heard[s].evidence, t as i64, out);
            },
            mean,
            scale,
            target: Target::Classes {
                labels: &labels,
                classes,
            },
        };
        let (hidden, bias) = network::learn(&examples, SCHEDULE, progress);
        let mut counts = vec![0usize; classes];
        for c in labels.iter().flatten() {
            counts[usize::from(*c)] += 1;
        }
        let total = counts.iter().sum::<usize>().max(1) as f32;
        let bias_and_prior = DMatrix::from_fn(2, classes, |r, c| match r {
            0 => bias[c],
            _ if counts[c] < LEAST_FRAMES => UNHEARD,
            _ => (counts[c] as f32 / total).ln(),
        });
        PhoneClassifier {
            hidden,
            bias_and_prior,
        }
    }

    /// Per frame of `x` (design rows: windows and the constant), each phone's scaled
    /// log-likelihood `ln P(q | x) − ln P(q)`; [`UNHEARD`] for a phone never learnt.
    pub(super) fn scores(&self, x: &DMatrix<f32>) -> Vec<Vec<f32>> {
        let classes = self.bias_and_prior.ncols();
        let mut logits = DMatrix::from_fn(x.nrows(), classes, |_, c| self.bias_and_prior[(0, c)]);
        self.hidden.add_to(x, &mut logits);
        logits
            .row_iter()
            .map(|row| {
                let top = row.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
                let log_z = top + row.iter().map(|v| (v - top).exp()).sum::<f32>().ln();
                row.iter()
                    .enumerate()
                    .map(|(c, v)| {
                        let prior = self.bias_and_prior[(1, c)];
                        if prior <= UNHEARD { UNHEARD } else { v - log_z - prior }
                    })
                    .collect()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phonemes::Phone;

    /// Analytic: the ear's whole fit plus a tenth of its worst word's plus three quarters of
    /// the general model's whole fit; no words, the wholes alone.
    #[test]
    fn the_ears_fit_weighs_in_the_worst_word_and_the_general_fit() {
        let fit = |words: Vec<f64>, overall| WordFit { words, overall };
        let general = fit(vec![-9.0], 0.4);
        assert!((ear_fit(&fit(vec![-1.0, -3.0, 0.5], -0.2), &general) - (-0.2 - 0.3 + 0.3)).abs() < 1e-12);
        assert!((ear_fit(&fit(Vec::new(), -0.2), &general) - 0.1).abs() < 1e-12);
        assert!(ear_matches(&fit(Vec::new(), -0.2), &general));
        assert!(!ear_matches(&fit(Vec::new(), -0.2), &fit(Vec::new(), 0.0)));
    }

    /// Each 10 ms frame takes the segment holding its middle; frames past the last segment
    /// have none.
    #[test]
    fn frames_take_the_phone_over_their_middle() {
        let Ok(aligner) = crate::align::Aligner::load_default(&[]) else {
            panic!("the committed acoustic model loads");
        };
        let model = &aligner.model;
        let seg = |p: &str, start: f64, end: f64| Segment {
            phone: Phone::parse(p).unwrap(),
            start,
            end,
        };
        let segments = [seg("sil", 0.0, 0.02), seg("b", 0.02, 0.051), seg("aa", 0.051, 0.07)];
        let labels = frame_labels(&segments, 9, model);
        let ci = |n: &str| model.ci(n).map(|c| c as u8);
        assert_eq!(
            labels,
            vec![ci("SIL"), ci("SIL"), ci("B"), ci("B"), ci("B"), ci("AA"), ci("AA"), None, None]
        );
    }
}
