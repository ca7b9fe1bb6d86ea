//! Frame-level unit selection (\[unitsel\] §5, DESIGN §8): every output frame is a real
//! codebook frame, chosen by Viterbi over one candidate list per frame — the codebook frames
//! of the target phone's viseme class — minimising the path cost
//! `PC = w_tc·Σ TC + w_cc·Σ (w_ccf·f + w_ccg·g)`:
//!
//! * target cost (eq. 1) `TC(i,u) = (1/Σv) Σ_{t=−n..n} v_t · M(T_{i+t}, P_{u+t})`,
//!   `v_t = e^{β₁|t|}`: how well the phone context of codebook frame u matches the target's
//!   around frame i, through the phoneme distance matrix M;
//! * visual cost (eq. 7) `f = Σ_d k_d |U1_d − U2_d|` between the frames at a join, each
//!   parameter standardised and weighted by its share of its own model's variance (shape and
//!   appearance ½ each, as for S), 0 between consecutive frames of one sentence;
//! * skip cost (eq. 8) `g`: 0 for the next frame of the same sentence, `w_1` for the same
//!   frame again, `w_i = e^{β₃ i}` for a forward jump of i < p, `w_p` for a jump ≥ p, a
//!   backward jump or another sentence.
//!
//! A beam keeps the B candidates of lowest target cost per frame (BENCHMARKS.md measures
//! what it costs in path cost).

use serde::{Deserialize, Serialize};

use super::viterbi::cheapest_path;
use super::{Chosen, PhoneReport, SynthError, Synthesis, Synthesiser, validate_request};
use crate::codebook::{Codebook, phone_at};
use crate::facespace::Frames;
use crate::options::{self, InvalidOption};
use crate::phonemes::{Phone, Segment};

/// The four weights of the path cost (\[unitsel\] §6 trains them; every one ≥ 0).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitWeights {
    /// Weight of the target costs.
    pub w_tc: f64,
    /// Weight of the concatenation costs.
    pub w_cc: f64,
    /// Weight of the visual cost within a concatenation cost.
    pub w_ccf: f64,
    /// Weight of the skip cost within a concatenation cost.
    pub w_ccg: f64,
}

impl Default for UnitWeights {
    fn default() -> Self {
        UnitWeights {
            w_tc: 1.0,
            w_cc: 1.0,
            w_ccf: 1.0,
            w_ccg: 1.0,
        }
    }
}

impl UnitWeights {
    /// Checks every weight: finite and ≥ 0.
    pub fn validate(&self) -> Result<(), InvalidOption> {
        for (name, v) in [
            ("w_tc", self.w_tc),
            ("w_cc", self.w_cc),
            ("w_ccf", self.w_ccf),
            ("w_ccg", self.w_ccg),
        ] {
            options::in_range(name, v, 0.0, f64::MAX)?;
        }
        Ok(())
    }
}

/// The constants of unit selection, with \[unitsel\]'s values by default.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UnitConstants {
    /// β₁ of the target cost's context weights `v_t = e^{β₁|t|}` (−0.3).
    pub beta1: f64,
    /// Context frames either side at 25 fps, n (5; scaled with the frame rate: 10 at 50 fps).
    pub context_at_25fps: usize,
    /// β₃ of the skip costs `w_i = e^{β₃ i}` (0.6).
    pub beta3: f64,
    /// Jumps of p frames or more cost `w_p` (5).
    pub p: usize,
    /// Candidates kept per frame, lowest target cost first (0: all).
    pub beam: usize,
}

impl Default for UnitConstants {
    fn default() -> Self {
        UnitConstants {
            beta1: -0.3,
            context_at_25fps: 5,
            beta3: 0.6,
            p: 5,
            beam: 60,
        }
    }
}

impl UnitConstants {
    /// Checks every constant's range.
    pub fn validate(&self) -> Result<(), InvalidOption> {
        options::in_range("beta1", self.beta1, -10.0, 0.0)?;
        options::count_in("context_at_25fps", self.context_at_25fps, 0, 100)?;
        options::in_range("beta3", self.beta3, 0.0, 10.0)?;
        options::count_in("p", self.p, 2, 1000)?;
        Ok(())
    }
}

/// A frame of the codebook: sentence and frame index.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct CodebookFrame {
    /// Index into the codebook's sentences.
    pub sentence: u32,
    /// Frame within it.
    pub frame: u32,
}

/// How a selection fared (\[unitsel\] eq. 12–15), for a synthesiser that picks codebook
/// frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SelectionStats {
    /// Mean target cost per frame (lip sync).
    pub tc_avg: f64,
    /// Mean length of the runs of consecutive frames of one sentence (frames).
    pub sl_avg: f64,
    /// Mean visual cost over consecutive output frames (0 inside a run: smoothness).
    pub vc_avg: f64,
    /// The path cost the search minimised.
    pub path_cost: f64,
    /// The runs, in order: (sentence name, first frame, length).
    pub segments: Vec<(String, u32, u32)>,
}

/// Frame-level unit selection (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UnitSelection {
    /// The path-cost weights.
    pub weights: UnitWeights,
    /// The constants.
    pub constants: UnitConstants,
}

/// Per-parameter weights `k_d` of the visual cost on absolute differences over
/// `layout.params_range()`: each parameter standardised (÷ σ_d) and weighted by its share of
/// its own model's variance, the two models ½ each — `½ σ_d / V_model`.
pub fn visual_weights(codebook: &Codebook) -> Vec<f64> {
    let layout = codebook.layout;
    let d = layout.params_range().len();
    let (mut sum, mut sq, mut n) = (vec![0.0; d], vec![0.0; d], 0.0);
    for s in &codebook.sentences {
        for row in s.frames.values().rows() {
            for (k, &v) in row.iter().skip(layout.params_range().start).enumerate() {
                sum[k] += f64::from(v);
                sq[k] += f64::from(v) * f64::from(v);
            }
            n += 1.0;
        }
    }
    let var: Vec<f64> = (0..d)
        .map(|k| (sq[k] / n - (sum[k] / n).powi(2)).max(0.0))
        .collect();
    let blocks = [0..layout.shape, layout.shape..d];
    let mut k = vec![0.0; d];
    for block in blocks {
        let total: f64 = var[block.clone()].iter().sum();
        if total > 0.0 {
            for i in block {
                k[i] = 0.5 * var[i].sqrt() / total;
            }
        }
    }
    k
}

/// The visual cost between two codebook frames.
fn visual(codebook: &Codebook, k: &[f64], a: CodebookFrame, b: CodebookFrame) -> f64 {
    let start = codebook.layout.params_range().start;
    let ra = codebook.sentences[a.sentence as usize]
        .frames
        .row(a.frame as usize);
    let rb = codebook.sentences[b.sentence as usize]
        .frames
        .row(b.frame as usize);
    ra[start..]
        .iter()
        .zip(&rb[start..])
        .zip(k)
        .map(|((x, y), k)| k * f64::from((x - y).abs()))
        .sum()
}

impl UnitSelection {
    /// The skip cost of going from `a` to `b` (eq. 8).
    fn skip(&self, a: CodebookFrame, b: CodebookFrame) -> f64 {
        let c = &self.constants;
        let w = |i: usize| (c.beta3 * i as f64).exp();
        if a.sentence != b.sentence || b.frame < a.frame {
            return w(c.p);
        }
        match (b.frame - a.frame) as usize {
            1 => 0.0,
            0 => w(1),
            i if i < c.p => w(i),
            _ => w(c.p),
        }
    }

    /// The visual and skip costs `(f, g)` of joining `a` to `b` (both 0 for the next frame
    /// of the same sentence).
    fn join_costs(
        &self,
        cb: &Codebook,
        k: &[f64],
        a: CodebookFrame,
        b: CodebookFrame,
    ) -> (f64, f64) {
        if a.sentence == b.sentence && b.frame == a.frame + 1 {
            return (0.0, 0.0);
        }
        (visual(cb, k, a, b), self.skip(a, b))
    }

    /// Concatenation cost `w_ccf·f + w_ccg·g`.
    fn concatenation(&self, cb: &Codebook, k: &[f64], a: CodebookFrame, b: CodebookFrame) -> f64 {
        let (f, g) = self.join_costs(cb, k, a, b);
        self.weights.w_ccf * f + self.weights.w_ccg * g
    }
}

/// The target phone of every output frame at `fps`.
fn frame_targets(target: &[Segment], fps: f64) -> Vec<Phone> {
    let start = target[0].start;
    super::frame_times(target, fps)
        .iter()
        .map(|t| phone_at(target, start + t))
        .collect()
}

impl Synthesiser for UnitSelection {
    fn name(&self) -> String {
        "unit selection".into()
    }

    fn synthesise(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
    ) -> Result<Synthesis, SynthError> {
        self.weights.validate()?;
        self.constants.validate()?;
        validate_request(target, fps)?;
        let (selection, stats, warnings) = self.select(codebook, target, fps)?;
        let start = target[0].start;
        let phones = target
            .iter()
            .map(|seg| {
                // The sentences this phone's frames came from, weighted by their share.
                let picked: Vec<&CodebookFrame> = selection
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| {
                        let t = start + *i as f64 / fps;
                        t >= seg.start && t < seg.end
                    })
                    .map(|(_, u)| u)
                    .collect();
                let mut chosen: Vec<Chosen> = Vec::new();
                for u in &picked {
                    let name = &codebook.sentences[u.sentence as usize].name;
                    match chosen.iter_mut().find(|c| &c.sentence == name) {
                        Some(c) => c.weight += 1.0 / picked.len() as f64,
                        None => chosen.push(Chosen {
                            sentence: name.clone(),
                            segment: u.frame as usize,
                            score: 0.0,
                            weight: 1.0 / picked.len() as f64,
                        }),
                    }
                }
                PhoneReport {
                    phone: seg.phone,
                    used: seg.phone,
                    start: seg.start,
                    end: seg.end,
                    chosen,
                }
            })
            .collect();
        Ok(Synthesis {
            frames: selected_frames(codebook, &selection, fps)?,
            phones,
            warnings,
            selection: Some(stats),
        })
    }
}

impl UnitSelection {
    /// The path cost `w_tc·Σ TC + w_cc·Σ CC` of any choice of codebook frames for `target`
    /// at `fps` (one per output frame): what [`UnitSelection::select`] minimises.
    pub fn path_cost(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
        path: &[CodebookFrame],
    ) -> f64 {
        let tc = TargetCost::for_target(codebook, &self.constants, target, fps);
        let k = visual_weights(codebook);
        let w = self.weights;
        (0..path.len())
            .map(|i| {
                let join = if i > 0 {
                    self.concatenation(codebook, &k, path[i - 1], path[i])
                } else {
                    0.0
                };
                w.w_tc * tc.at(i, path[i]) + w.w_cc * join
            })
            .sum()
    }

    /// The selected codebook frame of every output frame, the selection's statistics and
    /// warnings (phones whose viseme class has no frame in the codebook).
    pub fn select(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
    ) -> Result<(Vec<CodebookFrame>, SelectionStats, Vec<String>), SynthError> {
        let prepared = self.prepare(codebook, target, fps)?;
        let (selection, stats) = self.solve(codebook, &prepared)?;
        Ok((selection, stats, prepared.warnings))
    }

    /// Everything of the search that does not depend on the weights: the candidate lists
    /// with their target costs, and (where the lists are short enough) the visual and skip
    /// costs of every join — so weight training can re-solve it cheaply.
    pub fn prepare(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
    ) -> Result<Prepared, SynthError> {
        self.constants.validate()?;
        validate_request(target, fps)?;
        let targets = frame_targets(target, fps);
        let tc = TargetCost::new(codebook, &self.constants, targets.clone(), fps);
        // Codebook frames by viseme class.
        let mut by_viseme: Vec<Vec<CodebookFrame>> = vec![Vec::new(); crate::phonemes::N_VISEMES];
        for (s, phones) in codebook.frame_phones.iter().enumerate() {
            for (f, p) in phones.iter().enumerate() {
                by_viseme[p.viseme() as usize].push(CodebookFrame {
                    sentence: s as u32,
                    frame: f as u32,
                });
            }
        }
        let all: Vec<CodebookFrame> = by_viseme.iter().flatten().copied().collect();
        if all.is_empty() {
            return Err(SynthError::Empty);
        }
        let mut warnings = Vec::new();
        let target_cost = |i: usize, u: CodebookFrame| tc.at(i, u);
        // Candidates per output frame, pruned to the beam by target cost.
        use rayon::prelude::*;
        let lists: Vec<Vec<(CodebookFrame, f64)>> = targets
            .par_iter()
            .enumerate()
            .map(|(i, p)| {
                let pool = &by_viseme[p.viseme() as usize];
                // A class with no frame borrows the nearest class present (as blend does).
                let pool = match super::stand_in(codebook, *p) {
                    _ if !pool.is_empty() => pool,
                    Some(q) if !by_viseme[q.viseme() as usize].is_empty() => {
                        &by_viseme[q.viseme() as usize]
                    }
                    _ => &all,
                };
                let mut scored: Vec<(CodebookFrame, f64)> =
                    pool.iter().map(|&u| (u, target_cost(i, u))).collect();
                let beam = self.constants.beam;
                if beam > 0 && scored.len() > beam {
                    scored.select_nth_unstable_by(beam - 1, |a, b| {
                        a.1.total_cmp(&b.1).then(a.0.cmp(&b.0))
                    });
                    scored.truncate(beam);
                }
                scored.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                scored
            })
            .collect();
        for (i, p) in targets.iter().enumerate() {
            if by_viseme[p.viseme() as usize].is_empty()
                && (i == 0 || targets[i - 1].viseme() != p.viseme())
            {
                let used = super::stand_in(codebook, *p)
                    .filter(|q| !by_viseme[q.viseme() as usize].is_empty())
                    .map_or("every frame".to_owned(), |q| {
                        format!("frames of /{q}/'s class")
                    });
                warnings.push(format!(
                    "frame {i}: no codebook frame of /{p}/'s viseme class; {used} were the candidates"
                ));
            }
        }
        let k = visual_weights(codebook);
        let joins = (1..lists.len())
            .map(|i| {
                let (a, b) = (&lists[i - 1], &lists[i]);
                (a.len() * b.len() <= MAX_CACHED_JOINS).then(|| {
                    a.iter()
                        .flat_map(|&(u, _)| {
                            let k = &k;
                            b.iter()
                                .map(move |&(w, _)| self.join_costs(codebook, k, u, w))
                        })
                        .collect()
                })
            })
            .collect();
        Ok(Prepared {
            lists,
            joins,
            k,
            warnings,
        })
    }

    /// The cheapest path through a prepared lattice under these weights.
    pub fn solve(
        &self,
        codebook: &Codebook,
        prepared: &Prepared,
    ) -> Result<(Vec<CodebookFrame>, SelectionStats), SynthError> {
        self.weights.validate()?;
        let Prepared {
            lists, joins, k, ..
        } = prepared;
        let w = self.weights;
        let sizes: Vec<usize> = lists.iter().map(Vec::len).collect();
        let (path, cost) = cheapest_path(
            &sizes,
            |i, c| w.w_tc * lists[i][c].1,
            |i, p, c| {
                let (f, g) = match &joins[i - 1] {
                    Some(j) => j[p * sizes[i] + c],
                    None => self.join_costs(codebook, k, lists[i - 1][p].0, lists[i][c].0),
                };
                w.w_cc * (w.w_ccf * f + w.w_ccg * g)
            },
        )
        .ok_or(SynthError::Empty)?;
        let selection: Vec<CodebookFrame> = path
            .iter()
            .enumerate()
            .map(|(i, &c)| lists[i][c].0)
            .collect();
        let stats = selection_stats(codebook, k, &selection, |i| lists[i][path[i]].1, cost);
        Ok((selection, stats))
    }
}

/// Joins cached per step at most (candidates of one frame × the next's).
const MAX_CACHED_JOINS: usize = 16_384;

/// A unit-selection lattice ready to be solved under any weights ([`UnitSelection::prepare`]).
pub struct Prepared {
    /// Per output frame, the candidates kept and their target costs.
    lists: Vec<Vec<(CodebookFrame, f64)>>,
    /// Per join (output frames i−1 → i), the (visual, skip) costs of every candidate pair,
    /// row-major, where cached.
    joins: Vec<Option<Vec<(f64, f64)>>>,
    k: Vec<f64>,
    /// Phones whose viseme class has no codebook frame.
    pub warnings: Vec<String>,
}

/// The target cost (eq. 1) of codebook frames for the output frames of one target.
pub struct TargetCost<'a> {
    codebook: &'a Codebook,
    targets: Vec<Phone>,
    /// Context frames either side.
    n: isize,
    /// `v_t` for t = −n..=n, and their sum.
    v: Vec<f64>,
    v_sum: f64,
}

impl<'a> TargetCost<'a> {
    /// For output frames whose target phones are `targets`, at `fps`.
    pub fn new(
        codebook: &'a Codebook,
        constants: &UnitConstants,
        targets: Vec<Phone>,
        fps: f64,
    ) -> Self {
        let n = (constants.context_at_25fps as f64 * fps / 25.0).round() as isize;
        let v: Vec<f64> = (-n..=n)
            .map(|t| (constants.beta1 * t.unsigned_abs() as f64).exp())
            .collect();
        let v_sum = v.iter().sum();
        TargetCost {
            codebook,
            targets,
            n,
            v,
            v_sum,
        }
    }

    /// The target phones of the output frames of `target` at `fps`.
    pub fn for_target(
        codebook: &'a Codebook,
        constants: &UnitConstants,
        target: &[Segment],
        fps: f64,
    ) -> Self {
        Self::new(codebook, constants, frame_targets(target, fps), fps)
    }

    /// `TC(i, u)`.
    pub fn at(&self, i: usize, u: CodebookFrame) -> f64 {
        let target_at = |i: isize| -> Phone {
            if i < 0 || i as usize >= self.targets.len() {
                Phone::SIL
            } else {
                self.targets[i as usize]
            }
        };
        let phones = &self.codebook.frame_phones[u.sentence as usize];
        let codebook_at = |t: isize| -> Phone {
            let f = u.frame as isize + t;
            if f < 0 || f as usize >= phones.len() {
                Phone::SIL
            } else {
                phones[f as usize]
            }
        };
        (-self.n..=self.n)
            .zip(&self.v)
            .map(|(t, vt)| {
                vt * self
                    .codebook
                    .distance(target_at(i as isize + t), codebook_at(t))
            })
            .sum::<f64>()
            / self.v_sum
    }
}

/// The frames of a selection, in order: the synthesised trajectory of unit selection and the
/// graph.
pub(crate) fn selected_frames(
    codebook: &Codebook,
    selection: &[CodebookFrame],
    fps: f64,
) -> Result<Frames, SynthError> {
    let rows = selection
        .iter()
        .flat_map(|u| {
            codebook.sentences[u.sentence as usize]
                .frames
                .row(u.frame as usize)
                .to_vec()
        })
        .collect();
    Ok(Frames::from_rows(codebook.layout, fps, rows)?)
}

/// TC_avg, SL_avg and VC_avg of a selection (eq. 12–15); `tc(i)` is frame i's target cost.
pub fn selection_stats(
    codebook: &Codebook,
    k: &[f64],
    selection: &[CodebookFrame],
    tc: impl Fn(usize) -> f64,
    path_cost: f64,
) -> SelectionStats {
    let n = selection.len();
    let mut segments: Vec<(String, u32, u32)> = Vec::new();
    let mut visual_sum = 0.0;
    for (i, u) in selection.iter().enumerate() {
        let continues = i > 0 && {
            let a = selection[i - 1];
            a.sentence == u.sentence && u.frame == a.frame + 1
        };
        if continues {
            if let Some(last) = segments.last_mut() {
                last.2 += 1;
            }
        } else {
            if i > 0 {
                visual_sum += visual(codebook, k, selection[i - 1], *u);
            }
            segments.push((
                codebook.sentences[u.sentence as usize].name.clone(),
                u.frame,
                1,
            ));
        }
    }
    SelectionStats {
        tc_avg: (0..n).map(&tc).sum::<f64>() / n.max(1) as f64,
        sl_avg: n as f64 / segments.len().max(1) as f64,
        vc_avg: visual_sum / (n.max(2) - 1) as f64,
        path_cost,
        segments,
    }
}

/// A weights file: the four path-cost weights (all required), the constants (optional, the
/// defaults otherwise) and, from `train-weights`, how they were chosen. `train-weights`
/// writes it; `synth --weights` and `eval --weights` read it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WeightsFile {
    /// The path-cost weights.
    pub weights: UnitWeights,
    /// The constants.
    #[serde(default)]
    pub constants: UnitConstants,
    /// How the weights were trained (free-form, for the record).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training: Option<serde_json::Value>,
}

/// What can be wrong with a weights file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WeightsError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a weights file: bad JSON, a missing weight or an unknown key.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A weight or constant out of range.
    #[error("{path}: {source}")]
    Range {
        /// The file.
        path: std::path::PathBuf,
        /// What is out of range.
        source: InvalidOption,
    },
}

impl WeightsFile {
    /// Reads and checks a weights file.
    pub fn read(path: &std::path::Path) -> Result<Self, WeightsError> {
        let text =
            crate::safe_read::read_regular_string(path).map_err(|source| WeightsError::Io {
                path: path.into(),
                source,
            })?;
        let file: WeightsFile = serde_json::from_str(&text).map_err(|e| WeightsError::Invalid {
            path: path.into(),
            reason: e.to_string(),
        })?;
        let range = |source| WeightsError::Range {
            path: path.into(),
            source,
        };
        file.weights.validate().map_err(range)?;
        file.constants.validate().map_err(range)?;
        Ok(file)
    }

    /// Writes the file atomically.
    pub fn write(&self, path: &std::path::Path) -> Result<(), WeightsError> {
        let json = serde_json::to_vec_pretty(self).expect("weights serialise");
        crate::atomic::write_file(path, &json).map_err(|source| WeightsError::Io {
            path: path.into(),
            source,
        })
    }

    /// The unit selection these weights and constants make.
    pub fn unit_selection(&self) -> UnitSelection {
        UnitSelection {
            weights: self.weights,
            constants: self.constants,
        }
    }
}
