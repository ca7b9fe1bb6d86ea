//! Pareto training of the unit-selection weights (\[unitsel\] §6, DESIGN §8): a population of
//! weight vectors `(w_tc, w_cc, w_ccf, w_ccg)`, started from a seeded sample of a grid of 10
//! values per weight, evolves by non-dominated sorting (NSGA-II: rank, then crowding distance),
//! crossover and mutation on three objectives measured on validation sentences — average
//! target cost ↓ (lip sync), average segment length ↑ and average visual cost at joins ↓
//! (smoothness) — until the front stops improving: its hypervolume (the objective space it
//! dominates, scaled by the first generation's ranges) grows by less than `tolerance` for
//! `stable_generations` generations in a row. Of the final front, the point whose
//! syntheses correlate best with the real trajectories (mean of r_pca and r_h) is chosen.
//! Never run it on the test split.

use serde::Serialize;

use super::SynthError;
use super::unit::{Prepared, UnitConstants, UnitSelection, UnitWeights};
use crate::Progress;
use crate::codebook::Codebook;
use crate::corpus::Sentence;
use crate::eval;
use crate::model::FaceModel;
use crate::options;
use crate::rng::Rng;

/// The grid the population starts from: 10 values per weight, log-spaced over 10⁻²…10².
pub const GRID: [f64; 10] = [0.01, 0.028, 0.077, 0.22, 0.6, 1.7, 4.6, 13.0, 36.0, 100.0];

/// Options of [`train`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ParetoOptions {
    /// Seed of every random choice: same seed, same weights.
    pub seed: u64,
    /// Weight vectors per generation.
    pub population: usize,
    /// Generations at most.
    pub max_generations: usize,
    /// The front counts as stable after this many generations of little growth.
    pub stable_generations: usize,
    /// Relative hypervolume growth per generation below which the front counts as stable.
    pub tolerance: f64,
}

impl Default for ParetoOptions {
    fn default() -> Self {
        ParetoOptions {
            seed: 2009,
            population: 40,
            max_generations: 30,
            stable_generations: 3,
            tolerance: 1e-3,
        }
    }
}

/// One evaluated weight vector.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Candidate {
    /// The weights.
    pub weights: UnitWeights,
    /// Mean TC_avg over the sentences (↓).
    pub tc_avg: f64,
    /// Mean SL_avg (↑).
    pub sl_avg: f64,
    /// Mean VC_avg (↓).
    pub vc_avg: f64,
}

impl Candidate {
    /// Whether `self` is at least as good as `other` on every objective and better on one.
    pub fn dominates(&self, other: &Candidate) -> bool {
        let (a, b) = (self.objectives(), other.objectives());
        a.iter().zip(&b).all(|(x, y)| x <= y) && a.iter().zip(&b).any(|(x, y)| x < y)
    }

    /// The objectives as quantities to minimise.
    fn objectives(&self) -> [f64; 3] {
        [self.tc_avg, -self.sl_avg, self.vc_avg]
    }
}

/// The outcome of training.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Training {
    /// The chosen weights.
    pub chosen: Candidate,
    /// Its correlation with the real trajectories: (mean r_pca, mean r_h).
    pub correlation: (f64, f64),
    /// The final non-dominated front.
    pub front: Vec<Candidate>,
    /// Every weight vector evaluated, in order.
    pub evaluated: Vec<Candidate>,
    /// Generations run.
    pub generations: usize,
    /// The options used.
    pub options: ParetoOptions,
}

/// Fronts of a population by non-dominated sorting: `rank[i]` (0 = the Pareto front).
pub fn ranks(population: &[Candidate]) -> Vec<usize> {
    let n = population.len();
    let mut rank = vec![usize::MAX; n];
    let mut remaining: Vec<usize> = (0..n).collect();
    let mut r = 0;
    while !remaining.is_empty() {
        let front: Vec<usize> = remaining
            .iter()
            .copied()
            .filter(|&i| {
                !remaining
                    .iter()
                    .any(|&j| population[j].dominates(&population[i]))
            })
            .collect();
        for &i in &front {
            rank[i] = r;
        }
        remaining.retain(|i| !front.contains(i));
        r += 1;
    }
    rank
}

/// Crowding distance of each member within its front (NSGA-II): larger is lonelier.
fn crowding(population: &[Candidate], rank: &[usize]) -> Vec<f64> {
    let mut distance = vec![0.0; population.len()];
    let fronts = rank.iter().copied().max().map_or(0, |m| m + 1);
    for r in 0..fronts {
        let members: Vec<usize> = (0..population.len()).filter(|&i| rank[i] == r).collect();
        for m in 0..3 {
            let mut sorted = members.clone();
            sorted.sort_by(|&a, &b| {
                population[a].objectives()[m].total_cmp(&population[b].objectives()[m])
            });
            let (lo, hi) = (
                population[sorted[0]].objectives()[m],
                population[sorted[sorted.len() - 1]].objectives()[m],
            );
            distance[sorted[0]] = f64::INFINITY;
            distance[sorted[sorted.len() - 1]] = f64::INFINITY;
            if hi > lo {
                for w in sorted.windows(3) {
                    distance[w[1]] += (population[w[2]].objectives()[m]
                        - population[w[0]].objectives()[m])
                        / (hi - lo);
                }
            }
        }
    }
    distance
}

/// Objectives scaled to `[0, 1]` over a reference population (to be minimised).
struct Scale {
    lo: [f64; 3],
    span: [f64; 3],
}

impl Scale {
    fn of(population: &[Candidate]) -> Scale {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for c in population {
            for (m, v) in c.objectives().into_iter().enumerate() {
                lo[m] = lo[m].min(v);
                hi[m] = hi[m].max(v);
            }
        }
        let span = std::array::from_fn(|m| (hi[m] - lo[m]).max(1e-12));
        Scale { lo, span }
    }

    fn apply(&self, c: &Candidate) -> [f64; 3] {
        let o = c.objectives();
        std::array::from_fn(|m| (o[m] - self.lo[m]) / self.span[m])
    }
}

/// The volume of objective space (minimised) that `points` dominate up to `reference`:
/// slices along the third objective, each a 2-D staircase area. Points not better than the
/// reference in every objective add nothing. Exact; O(n² log n), for fronts of tens of points.
pub fn hypervolume(points: &[[f64; 3]], reference: [f64; 3]) -> f64 {
    let mut inside: Vec<[f64; 3]> = points
        .iter()
        .copied()
        .filter(|p| p.iter().zip(&reference).all(|(x, r)| x < r))
        .collect();
    inside.sort_by(|a, b| a[2].total_cmp(&b[2]));
    let mut volume = 0.0;
    for i in 0..inside.len() {
        let top = inside.get(i + 1).map_or(reference[2], |p| p[2]);
        let depth = top - inside[i][2];
        if depth > 0.0 {
            volume += depth * staircase_area(&inside[..=i], [reference[0], reference[1]]);
        }
    }
    volume
}

/// The 2-D area the points dominate (first two objectives, minimised) up to `reference`.
fn staircase_area(points: &[[f64; 3]], reference: [f64; 2]) -> f64 {
    let mut xy: Vec<(f64, f64)> = points.iter().map(|p| (p[0], p[1])).collect();
    xy.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let (mut area, mut best_y) = (0.0, reference[1]);
    for (k, &(x, y)) in xy.iter().enumerate() {
        if y < best_y {
            best_y = y;
        }
        let next_x = xy.get(k + 1).map_or(reference[0], |p| p.0);
        area += (next_x - x) * (reference[1] - best_y);
    }
    area
}

/// Trains the weights on `sentences` (a validation split) for `codebook`, the constants held.
pub fn train(
    model: &FaceModel,
    codebook: &Codebook,
    sentences: &[Sentence],
    constants: UnitConstants,
    options: &ParetoOptions,
    mut progress: impl FnMut(Progress),
) -> Result<Training, SynthError> {
    options::count_in("population", options.population, 4, 10_000)?;
    options::count_in("generations", options.max_generations, 1, 10_000)?;
    if sentences.is_empty() {
        return Err(SynthError::Empty);
    }
    let base = UnitSelection {
        weights: UnitWeights::default(),
        constants,
    };
    let fps = codebook.fps;
    let prepared: Vec<Prepared> = sentences
        .iter()
        .map(|s| base.prepare(codebook, &s.segments, fps))
        .collect::<Result<_, _>>()?;
    let evaluate = |weights: UnitWeights| -> Result<Candidate, SynthError> {
        let unit = UnitSelection { weights, constants };
        let (mut tc, mut sl, mut vc) = (0.0, 0.0, 0.0);
        for p in &prepared {
            let (_, stats) = unit.solve(codebook, p)?;
            tc += stats.tc_avg;
            sl += stats.sl_avg;
            vc += stats.vc_avg;
        }
        let n = prepared.len() as f64;
        Ok(Candidate {
            weights,
            tc_avg: tc / n,
            sl_avg: sl / n,
            vc_avg: vc / n,
        })
    };
    let mut rng = Rng::new(options.seed);
    let grid = |rng: &mut Rng| GRID[((rng.uniform() * GRID.len() as f64) as usize).min(9)];
    let mut evaluated = Vec::new();
    let mut population = Vec::with_capacity(options.population);
    for _ in 0..options.population {
        let w = UnitWeights {
            w_tc: grid(&mut rng),
            w_cc: grid(&mut rng),
            w_ccf: grid(&mut rng),
            w_ccg: grid(&mut rng),
        };
        let c = evaluate(w)?;
        evaluated.push(c);
        population.push(c);
    }
    // Hypervolume in objectives scaled to the first generation's ranges, from a reference
    // point 10 % beyond its worst values.
    let scale = Scale::of(&population);
    let volume = |pop: &[Candidate]| {
        let rank = ranks(pop);
        let front: Vec<[f64; 3]> = pop
            .iter()
            .zip(&rank)
            .filter(|(_, r)| **r == 0)
            .map(|(c, _)| scale.apply(c))
            .collect();
        hypervolume(&front, [1.1; 3])
    };
    let (mut last_volume, mut stable, mut generations) = (volume(&population), 0, 0);
    let bounds = (GRID[0] / 10.0, GRID[9] * 10.0);
    while generations < options.max_generations && stable < options.stable_generations {
        generations += 1;
        let rank = ranks(&population);
        let crowd = crowding(&population, &rank);
        let better =
            |a: usize, b: usize| rank[a] < rank[b] || (rank[a] == rank[b] && crowd[a] > crowd[b]);
        let tournament = |rng: &mut Rng| {
            let n = population.len();
            let (a, b) = (
                ((rng.uniform() * n as f64) as usize).min(n - 1),
                ((rng.uniform() * n as f64) as usize).min(n - 1),
            );
            if better(a, b) { a } else { b }
        };
        let mut offspring = Vec::with_capacity(options.population);
        for _ in 0..options.population {
            let (a, b) = (
                population[tournament(&mut rng)].weights,
                population[tournament(&mut rng)].weights,
            );
            // Crossover: each weight from a log-space blend of the parents; mutation: a
            // log-normal factor now and then.
            let mut child = |x: f64, y: f64| {
                let t = rng.uniform();
                let mut v = (x.ln() * t + y.ln() * (1.0 - t)).exp();
                if rng.uniform() < 0.3 {
                    v *= (0.7 * rng.normal()).exp();
                }
                v.clamp(bounds.0, bounds.1)
            };
            let w = UnitWeights {
                w_tc: child(a.w_tc, b.w_tc),
                w_cc: child(a.w_cc, b.w_cc),
                w_ccf: child(a.w_ccf, b.w_ccf),
                w_ccg: child(a.w_ccg, b.w_ccg),
            };
            let c = evaluate(w)?;
            evaluated.push(c);
            offspring.push(c);
        }
        // Environmental selection: the best `population` of parents and offspring.
        let mut all = population;
        all.extend(offspring);
        let rank = ranks(&all);
        let crowd = crowding(&all, &rank);
        let mut order: Vec<usize> = (0..all.len()).collect();
        order.sort_by(|&a, &b| {
            rank[a]
                .cmp(&rank[b])
                .then(crowd[b].total_cmp(&crowd[a]))
                .then(a.cmp(&b))
        });
        population = order
            .into_iter()
            .take(options.population)
            .map(|i| all[i])
            .collect();
        let v = volume(&population);
        let growth = (v - last_volume) / last_volume.max(f64::MIN_POSITIVE);
        stable = if growth < options.tolerance {
            stable + 1
        } else {
            0
        };
        last_volume = v;
        progress(Progress {
            stage: "evolving",
            done: generations,
            total: options.max_generations,
        });
    }
    // The front's point whose syntheses correlate best with the real trajectories.
    let rank = ranks(&population);
    let mut front: Vec<Candidate> = population
        .iter()
        .zip(&rank)
        .filter(|(_, r)| **r == 0)
        .map(|(c, _)| *c)
        .collect();
    let mut seen = Vec::new();
    front.retain(|c| {
        let key = c.weights;
        let new = !seen.contains(&key);
        seen.push(key);
        new
    });
    let mut best: Option<(f64, Candidate, (f64, f64))> = None;
    for c in &front {
        let unit = UnitSelection {
            weights: c.weights,
            constants,
        };
        let (mut r_pca, mut r_h) = (0.0, 0.0);
        for (p, s) in prepared.iter().zip(sentences) {
            let (selection, _) = unit.solve(codebook, p)?;
            let mut frames = super::unit::selected_frames(codebook, &selection, fps)?;
            for t in 0..frames.len().min(s.frames.len()) {
                frames.set_pose(t, s.frames.params(t).pose);
            }
            let scores = eval::score(model, &frames, &s.frames);
            r_pca += scores.r_pca / sentences.len() as f64;
            r_h += scores.r_h / sentences.len() as f64;
        }
        let key = 0.5 * (r_pca + r_h);
        if best.as_ref().is_none_or(|b| key > b.0) {
            best = Some((key, *c, (r_pca, r_h)));
        }
    }
    let (_, chosen, correlation) = best.ok_or(SynthError::Empty)?;
    Ok(Training {
        chosen,
        correlation,
        front,
        evaluated,
        generations,
        options: *options,
    })
}

impl Training {
    /// The front plot (\[unitsel\] Fig. 9): every weight vector evaluated (grey), the final
    /// front (blue) and the chosen point (red), TC_avg against VC_avg and against SL_avg.
    pub fn plot(&self) -> image::RgbImage {
        use crate::plot::{PALETTE, ScatterGroup, scatter, stack};
        let panel = |title: &str, y_label: &str, y: fn(&Candidate) -> f64| {
            let points = |cs: &[Candidate]| -> Vec<(f64, f64)> {
                cs.iter().map(|c| (c.tc_avg, y(c))).collect()
            };
            scatter(
                title,
                "TC_avg (target cost, lower = better lip sync)",
                y_label,
                &[
                    ScatterGroup {
                        label: "evaluated",
                        points: points(&self.evaluated),
                        color: image::Rgb([190, 190, 190]),
                        radius: 2,
                    },
                    ScatterGroup {
                        label: "Pareto front",
                        points: points(&self.front),
                        color: PALETTE[0],
                        radius: 3,
                    },
                    ScatterGroup {
                        label: "chosen (best correlation)",
                        points: points(std::slice::from_ref(&self.chosen)),
                        color: PALETTE[3],
                        radius: 5,
                    },
                ],
                900,
                320,
            )
        };
        stack(&[
            panel(
                "Pareto training: target cost against visual cost at joins",
                "VC_avg",
                |c| c.vc_avg,
            ),
            panel(
                "Pareto training: target cost against segment length",
                "SL_avg (frames)",
                |c| c.sl_avg,
            ),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(tc: f64, sl: f64, vc: f64) -> Candidate {
        Candidate {
            weights: UnitWeights::default(),
            tc_avg: tc,
            sl_avg: sl,
            vc_avg: vc,
        }
    }

    #[test]
    fn non_dominated_sorting_by_hand() {
        // b dominates a (lower TC, longer segments, same VC); c and b trade off; d is
        // dominated by everything.
        let pop = [
            c(2.0, 3.0, 1.0),
            c(1.0, 4.0, 1.0),
            c(0.5, 2.0, 0.5),
            c(3.0, 1.0, 2.0),
        ];
        assert!(pop[1].dominates(&pop[0]) && !pop[0].dominates(&pop[1]));
        assert!(!pop[1].dominates(&pop[2]) && !pop[2].dominates(&pop[1]));
        assert_eq!(ranks(&pop), vec![1, 0, 0, 2]);
        assert!(!pop[0].dominates(&pop[0]), "nothing dominates itself");
    }

    #[test]
    fn hypervolume_by_inclusion_exclusion() {
        let r = [1.0; 3];
        assert_eq!(hypervolume(&[], r), 0.0);
        // One point: a box.
        let a = [0.5, 0.25, 0.0];
        assert!((hypervolume(&[a], r) - 0.5 * 0.75 * 1.0).abs() < 1e-12);
        // Two boxes: |A| + |B| − |A ∩ B|, the intersection's corner the componentwise max.
        let b = [0.2, 0.6, 0.5];
        let boxed = |p: [f64; 3]| (1.0 - p[0]) * (1.0 - p[1]) * (1.0 - p[2]);
        let both = boxed(a) + boxed(b) - boxed([0.5, 0.6, 0.5]);
        assert!((hypervolume(&[a, b], r) - both).abs() < 1e-12);
        // A dominated point and one outside the reference add nothing.
        assert!((hypervolume(&[a, b, [0.6, 0.7, 0.6], [0.0, 0.0, 1.5]], r) - both).abs() < 1e-12);
    }

    #[test]
    fn hypervolume_matches_a_grid_count() {
        // Random points against counting the cells of a fine grid that some point dominates.
        let mut rng = Rng::new(7);
        let points: Vec<[f64; 3]> = (0..12)
            .map(|_| [rng.uniform(), rng.uniform(), rng.uniform()])
            .collect();
        let n = 80;
        let mut count = 0usize;
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    let c = [i, j, k].map(|v| (v as f64 + 0.5) / n as f64);
                    if points.iter().any(|p| (0..3).all(|m| p[m] <= c[m])) {
                        count += 1;
                    }
                }
            }
        }
        let grid = count as f64 / (n * n * n) as f64;
        let exact = hypervolume(&points, [1.0; 3]);
        assert!((exact - grid).abs() < 0.01, "exact {exact} vs grid {grid}");
    }
}
