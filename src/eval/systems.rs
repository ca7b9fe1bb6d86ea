//! The systems a held-out evaluation compares (DESIGN §9): a synthesiser with or without
//! the smoothing spline, scored sentence by sentence against the real trajectories.

use serde::Serialize;

use super::{Scores, mean_scores, score};
use crate::codebook::Codebook;
use crate::corpus::Sentence;
use crate::model::FaceModel;
use crate::synth::blend::Blend;
use crate::synth::{Smoothing, SynthError, Synthesiser, synthesise};

/// One row of an evaluation: a synthesiser and its smoothing.
pub struct System {
    /// The row's name.
    pub name: String,
    /// What synthesises.
    pub synthesiser: Box<dyn Synthesiser + Sync>,
    /// Smoothing weight λ, or none.
    pub smoothing: Option<f64>,
}

impl System {
    /// A row named after the synthesiser and smoothing.
    pub fn new(synthesiser: impl Synthesiser + Sync + 'static, smoothing: Option<f64>) -> Self {
        let name = match smoothing {
            Some(l) => format!("{}, smoothed λ={l:e}", synthesiser.name()),
            None => format!("{}, unsmoothed", synthesiser.name()),
        };
        System {
            name,
            synthesiser: Box::new(synthesiser),
            smoothing,
        }
    }

    /// The default comparison: the blend (C = 1, N = 3) smoothed at `lambda` and unsmoothed,
    /// N = 1 unsmoothed, and the per-phoneme mean.
    pub fn standard(lambda: f64) -> Vec<System> {
        vec![
            System::new(Blend::default(), Some(lambda)),
            System::new(Blend::default(), None),
            System::new(
                Blend {
                    top_n: 1,
                    ..Blend::default()
                },
                None,
            ),
            System::new(Blend::PHONE_MEAN, None),
        ]
    }
}

/// One system's scores.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SystemScores {
    /// The system's name.
    pub system: String,
    /// Mean over the sentences.
    pub mean: Scores,
    /// Per sentence, in order.
    pub per_sentence: Vec<Scores>,
}

/// Synthesises every held-out sentence from its own phone timings with each system and scores
/// it against the sentence's real frames.
pub fn evaluate(
    model: &FaceModel,
    codebook: &Codebook,
    heldout: &[Sentence],
    systems: &[System],
) -> Result<Vec<SystemScores>, SynthError> {
    systems
        .iter()
        .map(|system| {
            let smoothing = system.smoothing.map_or(Smoothing::Off, Smoothing::On);
            let per_sentence = heldout
                .iter()
                .map(|s| {
                    let u = synthesise(
                        system.synthesiser.as_ref(),
                        codebook,
                        s.segments.clone(),
                        codebook.fps,
                        smoothing,
                    )?;
                    Ok(score(model, u.variants()[0].1, &s.frames))
                })
                .collect::<Result<Vec<_>, SynthError>>()?;
            Ok(SystemScores {
                system: system.name.clone(),
                mean: mean_scores(&per_sentence),
                per_sentence,
            })
        })
        .collect()
}

/// Mean over sentences of the real trajectories' mouth-height standard deviation (the
/// articulation amplitude the systems should match).
pub fn real_mouth_sd(model: &FaceModel, heldout: &[Sentence]) -> f64 {
    let scores: Vec<Scores> = heldout
        .iter()
        .map(|s| score(model, &s.frames, &s.frames))
        .collect();
    mean_scores(&scores).mouth_sd_px
}
