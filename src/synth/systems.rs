//! The systems a held-out evaluation compares (DESIGN §9, \[blend\] §6): the blend with N = 1,
//! 3 and 5 examples, the per-phoneme mean and random lips, each smoothed and unsmoothed — the
//! same smoothing for every row, its λ chosen on a validation split that is never reported.

use serde::Serialize;

use super::blend::Blend;
use super::graph::Graph;
use super::random::RandomLips;
use super::unit::UnitSelection;
use super::{Pose, Request, Smoothing, SynthError, Synthesiser, synthesise};
use crate::codebook::Codebook;
use crate::corpus::Sentence;
use crate::eval::mouth::{MouthPc, flicker, inner_mouth_height, lip_motion};
use crate::eval::{Scores, landmarks, mean_scores, pearson, score, standard_deviation};
use crate::model::FaceModel;

/// The smoothing weights tried on the validation split.
pub const LAMBDA_GRID: [f64; 7] = [1e-6, 3e-6, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3];

/// One row of an evaluation: a synthesiser and its smoothing.
pub struct System {
    /// The row's name.
    pub name: String,
    /// What synthesises.
    pub synthesiser: Box<dyn Synthesiser>,
    /// Smoothing weight λ, or none.
    pub smoothing: Option<f64>,
}

impl System {
    /// A row named after the synthesiser and smoothing.
    pub fn new(synthesiser: impl Synthesiser + 'static, smoothing: Option<f64>) -> Self {
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
    /// Synthesised over real lip motion ([`lip_motion`]: how fast the mouth moves).
    pub lip_motion_ratio: f64,
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
                            lip_motion(model, &a) / lip_motion(model, &b).max(1e-12),
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
                    lip_motion_ratio: mouth.iter().map(|x| x.4).sum::<f64>() / m,
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
    synthesiser: impl Synthesiser + Clone + 'static,
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
        .map_or(super::DEFAULT_SMOOTHING, |g| g.0);
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

/// Blend N tried when a talker's settings are chosen ([`choose_settings`]).
pub const TOP_N_GRID: [usize; 4] = [3, 5, 8, 12];

/// λ tried when a talker's settings are chosen; 0 is no smoothing.
pub const SETTINGS_LAMBDA_GRID: [f64; 8] = [0.0, 1e-7, 3e-7, 1e-6, 3e-6, 1e-5, 3e-5, 1e-4];

/// The least lip motion, over real, a talker's settings may keep (issue 33: a mouth that
/// moves as fast as the talker's, not a smoothed average of it).
pub const MOTION_FLOOR: f64 = 0.9;

/// How far the inner-mouth height's s.d. may stray from real, as a fraction.
pub const AMPLITUDE_BAND: f64 = 0.1;

/// One blend setting scored on the validation sentences.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SettingsTrial {
    /// Examples blended per phone, N.
    pub top_n: usize,
    /// Smoothing weight λ (0: none).
    pub smoothing: f64,
    /// Its mouth measures, means over the validation sentences.
    pub mouth: MouthScores,
}

impl SettingsTrial {
    /// What the choice maximises: the mean of mouth r_pca (eq. 16) and inner r_h.
    pub fn correlation(&self) -> f64 {
        0.5 * (self.mouth.r_pca_mouth + self.mouth.r_h_inner)
    }

    /// How far it falls short of the motion floor and the amplitude band (0: within both).
    pub fn shortfall(&self) -> f64 {
        (MOTION_FLOOR - self.mouth.lip_motion_ratio).max(0.0)
            + ((self.mouth.inner_sd_ratio - 1.0).abs() - AMPLITUDE_BAND).max(0.0)
    }
}

/// The blend settings chosen for a talker on validation sentences, with every trial.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SettingsChoice {
    /// The chosen trial.
    pub chosen: SettingsTrial,
    /// Whether it keeps the lip motion and amplitude (else it is the one nearest to them).
    pub within_bounds: bool,
    /// How many validation sentences chose it.
    pub sentences: usize,
    /// Every trial, N-major.
    pub trials: Vec<SettingsTrial>,
}

impl SettingsChoice {
    /// The rule of [`choose_settings`] over scored trials: of those within the motion floor
    /// and the amplitude band, the best correlated; when none is, the one falling least short,
    /// then the best correlated. `None` without trials.
    pub fn from_trials(trials: Vec<SettingsTrial>, sentences: usize) -> Option<Self> {
        let chosen = trials
            .iter()
            .min_by(|a, b| {
                a.shortfall()
                    .total_cmp(&b.shortfall())
                    .then(b.correlation().total_cmp(&a.correlation()))
            })?
            .clone();
        Some(SettingsChoice {
            within_bounds: chosen.shortfall() == 0.0,
            chosen,
            sentences,
            trials,
        })
    }

    /// The rule and its outcome in words, for a talker's `chosen_on`.
    pub fn describe(&self, split: &str) -> String {
        let c = &self.chosen;
        let bounds = if self.within_bounds {
            "the best mean of mouth r_pca (eq. 16) and inner r_h among the settings keeping"
        } else {
            "none kept both, so the nearest to keeping"
        };
        format!(
            "blend C=1 N={} λ={:e} on {} validation sentences ({split}): {bounds} lip motion ≥ {MOTION_FLOOR}× and inner s.d. within {:.0} % of real (r_pca {:.3}, r_h {:.3}, motion {:.2}×, s.d. {:.2}×)",
            c.top_n,
            c.smoothing,
            self.sentences,
            AMPLITUDE_BAND * 100.0,
            c.mouth.r_pca_mouth,
            c.mouth.r_h_inner,
            c.mouth.lip_motion_ratio,
            c.mouth.inner_sd_ratio
        )
    }
}

/// Chooses a talker's blend N and λ (C = 1) on `validation` (sentences kept out of the
/// codebook and never reported): of the settings whose lip motion is at least
/// [`MOTION_FLOOR`] of real and whose inner-mouth s.d. is within [`AMPLITUDE_BAND`], the one
/// with the best mean of mouth r_pca (eq. 16) and inner r_h — correlation alone picks heavy
/// smoothing that halves how fast the mouth moves (BENCHMARKS "Say"). When none keeps both,
/// the one falling least short, then the best correlated. `None` when the model has no lips
/// (not a 68-point face) to measure.
pub fn choose_settings(
    model: &FaceModel,
    codebook: &Codebook,
    validation: &[Sentence],
    tops: &[usize],
    lambdas: &[f64],
) -> Result<Option<SettingsChoice>, SynthError> {
    if validation.is_empty() {
        return Ok(None);
    }
    let mut systems = Vec::new();
    for &top_n in tops {
        for &l in lambdas {
            let blend = Blend {
                top_n,
                ..Blend::default()
            };
            systems.push(System::new(blend, (l > 0.0).then_some(l)));
        }
    }
    let scores = evaluate(model, codebook, validation, &systems)?;
    let mut trials = Vec::new();
    for ((top_n, smoothing), s) in tops
        .iter()
        .flat_map(|&n| lambdas.iter().map(move |&l| (n, l)))
        .zip(scores)
    {
        match s.mouth {
            Some(mouth) => trials.push(SettingsTrial {
                top_n,
                smoothing,
                mouth,
            }),
            None => return Ok(None),
        }
    }
    Ok(SettingsChoice::from_trials(trials, validation.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(top_n: usize, r: f64, sd: f64, motion: f64) -> SettingsTrial {
        SettingsTrial {
            top_n,
            smoothing: 0.0,
            mouth: MouthScores {
                r_pca_mouth: r,
                r_h_inner: r,
                inner_sd_ratio: sd,
                lip_motion_ratio: motion,
                flicker: vec![1.0],
                flicker_worst: 1.0,
            },
        }
    }

    /// The best correlated of the trials within bounds wins over better correlated ones out
    /// of them (too slow, too small, too large); with none within, the nearest.
    #[test]
    fn settings_keep_the_motion_then_correlate() {
        let trials = vec![
            trial(1, 0.90, 1.0, 0.70),
            trial(2, 0.85, 1.0, 0.95),
            trial(3, 0.88, 1.0, 0.91),
            trial(4, 0.95, 0.85, 1.0),
            trial(5, 0.95, 1.15, 1.0),
        ];
        let c = SettingsChoice::from_trials(trials, 7).unwrap();
        assert_eq!(c.chosen.top_n, 3);
        assert!(c.within_bounds);
        assert_eq!((c.sentences, c.trials.len()), (7, 5));
        assert!(c.describe("here").contains("N=3"));
        let c = SettingsChoice::from_trials(
            vec![trial(1, 0.9, 1.0, 0.5), trial(2, 0.8, 1.0, 0.8), trial(3, 0.95, 1.0, 0.8)],
            1,
        )
        .unwrap();
        assert_eq!(c.chosen.top_n, 3);
        assert!(!c.within_bounds);
        assert!(c.describe("here").contains("nearest"));
        assert!(SettingsChoice::from_trials(Vec::new(), 0).is_none());
    }
}
