//! The dynamic-phoneme graph (\[graph\] §3, DESIGN §8): units are "dynamic phonemes" —
//! from the centre of the previous phone to the centre of the next, an onset half and an
//! offset half about one central phone, voiced/voiceless consonant pairs merged (nasals kept
//! apart). Between the offset half of one unit and the onset half of the next, the transition
//! probability of a frame pair is `exp(−d/σ)` (σ = half the mean frame distance), averaged
//! along the diagonal over 3 frames so that motion matches too; each unit pair is stitched at
//! its most probable frame pair. Viterbi maximises the product of the transition
//! probabilities (minimises the sum of `−ln p`); consecutive units of one recording join with
//! probability 1, so recorded stretches are reused whole. The chosen units are scaled
//! linearly onto the target's phone centres, nearest frame, no interpolation.
//!
//! Frame distance: L2 over the face-space parameters, each standardised and weighted by its
//! share of its own model's variance (as for S) — a documented stand-in for \[graph\]'s
//! Haar-wavelet PCA features of the texture.

use serde::{Deserialize, Serialize};

use super::unit::{CodebookFrame, TargetCost, UnitConstants, selection_stats, visual_weights};
use super::viterbi::cheapest_path;
use super::{Chosen, PhoneReport, SynthError, Synthesis, Synthesiser, validate_request};
use crate::codebook::{Codebook, Occurrence};
use crate::options::{self, InvalidOption};
use crate::phonemes::{Phone, Segment};
use crate::rng::Rng;

/// The constants of the graph.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GraphConstants {
    /// Transitions less probable than this are pruned (unless no path is left).
    pub min_probability: f64,
    /// Frame pairs sampled to estimate the mean frame distance (σ is half of it).
    pub sigma_samples: usize,
    /// Candidate units kept per target phone, the best by context similarity (the blend's
    /// score, C = 1): the stitch search is quadratic in them, so a large codebook (GRID: 1 482
    /// silences) is cut to these; 0 keeps every one.
    #[serde(default = "default_max_candidates")]
    pub max_candidates: usize,
}

fn default_max_candidates() -> usize {
    100
}

impl Default for GraphConstants {
    fn default() -> Self {
        GraphConstants {
            min_probability: 1e-6,
            sigma_samples: 20_000,
            max_candidates: default_max_candidates(),
        }
    }
}

/// Dynamic-phoneme graph synthesis (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Graph {
    /// The constants.
    pub constants: GraphConstants,
}

/// The label a unit is found by: voiced/voiceless consonant pairs merged, nasals kept apart.
pub fn merged(p: Phone) -> Phone {
    let pairs = [
        ("b", "p"),
        ("d", "t"),
        ("g", "k"),
        ("v", "f"),
        ("z", "s"),
        ("dh", "th"),
        ("zh", "sh"),
        ("jh", "ch"),
    ];
    pairs
        .iter()
        .find(|(voiced, _)| Phone::parse(voiced) == Some(p))
        .and_then(|(_, voiceless)| Phone::parse(voiceless))
        .unwrap_or(p)
}

/// A dynamic phoneme of the codebook: its sentence and central segment, and its span
/// (onset start, centre, offset end) in seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Unit {
    sentence: usize,
    segment: usize,
    onset: f64,
    centre: f64,
    offset: f64,
}

fn centre(s: &Segment) -> f64 {
    0.5 * (s.start + s.end)
}

/// Every dynamic phoneme of the codebook (zero-length segments skipped), in sentence order.
fn units(codebook: &Codebook) -> Vec<Unit> {
    let mut out = Vec::new();
    for (si, s) in codebook.sentences.iter().enumerate() {
        let segs: Vec<(usize, &Segment)> = s
            .segments
            .iter()
            .enumerate()
            .filter(|(_, g)| g.duration() > 0.0)
            .collect();
        for (k, &(gi, g)) in segs.iter().enumerate() {
            out.push(Unit {
                sentence: si,
                segment: gi,
                onset: if k == 0 {
                    g.start
                } else {
                    centre(segs[k - 1].1)
                },
                centre: centre(g),
                offset: if k + 1 == segs.len() {
                    g.end
                } else {
                    centre(segs[k + 1].1)
                },
            });
        }
    }
    out
}

/// Standardised, block-weighted parameters of every codebook frame, for L2 distances.
struct Features {
    /// Per sentence, frames × d.
    rows: Vec<Vec<f32>>,
    d: usize,
}

impl Features {
    fn new(codebook: &Codebook) -> Self {
        // √(½ / V_model) per parameter: L2 over these is the S metric (DESIGN §7).
        let w = crate::codebook::parameter_weights(codebook);
        let scale: Vec<f32> = w.iter().map(|x| x.sqrt() as f32).collect();
        let start = codebook.layout.params_range().start;
        let rows = codebook
            .sentences
            .iter()
            .map(|s| {
                s.frames
                    .values()
                    .rows()
                    .into_iter()
                    .flat_map(|r| {
                        r.iter()
                            .skip(start)
                            .zip(&scale)
                            .map(|(v, k)| v * k)
                            .collect::<Vec<_>>()
                    })
                    .collect()
            })
            .collect();
        Features {
            rows,
            d: scale.len(),
        }
    }

    fn frames(&self, sentence: usize) -> usize {
        self.rows[sentence].len() / self.d.max(1)
    }

    fn distance(&self, a: (usize, usize), b: (usize, usize)) -> f64 {
        let d = self.d;
        let x = &self.rows[a.0][a.1 * d..(a.1 + 1) * d];
        let y = &self.rows[b.0][b.1 * d..(b.1 + 1) * d];
        x.iter()
            .zip(y)
            .map(|(p, q)| f64::from(p - q).powi(2))
            .sum::<f64>()
            .sqrt()
    }
}

/// Frames of `sentence` whose times lie in `[from, to]` (at least the nearest one).
fn frames_in(features: &Features, fps: f64, sentence: usize, from: f64, to: f64) -> Vec<usize> {
    let last = features.frames(sentence).saturating_sub(1);
    let a = ((from * fps).ceil() as usize).min(last);
    let b = ((to * fps).floor() as usize).clamp(a, last);
    (a..=b).collect()
}

/// The lattice of one target: candidate units per target phone and their stitches.
struct Lattice<'a> {
    codebook: &'a Codebook,
    units: Vec<Unit>,
    candidates: Vec<Vec<usize>>,
    features: Features,
    sigma: f64,
    min_probability: f64,
}

impl Lattice<'_> {
    /// The most probable stitch from unit `a`'s offset half to unit `b`'s onset half:
    /// (ln probability, frame of a, frame of b); probability 1 for consecutive units of one
    /// sentence. Logarithms throughout, so distant frames never underflow to "impossible".
    fn stitch(&self, a: usize, b: usize) -> (f64, usize, usize) {
        let (ua, ub) = (self.units[a], self.units[b]);
        let fps = self.codebook.fps;
        if ua.sentence == ub.sentence && b == a + 1 {
            let f = (ua.offset * fps).round() as usize;
            return (0.0, f, f);
        }
        let fa = frames_in(&self.features, fps, ua.sentence, ua.centre, ua.offset);
        let fb = frames_in(&self.features, fps, ub.sentence, ub.onset, ub.centre);
        let (na, nb) = (
            self.features.frames(ua.sentence) as isize,
            self.features.frames(ub.sentence) as isize,
        );
        let mut best = (f64::NEG_INFINITY, fa[0], fb[0]);
        for &x in &fa {
            for &y in &fb {
                // Averaged along the diagonal over 3 frames: similar motion, not only pose.
                // ln of the mean of exp(−d/σ), shifted by the smallest d/σ.
                let z: [f64; 3] = std::array::from_fn(|i| {
                    let delta = i as isize - 1;
                    let (xx, yy) = (
                        (x as isize + delta).clamp(0, na - 1) as usize,
                        (y as isize + delta).clamp(0, nb - 1) as usize,
                    );
                    self.features.distance((ua.sentence, xx), (ub.sentence, yy)) / self.sigma
                });
                let m = z.iter().copied().fold(f64::INFINITY, f64::min);
                let ln_p = -m + (z.iter().map(|v| (m - v).exp()).sum::<f64>() / 3.0).ln();
                if ln_p > best.0 {
                    best = (ln_p, x, y);
                }
            }
        }
        best
    }

    /// `−ln p` of the transition from unit `a` to unit `b`. With `prune`, improbable
    /// transitions and a unit followed by itself (a within-state loop) are cut; without, they
    /// stay as the fallback when nothing else connects (a repeated phone with one example).
    fn cost(&self, a: usize, b: usize, prune: bool) -> f64 {
        if prune && a == b {
            return f64::INFINITY;
        }
        let ln_p = self.stitch(a, b).0;
        if prune && ln_p < self.min_probability.ln() {
            f64::INFINITY
        } else {
            -ln_p
        }
    }
}

impl Graph {
    fn lattice<'a>(
        &self,
        codebook: &'a Codebook,
        target: &[Segment],
        warnings: &mut Vec<String>,
    ) -> Result<Lattice<'a>, SynthError> {
        let units = units(codebook);
        if units.is_empty() {
            return Err(SynthError::Empty);
        }
        let candidates: Vec<Vec<usize>> = target
            .iter()
            .enumerate()
            .map(|(k, g)| {
                let label = |u: &Unit| codebook.sentences[u.sentence].segments[u.segment].phone;
                let best = |mut found: Vec<usize>| -> Vec<usize> {
                    let cap = self.constants.max_candidates;
                    if cap > 0 && found.len() > cap {
                        let score = |i: usize| {
                            let u = &units[i];
                            let o = Occurrence { sentence: u.sentence, segment: u.segment };
                            super::blend::context_score(codebook, target, k, o, 1)
                        };
                        let mut scored: Vec<(usize, f64)> = found.iter().map(|&i| (i, score(i))).collect();
                        scored.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                        found = scored.into_iter().take(cap).map(|(i, _)| i).collect();
                        found.sort_unstable();
                    }
                    found
                };
                let same: Vec<usize> = (0..units.len())
                    .filter(|&i| merged(label(&units[i])) == merged(g.phone))
                    .collect();
                if !same.is_empty() {
                    return best(same);
                }
                let class: Vec<usize> = (0..units.len())
                    .filter(|&i| label(&units[i]).viseme() == g.phone.viseme())
                    .collect();
                if !class.is_empty() {
                    warnings.push(format!(
                        "phone {k} /{}/: no unit of its label; used its viseme class",
                        g.phone
                    ));
                    return best(class);
                }
                warnings.push(format!(
                    "phone {k} /{}/: no unit of its label or viseme class; every unit was a candidate",
                    g.phone
                ));
                best((0..units.len()).collect())
            })
            .collect();
        let features = Features::new(codebook);
        // σ: half the mean distance between frames, from a seeded sample of pairs.
        let sizes: Vec<usize> = (0..codebook.sentences.len())
            .map(|s| features.frames(s))
            .collect();
        let total: usize = sizes.iter().sum();
        let locate = |mut i: usize| -> (usize, usize) {
            for (s, &n) in sizes.iter().enumerate() {
                if i < n {
                    return (s, i);
                }
                i -= n;
            }
            (sizes.len() - 1, sizes[sizes.len() - 1] - 1)
        };
        let mut rng = Rng::new(0x0067_7261_7068);
        let samples = self.constants.sigma_samples.max(1);
        let mean = (0..samples)
            .map(|_| {
                let a = locate((rng.uniform() * total as f64) as usize);
                let b = locate((rng.uniform() * total as f64) as usize);
                features.distance(a, b)
            })
            .sum::<f64>()
            / samples as f64;
        Ok(Lattice {
            codebook,
            units,
            candidates,
            features,
            sigma: (0.5 * mean).max(f64::MIN_POSITIVE),
            min_probability: self.constants.min_probability,
        })
    }

    /// The chosen unit per target phone and the path's cost (`−ln` of its probability).
    fn choose(&self, lattice: &Lattice<'_>) -> Option<(Vec<usize>, f64)> {
        let sizes: Vec<usize> = lattice.candidates.iter().map(Vec::len).collect();
        let run = |prune: bool| {
            cheapest_path(
                &sizes,
                |_, _| 0.0,
                |k, p, c| {
                    lattice.cost(
                        lattice.candidates[k - 1][p],
                        lattice.candidates[k][c],
                        prune,
                    )
                },
            )
        };
        run(true).or_else(|| run(false)).map(|(path, cost)| {
            let units = path
                .iter()
                .enumerate()
                .map(|(k, &c)| lattice.candidates[k][c])
                .collect();
            (units, cost)
        })
    }
}

impl Synthesiser for Graph {
    fn name(&self) -> String {
        "dynamic-phoneme graph".into()
    }

    fn synthesise(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
    ) -> Result<Synthesis, SynthError> {
        options::in_range("min_probability", self.constants.min_probability, 0.0, 1.0)?;
        if self.constants.sigma_samples == 0 {
            return Err(InvalidOption::new("sigma_samples", 0, "at least 1").into());
        }
        validate_request(target, fps)?;
        // Zero-length target phones have no centre to scale to: they are left out.
        let target: Vec<Segment> = target
            .iter()
            .copied()
            .filter(|g| g.duration() > 0.0)
            .collect();
        let mut warnings = Vec::new();
        let lattice = self.lattice(codebook, &target, &mut warnings)?;
        let (chosen, cost) = self.choose(&lattice).ok_or(SynthError::Empty)?;
        let cb_fps = codebook.fps;
        let start = target[0].start;
        let times = super::frame_times(&target, fps);
        let centres: Vec<f64> = target.iter().map(centre).collect();
        let mut selection = Vec::with_capacity(times.len());
        for &t in &times {
            let t = start + t;
            // Between the centres of target phones k and k+1 (k = −1 before the first).
            let k = centres.partition_point(|&c| c <= t) as isize - 1;
            let frame_of = |u: usize, from: (f64, f64), to: (f64, f64)| -> CodebookFrame {
                // Linear map of target time `from` onto unit time `to`.
                let unit = lattice.units[u];
                let span = (from.1 - from.0).max(1e-9);
                let s = to.0 + (t - from.0) / span * (to.1 - to.0);
                let last = lattice.features.frames(unit.sentence).saturating_sub(1);
                CodebookFrame {
                    sentence: unit.sentence as u32,
                    frame: ((s * cb_fps).round().max(0.0) as usize).min(last) as u32,
                }
            };
            let u = |k: usize| lattice.units[chosen[k]];
            let frame = if k < 0 {
                let u0 = u(0);
                frame_of(
                    chosen[0],
                    (target[0].start, centres[0]),
                    (u0.onset, u0.centre),
                )
            } else if k as usize + 1 >= target.len() {
                let k = k as usize;
                let uk = u(k);
                frame_of(
                    chosen[k],
                    (centres[k], target[k].end),
                    (uk.centre, uk.offset),
                )
            } else {
                let k = k as usize;
                let (ua, ub) = (u(k), u(k + 1));
                let (_, fa, _) = lattice.stitch(chosen[k], chosen[k + 1]);
                let half = (ua.offset - ua.centre).max(1e-9);
                let rho = ((fa as f64 / cb_fps - ua.centre) / half).clamp(0.0, 1.0);
                let stitch = centres[k] + rho * (centres[k + 1] - centres[k]);
                let gap = (centres[k], centres[k + 1]);
                if t < stitch {
                    frame_of(chosen[k], gap, (ua.centre, ua.offset))
                } else {
                    frame_of(chosen[k + 1], gap, (ub.onset, ub.centre))
                }
            };
            selection.push(frame);
        }
        let tc = TargetCost::for_target(codebook, &UnitConstants::default(), &target, fps);
        let k = visual_weights(codebook);
        let stats = selection_stats(codebook, &k, &selection, |i| tc.at(i, selection[i]), cost);
        let phones = target
            .iter()
            .zip(&chosen)
            .map(|(g, &u)| {
                let unit = lattice.units[u];
                PhoneReport {
                    phone: g.phone,
                    used: codebook.sentences[unit.sentence].segments[unit.segment].phone,
                    start: g.start,
                    end: g.end,
                    chosen: vec![Chosen {
                        sentence: codebook.sentences[unit.sentence].name.clone(),
                        segment: unit.segment,
                        score: 0.0,
                        weight: 1.0,
                    }],
                }
            })
            .collect();
        Ok(Synthesis {
            frames: super::unit::selected_frames(codebook, &selection, fps)?,
            phones,
            warnings,
            selection: Some(stats),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codebook::SimilarityOptions;
    use crate::corpus::Sentence;
    use crate::facespace::Layout;

    /// A small random codebook: `n` sentences of three phones from a four-phone inventory.
    fn random_codebook(rng: &mut Rng, n: usize) -> Codebook {
        let layout = Layout::new(1, 2);
        let inventory = ["aa", "m", "b", "s"];
        let sentences: Vec<Sentence> = (0..n)
            .map(|k| {
                let segments: Vec<Segment> = (0..3)
                    .map(|i| Segment {
                        start: 0.12 * i as f64,
                        end: 0.12 * (i + 1) as f64,
                        phone: Phone::parse(inventory[(rng.uniform() * 4.0) as usize]).unwrap(),
                    })
                    .collect();
                let rows: Vec<f32> = (0..9)
                    .flat_map(|_| {
                        let mut r = vec![1.0, 0.0, 0.0, 0.0];
                        r.extend((0..3).map(|_| rng.range(-1.0, 1.0) as f32));
                        r
                    })
                    .collect();
                Sentence {
                    name: format!("s{k}"),
                    source: "random".into(),
                    frames: crate::facespace::Frames::from_rows(layout, 25.0, rows).unwrap(),
                    segments,
                }
            })
            .collect();
        Codebook::build(
            sentences,
            25.0,
            layout,
            None,
            SimilarityOptions::default(),
            &mut crate::no_progress,
        )
        .unwrap()
    }

    /// The graph's path is the most probable of all unit sequences: on small random
    /// codebooks every choice of candidate units is enumerated and costed (pruned
    /// transitions excluded while any path survives pruning, as the search does).
    #[test]
    fn graph_path_is_the_most_probable_of_every_path() {
        let (mut fallbacks, mut pruned_away) = (0, 0);
        for seed in 0..16u64 {
            let mut rng = Rng::new(seed);
            let cb = random_codebook(&mut rng, 3);
            let phones = ["aa", "m", "b", "s"];
            let target: Vec<Segment> = (0..3)
                .map(|i| Segment {
                    start: 0.1 * i as f64,
                    end: 0.1 * (i + 1) as f64,
                    phone: Phone::parse(phones[(rng.uniform() * 4.0) as usize]).unwrap(),
                })
                .collect();
            let graph = Graph {
                constants: GraphConstants {
                    // High enough that pruning bites on some seeds.
                    min_probability: 0.05,
                    ..GraphConstants::default()
                },
            };
            let lattice = graph.lattice(&cb, &target, &mut Vec::new()).unwrap();
            let (chosen, cost) = graph.choose(&lattice).unwrap();
            let path_cost = |path: &[usize], prune: bool| -> f64 {
                path.windows(2)
                    .map(|w| lattice.cost(w[0], w[1], prune))
                    .sum()
            };
            let mut best = [f64::INFINITY; 2];
            let pools = &lattice.candidates;
            for &a in &pools[0] {
                for &b in &pools[1] {
                    for &c in &pools[2] {
                        for (slot, prune) in [(0, true), (1, false)] {
                            best[slot] = best[slot].min(path_cost(&[a, b, c], prune));
                        }
                    }
                }
            }
            fallbacks += usize::from(best[0].is_infinite());
            pruned_away += usize::from(best[0].is_finite() && best[0] > best[1] + 1e-12);
            let expected = if best[0].is_finite() {
                best[0]
            } else {
                best[1]
            };
            assert!(
                (cost - expected).abs() < 1e-9,
                "seed {seed}: graph {cost}, brute force {expected}"
            );
            let own = path_cost(&chosen, best[0].is_finite());
            assert!(
                (own - cost).abs() < 1e-9,
                "seed {seed}: path costs {own}, reported {cost}"
            );
            // Merged labels: a /b/ target takes /p/ and /b/ units alike, and only them
            // while the codebook has any (else its viseme class, reported).
            let label = |u: usize| {
                let unit = lattice.units[u];
                cb.sentences[unit.sentence].segments[unit.segment].phone
            };
            for (k, g) in target.iter().enumerate() {
                let all = 0..lattice.units.len();
                let same = all.clone().any(|u| merged(label(u)) == merged(g.phone));
                let class = all.clone().any(|u| label(u).viseme() == g.phone.viseme());
                for &u in &pools[k] {
                    if same {
                        assert_eq!(merged(label(u)), merged(g.phone), "seed {seed}");
                    } else if class {
                        assert_eq!(label(u).viseme(), g.phone.viseme(), "seed {seed}");
                    }
                }
                if !same && !class {
                    assert_eq!(pools[k].len(), lattice.units.len(), "seed {seed}");
                }
            }
        }
        // Both branches ran: pruning that cut the overall cheapest path, and the unpruned
        // fallback when pruning (or a repeated single unit) left no path at all.
        assert!(
            fallbacks > 0 && pruned_away > 0,
            "{fallbacks} {pruned_away}"
        );
    }

    /// A phone repeated in the target with a single example in the codebook: the unit must
    /// follow itself, which only the unpruned fallback allows.
    #[test]
    fn a_repeated_phone_with_one_example_still_synthesises() {
        let mut rng = Rng::new(3);
        let mut cb = random_codebook(&mut rng, 1);
        let p = |s: &str| Phone::parse(s).unwrap();
        for (g, ph) in cb.sentences[0].segments.iter_mut().zip(["m", "aa", "s"]) {
            g.phone = p(ph);
        }
        let target: Vec<Segment> = (0..3)
            .map(|i| Segment {
                start: 0.1 * i as f64,
                end: 0.1 * (i + 1) as f64,
                phone: p("aa"),
            })
            .collect();
        let s = Graph::default().synthesise(&cb, &target, 25.0).unwrap();
        assert_eq!(s.frames.len(), 8);
        assert!(s.phones.iter().all(|r| r.used == p("aa")));
    }

    #[test]
    fn voicing_pairs_merge_and_nasals_stay_apart() {
        let p = |s: &str| Phone::parse(s).unwrap();
        assert_eq!(merged(p("b")), merged(p("p")));
        assert_eq!(merged(p("zh")), merged(p("sh")));
        assert_ne!(merged(p("m")), merged(p("n")));
        assert_ne!(merged(p("m")), merged(p("b")));
    }
}
