//! `study analyse`: the tables of \[blend\] §6 and \[unitsel\] from the stored answers —
//! Wilcoxon signed-rank per rated pair (per viewer and pooled), Kruskal–Wallis across the
//! conditions' scores, and the Turing test's correct-identification rate with its exact 95 %
//! interval — plus a box plot of the scores per condition.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use super::stats::{self, Binomial, GroupRank, KruskalWallis, Wilcoxon};
use super::{Answer, Condition, Manifest, Response, StudyError, answers};
use crate::{atomic, plot, video};

/// Scores are stored on the 1–50 scale and reported on the ITU 1–5 one (÷10).
const TO_ITU: f64 = 0.1;

/// The Wilcoxon test of one rated pair.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairTest {
    /// The first condition (the reference).
    pub first: Condition,
    /// The second.
    pub second: Condition,
    /// All viewers' paired scores together (`None` without answers).
    pub pooled: Option<Wilcoxon>,
    /// Mean score of the first condition (1–5).
    pub mean_first: f64,
    /// Mean score of the second (1–5).
    pub mean_second: f64,
    /// Per viewer with answers for this pair.
    pub per_viewer: Vec<ViewerTest>,
}

/// One viewer's test of a pair.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewerTest {
    /// The viewer.
    pub viewer: String,
    /// The test.
    pub test: Wilcoxon,
    /// Mean score of the first condition (1–5).
    pub mean_first: f64,
    /// Mean score of the second (1–5).
    pub mean_second: f64,
}

/// The scores one condition received (1–5).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ConditionScores {
    /// The condition.
    pub condition: Condition,
    /// Scores.
    pub n: usize,
    /// Their mean.
    pub mean: f64,
    /// Their median.
    pub median: f64,
    /// Mean rank and z among all scores (Kruskal–Wallis).
    pub rank: Option<GroupRank>,
    /// The scores (1–5).
    pub scores: Vec<f64>,
}

/// One condition's Turing-test result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TuringRow {
    /// The condition.
    pub condition: Condition,
    /// Judgements.
    pub n: usize,
    /// How many said "real".
    pub judged_real: usize,
    /// Correct identifications (real for the original, synthetic otherwise), tested against ½.
    pub correct: Binomial,
}

/// The Turing test.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Turing {
    /// Every judgement: the correct-identification rate and its exact 95 % interval (½ =
    /// viewers cannot tell real from synthetic).
    pub overall: Binomial,
    /// Per condition.
    pub per_condition: Vec<TuringRow>,
}

/// Everything `study analyse` reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// Viewers in the study.
    pub viewers: usize,
    /// Viewers who answered every trial.
    pub complete_viewers: usize,
    /// Answers stored.
    pub answers: usize,
    /// Answers a complete study would hold.
    pub expected: usize,
    /// Per rated pair.
    pub pairs: Vec<PairTest>,
    /// Per condition, in the order given.
    pub conditions: Vec<ConditionScores>,
    /// Kruskal–Wallis across the conditions' scores.
    pub kruskal: Option<KruskalWallis>,
    /// The Turing test, when the study ran one.
    pub turing: Option<Turing>,
    /// Answers that came implausibly fast: sooner than the trial's clip lasts after it was
    /// fetched, or after the viewer's previous answer (kept in the tables; listed here).
    pub fast_answers: Vec<FastAnswer>,
    /// What the numbers do not show, and anything left out.
    pub notes: Vec<String>,
}

/// An answer given sooner than its clip could be watched.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FastAnswer {
    /// The viewer.
    pub viewer: String,
    /// Their trial.
    pub trial: usize,
    /// The longest of the trial's clips, in seconds.
    pub clip_seconds: f64,
    /// Seconds from the clip's fetch to the answer, when the log has it.
    pub after_fetch: Option<f64>,
    /// Seconds since the viewer's previous answer (none for their first).
    pub after_previous: Option<f64>,
}

/// The answers of `answers` sooner than their clips last (less the server's slack) after
/// the fetch or after the viewer's previous answer.
pub fn fast_answers(manifest: &Manifest, answers: &[Answer]) -> Vec<FastAnswer> {
    let slack = answers::ANSWER_SLACK_SECONDS;
    let mut previous: std::collections::HashMap<&str, f64> = Default::default();
    let mut fast = Vec::new();
    for a in answers {
        let clip_seconds = a
            .stimuli
            .iter()
            .filter_map(|id| manifest.stimulus(id))
            .map(|s| s.frames as f64 / manifest.fps)
            .fold(0.0, f64::max);
        let after_previous = previous.insert(&a.viewer, a.at).map(|p| a.at - p);
        let too_soon = |t: Option<f64>| t.is_some_and(|t| t + slack < clip_seconds);
        if too_soon(a.after_fetch) || too_soon(after_previous) {
            fast.push(FastAnswer {
                viewer: a.viewer.clone(),
                trial: a.trial,
                clip_seconds,
                after_fetch: a.after_fetch,
                after_previous,
            });
        }
    }
    fast
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Reads the study in `dir` and its answers and computes the report.
pub fn analyse(dir: &Path) -> Result<Report, StudyError> {
    let manifest = Manifest::load(dir)?;
    let (stored, note) = answers::read(dir, &manifest)?;
    if stored.is_empty() {
        return Err(StudyError::invalid(
            &dir.join(super::ANSWERS),
            "no answers stored yet: serve the study (facespace study serve) and send the viewers their links first",
        ));
    }
    let mut report = report(&manifest, &stored);
    report.notes.extend(note);
    Ok(report)
}

/// The report of `answers` to the study `manifest` (answers already checked against it).
pub fn report(manifest: &Manifest, answers: &[Answer]) -> Report {
    let condition = |id: &str| manifest.stimulus(id).map(|s| s.condition);
    let mut notes = Vec::new();
    // Rated pairs: (viewer, score of the pair's first condition, of its second).
    let mut paired: Vec<Vec<(String, f64, f64)>> = vec![Vec::new(); manifest.pairs.len()];
    let mut by_condition: Vec<Vec<f64>> = vec![Vec::new(); manifest.conditions.len()];
    let mut judged: Vec<(Condition, bool)> = Vec::new();
    for a in answers {
        let conditions: Vec<Option<Condition>> = a.stimuli.iter().map(|s| condition(s)).collect();
        match (&a.response, conditions.as_slice()) {
            (Response::Scores { scores }, [Some(x), Some(y)]) => {
                for (c, s) in [(x, scores[0]), (y, scores[1])] {
                    if let Some(i) = manifest.conditions.iter().position(|k| k == c) {
                        by_condition[i].push(s * TO_ITU);
                    }
                }
                if let Some(p) = manifest
                    .pairs
                    .iter()
                    .position(|&(f, g)| (f, g) == (*x, *y) || (f, g) == (*y, *x))
                {
                    let (first, second) = if manifest.pairs[p].0 == *x {
                        (scores[0], scores[1])
                    } else {
                        (scores[1], scores[0])
                    };
                    paired[p].push((a.viewer.clone(), first * TO_ITU, second * TO_ITU));
                }
            }
            (Response::Judgement { real }, [Some(c)]) => judged.push((*c, *real)),
            _ => notes.push(format!(
                "viewer {} trial {}: stimuli not in the manifest, left out",
                a.viewer, a.trial
            )),
        }
    }
    let pairs = manifest
        .pairs
        .iter()
        .zip(&paired)
        .map(|(&(first, second), rows)| {
            let a: Vec<f64> = rows.iter().map(|r| r.1).collect();
            let b: Vec<f64> = rows.iter().map(|r| r.2).collect();
            let per_viewer = manifest
                .viewers
                .iter()
                .filter_map(|v| {
                    let mine: Vec<&(String, f64, f64)> =
                        rows.iter().filter(|r| r.0 == v.id).collect();
                    let a: Vec<f64> = mine.iter().map(|r| r.1).collect();
                    let b: Vec<f64> = mine.iter().map(|r| r.2).collect();
                    stats::wilcoxon(&a, &b).map(|test| ViewerTest {
                        viewer: v.id.clone(),
                        test,
                        mean_first: mean(&a),
                        mean_second: mean(&b),
                    })
                })
                .collect();
            PairTest {
                first,
                second,
                pooled: stats::wilcoxon(&a, &b),
                mean_first: mean(&a),
                mean_second: mean(&b),
                per_viewer,
            }
        })
        .collect();
    let rated: Vec<Vec<f64>> = by_condition
        .iter()
        .filter(|g| !g.is_empty())
        .cloned()
        .collect();
    let kruskal = if rated.len() == by_condition.len() {
        stats::kruskal(&rated)
    } else {
        None
    };
    let conditions = manifest
        .conditions
        .iter()
        .zip(&by_condition)
        .enumerate()
        .map(|(i, (&condition, scores))| ConditionScores {
            condition,
            n: scores.len(),
            mean: mean(scores),
            median: plot::median(scores),
            rank: kruskal.as_ref().map(|k| k.groups[i]),
            scores: scores.clone(),
        })
        .collect();
    let turing = (!judged.is_empty()).then(|| {
        let correct = judged.iter().filter(|(c, r)| c.is_real() == *r).count();
        Turing {
            overall: stats::binomial(correct, judged.len()).expect("n > 0"),
            per_condition: manifest
                .conditions
                .iter()
                .filter_map(|&c| {
                    let mine: Vec<bool> = judged
                        .iter()
                        .filter(|(k, _)| *k == c)
                        .map(|(_, r)| *r)
                        .collect();
                    let real = mine.iter().filter(|&&r| r).count();
                    let correct = if c.is_real() { real } else { mine.len() - real };
                    stats::binomial(correct, mine.len()).map(|correct| TuringRow {
                        condition: c,
                        n: mine.len(),
                        judged_real: real,
                        correct,
                    })
                })
                .collect(),
        }
    });
    let expected: usize = manifest.viewers.iter().map(|v| v.trials.len()).sum();
    let complete_viewers = manifest
        .viewers
        .iter()
        .filter(|v| answers.iter().filter(|a| a.viewer == v.id).count() == v.trials.len())
        .count();
    if answers.len() < expected {
        notes.push(format!(
            "{} of {expected} answers stored ({complete_viewers} of {} viewers complete): the tests use what is there",
            answers.len(),
            manifest.viewers.len()
        ));
    }
    let fast = fast_answers(manifest, answers);
    if !fast.is_empty() {
        notes.push(format!(
            "{} of {} answers came sooner than their clip lasts (after its fetch or the viewer's previous answer): not watched through; listed in fast_answers",
            fast.len(),
            answers.len()
        ));
    }
    notes.push(
        "p-values are not corrected for the number of pairs tested; the Kruskal–Wallis test pools every viewer's scores as independent, which repeated viewers are not".into(),
    );
    Report {
        viewers: manifest.viewers.len(),
        complete_viewers,
        answers: answers.len(),
        expected,
        pairs,
        conditions,
        kruskal,
        turing,
        fast_answers: fast,
        notes,
    }
}

impl Report {
    /// The report as Markdown tables, like the papers'.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# Subjective study\n\n{} answers of {} expected; {} of {} viewers complete. Scores on the ITU 1–5 scale (the 1–50 slider ÷ 10).\n",
            self.answers, self.expected, self.complete_viewers, self.viewers
        );
        let p = |w: &Wilcoxon| {
            format!(
                "{} | {} | {} | {:.4} | {:.2} | {}",
                w.n, w.nonzero, w.w, w.p, w.z, w.method
            )
        };
        if !self.pairs.is_empty() {
            let _ = writeln!(
                s,
                "## A/B rating: Wilcoxon signed-rank per pair\n\n| pair | viewer | mean 1st | mean 2nd | N | n≠0 | W | p | Z | method |\n|---|---|---|---|---|---|---|---|---|---|"
            );
            for t in &self.pairs {
                let name = format!("{} vs {}", t.first, t.second);
                for v in &t.per_viewer {
                    let _ = writeln!(
                        s,
                        "| {name} | {} | {:.2} | {:.2} | {} |",
                        v.viewer,
                        v.mean_first,
                        v.mean_second,
                        p(&v.test)
                    );
                }
                if let Some(w) = &t.pooled {
                    let _ = writeln!(
                        s,
                        "| **{name}** | **pooled** | {:.2} | {:.2} | {} |",
                        t.mean_first,
                        t.mean_second,
                        p(w)
                    );
                }
            }
            let _ = writeln!(s);
        }
        if !self.conditions.is_empty() && self.conditions.iter().any(|c| c.n > 0) {
            let _ = writeln!(s, "## Scores per condition: Kruskal–Wallis\n");
            if let Some(k) = &self.kruskal {
                let _ = writeln!(s, "H = {:.3}, df = {}, p = {:.3e}\n", k.h, k.df, k.p);
            }
            let _ = writeln!(
                s,
                "| condition | n | mean | median | mean rank | Z |\n|---|---|---|---|---|---|"
            );
            for c in &self.conditions {
                let (rank, z) = c.rank.map_or(("–".into(), "–".into()), |r| {
                    (format!("{:.1}", r.mean_rank), format!("{:.2}", r.z))
                });
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.2} | {:.2} | {rank} | {z} |",
                    c.condition, c.n, c.mean, c.median
                );
            }
            let _ = writeln!(s);
        }
        if let Some(t) = &self.turing {
            let _ = writeln!(
                s,
                "## Turing test: real or synthetic?\n\n| condition | judgements | judged real | correct | rate | 95 % interval | p (rate = ½) |\n|---|---|---|---|---|---|---|"
            );
            let row = |name: &str, n: usize, real: String, b: &Binomial| {
                format!(
                    "| {name} | {n} | {real} | {} | {:.3} | {:.3} – {:.3} | {:.4} |",
                    b.k, b.rate, b.low, b.high, b.p
                )
            };
            for r in &t.per_condition {
                let _ = writeln!(
                    s,
                    "{}",
                    row(
                        &r.condition.to_string(),
                        r.n,
                        r.judged_real.to_string(),
                        &r.correct
                    )
                );
            }
            let _ = writeln!(
                s,
                "{}\n",
                row("**all**", t.overall.n, "".into(), &t.overall)
            );
        }
        let _ = writeln!(s, "## Notes\n");
        for n in &self.notes {
            let _ = writeln!(s, "- {n}");
        }
        s
    }
}

/// Writes `report.json`, `report.md` and `scores.png` (a box plot per condition) into `dir`,
/// staged and swapped in whole.
pub fn write_report(dir: &Path, report: &Report) -> Result<(), StudyError> {
    let io = |source| StudyError::Io {
        path: dir.into(),
        source,
    };
    atomic::replace_dir(
        dir,
        "study report",
        |staged| {
            let json = serde_json::to_vec_pretty(report).expect("the report serialises");
            atomic::write_file(&staged.join("report.json"), &json).map_err(io)?;
            atomic::write_file(&staged.join("report.md"), report.markdown().as_bytes())
                .map_err(io)?;
            let (labels, groups): (Vec<String>, Vec<Vec<f64>>) = report
                .conditions
                .iter()
                .map(|c| (c.condition.to_string(), c.scores.clone()))
                .unzip();
            if groups.iter().any(|g| !g.is_empty()) {
                let labels: Vec<&str> = labels.iter().map(String::as_str).collect();
                let image = plot::box_plot(
                    "Naturalness scores per condition",
                    "score (ITU 1–5)",
                    &labels,
                    &groups,
                );
                video::write_png(&staged.join("scores.png"), &image)?;
            }
            Ok(())
        },
        io,
    )
}
