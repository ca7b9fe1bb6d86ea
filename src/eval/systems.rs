//! The systems a held-out evaluation compares (DESIGN §9, \[blend\] §6): the blend with N = 1,
//! 3 and 5 examples, the per-phoneme mean and random lips, each smoothed and unsmoothed — the
//! same smoothing for every row, its λ chosen on a validation split that is never reported.

use serde::Serialize;

use super::mouth::{MouthPc, flicker, inner_mouth_height};
use super::{Scores, landmarks, mean_scores, pearson, score, standard_deviation};
use crate::codebook::Codebook;
use crate::corpus::Sentence;
use crate::model::FaceModel;
use crate::synth::blend::Blend;
use crate::synth::graph::Graph;
use crate::synth::random::RandomLips;
use crate::synth::unit::UnitSelection;
use crate::synth::{Pose, Request, Smoothing, SynthError, Synthesiser, synthesise};

/// The smoothing weights tried on the validation split.
pub const LAMBDA_GRID: [f64; 7] = [1e-6, 3e-6, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3];

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

    /// The comparison of \[blend\] §6 with fair baselines: blend C = 1 with N = 1, 3, 5, the
    /// per-phoneme mean, random lips, unit selection (`unit`) and the dynamic-phoneme graph,
    /// each smoothed at `lambda` and unsmoothed; and blend N = 5 by the plain average, to show
    /// what variance preservation changes.
    pub fn comparison(lambda: f64, unit: UnitSelection) -> Vec<System> {
        let mut rows = Vec::new();
        for smoothing in [Some(lambda), None] {
            rows.push(System::new(unit, smoothing));
            rows.push(System::new(Graph::default(), smoothing));
            for n in [1, 3, 5] {
                rows.push(System::new(
                    Blend {
                        top_n: n,
                        ..Blend::default()
                    },
                    smoothing,
                ));
            }
            rows.push(System::new(
                Blend {
                    top_n: 5,
                    preserve_variance: false,
                    ..Blend::default()
                },
                smoothing,
            ));
            rows.push(System::new(Blend::PHONE_MEAN, smoothing));
            rows.push(System::new(RandomLips { seed: 7 }, smoothing));
        }
        rows
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
    /// For systems that select codebook frames: mean TC_avg, SL_avg and VC_avg over the
    /// sentences (\[unitsel\] eq. 12–15).
    pub selection: Option<SelectionMeans>,
    /// The mouth measures on recorded talkers (\[unitsel\] §7), when the model has lips.
    pub mouth: Option<MouthScores>,
}

/// \[unitsel\] §7's measures, means over the sentences.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MouthScores {
    /// Eq. 16: Pearson r of the first principal component of the photometrically normalised
    /// mouth-region appearance (the PCA fitted on the real held-out frames).
    pub r_pca_mouth: f64,
    /// Pearson r of the inner-mouth height.
    pub r_h_inner: f64,
    /// Synthesised over real inner-mouth height s.d. (articulation amplitude kept).
    pub inner_sd_ratio: f64,
    /// Per appearance parameter, the synthesised within-sentence s.d. over the real one's.
    pub flicker: Vec<f64>,
    /// The largest of `flicker`.
    pub flicker_worst: f64,
}

/// Means of the selection measures over sentences.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SelectionMeans {
    /// Mean target cost per frame.
    pub tc_avg: f64,
    /// Mean run length (frames).
    pub sl_avg: f64,
    /// Mean visual cost between consecutive frames.
    pub vc_avg: f64,
}

/// Synthesises every held-out sentence from its own phone timings with each system and scores
/// it against the sentence's real frames.
pub fn evaluate(
    model: &FaceModel,
    codebook: &Codebook,
    heldout: &[Sentence],
    systems: &[System],
) -> Result<Vec<SystemScores>, SynthError> {
    let real: Vec<&crate::facespace::Frames> = heldout.iter().map(|s| &s.frames).collect();
    let pc = MouthPc::fit(model, &real);
    let inner = |f: &crate::facespace::Frames| -> Vec<f64> {
        landmarks(model, f)
            .iter()
            .map(|p| inner_mouth_height(p))
            .collect()
    };
    systems
        .iter()
        .map(|system| {
            let smoothing = system.smoothing.map_or(Smoothing::Off, Smoothing::On);
            let mut selections = Vec::new();
            let mut mouth = Vec::new();
            let per_sentence = heldout
                .iter()
                .map(|s| {
                    // The real sentence's own poses: the measures compare shape and appearance.
                    let request = Request {
                        pose: Pose::Replay(s.frames.iter().map(|p| p.pose).collect()),
                        ..Request::new(s.segments.clone(), codebook.fps, smoothing)
                    };
                    let u = synthesise(system.synthesiser.as_ref(), codebook, request)?;
                    if let Some(stats) = &u.synthesis.selection {
                        selections.push((stats.tc_avg, stats.sl_avg, stats.vc_avg));
                    }
                    let synth = u.variants()[0].1;
                    if let Some(pc) = &pc {
                        let n = synth.len().min(s.frames.len());
                        let (a, b) = (synth.slice(0..n), s.frames.slice(0..n));
                        let (hi_s, hi_r) = (inner(&a), inner(&b));
                        mouth.push((
                            pearson(&pc.series(&a), &pc.series(&b)),
                            pearson(&hi_s, &hi_r),
                            standard_deviation(&hi_s) / standard_deviation(&hi_r).max(1e-9),
                            flicker(&a, &b),
                        ));
                    }
                    Ok(score(model, synth, &s.frames))
                })
                .collect::<Result<Vec<_>, SynthError>>()?;
            let n = selections.len().max(1) as f64;
            let selection = (!selections.is_empty()).then(|| SelectionMeans {
                tc_avg: selections.iter().map(|s| s.0).sum::<f64>() / n,
                sl_avg: selections.iter().map(|s| s.1).sum::<f64>() / n,
                vc_avg: selections.iter().map(|s| s.2).sum::<f64>() / n,
            });
            let m = mouth.len().max(1) as f64;
            let mouth = (!mouth.is_empty()).then(|| {
                let dims = mouth[0].3.len();
                let flicker: Vec<f64> = (0..dims)
                    .map(|k| mouth.iter().map(|x| x.3[k]).sum::<f64>() / m)
                    .collect();
                MouthScores {
                    r_pca_mouth: mouth.iter().map(|x| x.0).sum::<f64>() / m,
                    r_h_inner: mouth.iter().map(|x| x.1).sum::<f64>() / m,
                    inner_sd_ratio: mouth.iter().map(|x| x.2).sum::<f64>() / m,
                    flicker_worst: flicker.iter().copied().fold(0.0, f64::max),
                    flicker,
                }
            });
            Ok(SystemScores {
                system: system.name.clone(),
                mean: mean_scores(&per_sentence),
                per_sentence,
                selection,
                mouth,
            })
        })
        .collect()
}

/// The smoothing weight chosen on a validation split, with the scores of every weight tried.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SmoothingChoice {
    /// The λ with the lowest mean DTW.
    pub lambda: f64,
    /// Every λ tried, with its mean scores on the validation sentences.
    pub grid: Vec<(f64, Scores)>,
}

/// Chooses λ for `synthesiser` on `validation` (sentences never reported): the grid value
/// with the lowest mean DTW to the real trajectories (DTW weighs the whole trajectory, shape
/// and appearance, where r_pca sees one parameter).
pub fn choose_smoothing(
    model: &FaceModel,
    codebook: &Codebook,
    validation: &[Sentence],
    synthesiser: impl Synthesiser + Sync + Clone + 'static,
    grid: &[f64],
) -> Result<SmoothingChoice, SynthError> {
    let systems: Vec<System> = grid
        .iter()
        .map(|&l| System::new(synthesiser.clone(), Some(l)))
        .collect();
    let scores = evaluate(model, codebook, validation, &systems)?;
    let grid: Vec<(f64, Scores)> = grid
        .iter()
        .zip(&scores)
        .map(|(&l, s)| (l, s.mean))
        .collect();
    let lambda = grid
        .iter()
        .min_by(|a, b| a.1.dtw.total_cmp(&b.1.dtw))
        .map_or(crate::synth::DEFAULT_SMOOTHING, |g| g.0);
    Ok(SmoothingChoice { lambda, grid })
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
