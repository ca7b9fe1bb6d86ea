//! The frame-synchronous Viterbi search over a graph, beam-pruned, all at once or a few
//! frames at a time ([`Decoder`]).

use super::*;

/// An HMM's best way out after its last frame: score through the exit transition, and the
/// history of the state it leaves from.
pub(crate) fn best_exit(
    a: &[[f32; STATES + 1]; STATES],
    score: &[f32; STATES],
    hist: &[u32; STATES],
) -> (f32, u32) {
    let mut best = (f32::NEG_INFINITY, NONE);
    for s in 0..STATES {
        let v = score[s] + a[s][STATES];
        if v > best.0 {
            best = (v, hist[s]);
        }
    }
    best
}

/// Frame-synchronous Viterbi over the graph, beam-pruned; phone-level back-pointers.
pub(crate) fn viterbi(
    model: &AcousticModel,
    g: &Graph,
    feats: &[[f32; FEATURE_DIM]],
) -> Option<Path> {
    best_path(model, g, feats.iter().map(Emission::Acoustic))
}

/// The search over every frame's `emissions`, beam-pruned; `None` when the beam lost every
/// hypothesis or no final HMM was reached.
pub(crate) fn best_path<'e>(
    model: &AcousticModel,
    g: &Graph,
    emissions: impl Iterator<Item = Emission<'e>>,
) -> Option<Path> {
    let mut decoder = Decoder::new(model, g);
    for emission in emissions {
        decoder.advance(g, emission)?;
    }
    decoder.finish(g)
}

/// What scores a state in one frame of the search.
#[derive(Clone, Copy)]
pub(crate) enum Emission<'a> {
    /// The acoustic model's scores of these features, on demand.
    Acoustic(&'a [f32; FEATURE_DIM]),
    /// Every state of a phone its phone's score (a hybrid recogniser's).
    Phones(&'a [f32]),
    /// The acoustic model's scores of each context-independent phone's states, computed
    /// beforehand ([`ci_state_scores`]; a graph of context-independent phones only).
    States(&'a [[f32; STATES]]),
}


/// [`viterbi`] of a phone loop ([`Graph::phone_loop`]) over scores from [`ci_state_scores`].
pub(crate) fn viterbi_states(model: &AcousticModel, g: &Graph, states: &[Vec<[f32; STATES]>]) -> Option<Path> {
    best_path(model, g, states.iter().map(|row| Emission::States(row)))
}

/// [`viterbi`] with every state of a phone scoring that phone's entry of the frame's row of
/// `scores` (frames × context-independent phones) in place of the acoustic model's.
pub(crate) fn viterbi_scored(model: &AcousticModel, g: &Graph, scores: &[Vec<f32>]) -> Option<Path> {
    best_path(model, g, scores.iter().map(|row| Emission::Phones(row)))
}

/// The Viterbi search's state between frames, so that features can arrive a few at a time
/// (live phone recognition) as well as all at once ([`viterbi`]).
pub(crate) struct Decoder<'m> {
    pub(crate) model: &'m AcousticModel,
    pub(crate) scorer: Scorer<'m>,
    pub(crate) score: Vec<[f32; STATES]>,
    pub(crate) hist: Vec<[u32; STATES]>,
    pub(crate) next: Vec<[f32; STATES]>,
    pub(crate) next_hist: Vec<[u32; STATES]>,
    pub(crate) exit: Vec<(f32, u32)>,
    pub(crate) active: Vec<bool>,
    /// (node, first frame, previous record, score on entry)
    pub(crate) records: Vec<(u32, u32, u32, f32)>,
    pub(crate) start_cost: Vec<f32>,
    /// Frames decoded.
    pub(crate) frames: usize,
}

/// Records kept before the unreachable ones are dropped (a live stream runs for hours).
pub(crate) const RECORDS_BEFORE_COMPACTION: usize = 1 << 18;

impl<'m> Decoder<'m> {
    pub(crate) fn new(model: &'m AcousticModel, g: &Graph) -> Self {
        let n = g.nodes.len();
        let ninf = f32::NEG_INFINITY;
        let mut start_cost = vec![ninf; n];
        for &(h, c) in &g.start {
            start_cost[h as usize] = c;
        }
        Decoder {
            model,
            scorer: Scorer::new(model),
            score: vec![[ninf; STATES]; n],
            hist: vec![[NONE; STATES]; n],
            next: vec![[ninf; STATES]; n],
            next_hist: vec![[NONE; STATES]; n],
            exit: vec![(ninf, NONE); n],
            active: vec![false; n],
            records: Vec::new(),
            start_cost,
            frames: 0,
        }
    }

    /// One frame of a phone loop's search over its phones' state scores ([`ci_state_scores`]);
    /// `None` when the beam lost every hypothesis.
    pub(crate) fn step_states(&mut self, g: &Graph, states: &[[f32; STATES]]) -> Option<()> {
        self.advance(g, Emission::States(states))
    }

    /// One frame of the search, each state scored as `emission` says.
    // States index the transition matrix in both its dimensions and the scores beside it.
    #[allow(clippy::needless_range_loop)]
    pub(crate) fn advance(&mut self, g: &Graph, emission: Emission<'_>) -> Option<()> {
        let model = self.model;
        let n = g.nodes.len();
        let ninf = f32::NEG_INFINITY;
        let t = self.frames;
        if let Emission::Acoustic(feat) = emission {
            self.scorer.set_frame(t as u32, feat);
        }
        // Exits of the previous frame.
        for h in 0..n {
            self.exit[h] = (ninf, NONE);
            if self.active[h] {
                self.exit[h] =
                    best_exit(&model.tmats[g.nodes[h].tmat], &self.score[h], &self.hist[h]);
            }
        }
        let mut best = ninf;
        for h in 0..n {
            let (mut entry, mut entry_hist) = if t == 0 {
                (self.start_cost[h], NONE)
            } else {
                (ninf, NONE)
            };
            for &(p, c) in &g.preds[h] {
                let v = self.exit[p as usize].0 + c;
                if v > entry {
                    entry = v;
                    entry_hist = self.exit[p as usize].1;
                }
            }
            if !self.active[h] && entry == ninf {
                self.next[h] = [ninf; STATES];
                continue;
            }
            let node = &g.nodes[h];
            let a = &model.tmats[node.tmat];
            for j in 0..STATES {
                let (mut v, mut from) = (ninf, NONE);
                for i in 0..=j {
                    let s = self.score[h][i] + a[i][j];
                    if s > v {
                        v = s;
                        from = self.hist[h][i];
                    }
                }
                if j == 0 && entry > v {
                    v = entry;
                    self.records.push((h as u32, t as u32, entry_hist, entry));
                    from = (self.records.len() - 1) as u32;
                }
                if v > ninf {
                    v += match emission {
                        Emission::Phones(scores) => scores[usize::from(node.phone)],
                        Emission::States(scores) => scores[usize::from(node.phone)][j],
                        Emission::Acoustic(_) => self.scorer.score(node.senones[j]),
                    };
                }
                self.next[h][j] = v;
                self.next_hist[h][j] = from;
                best = best.max(v);
            }
        }
        if best == ninf {
            return None;
        }
        let threshold = best - BEAM;
        for h in 0..n {
            let mut any = false;
            for v in self.next[h].iter_mut() {
                if *v < threshold {
                    *v = ninf;
                } else {
                    any = true;
                }
            }
            self.active[h] = any;
        }
        std::mem::swap(&mut self.score, &mut self.next);
        std::mem::swap(&mut self.hist, &mut self.next_hist);
        self.frames += 1;
        if self.records.len() > RECORDS_BEFORE_COMPACTION {
            self.compact();
        }
        Some(())
    }

    /// The best path so far, ending in whichever state scores best now (not necessarily at
    /// an HMM's exit): what a live stream commits from.
    pub(crate) fn partial(&self) -> Path {
        let (mut best, mut at) = (f32::NEG_INFINITY, NONE);
        for (h, (score, hist)) in self.score.iter().zip(&self.hist).enumerate() {
            if !self.active[h] {
                continue;
            }
            for (&v, &from) in score.iter().zip(hist) {
                if v > best {
                    (best, at) = (v, from);
                }
            }
        }
        self.trace(at, best)
    }

    /// The best path through the graph's final HMMs after the last frame.
    pub(crate) fn finish(&self, g: &Graph) -> Option<Path> {
        let (mut best, mut at) = (f32::NEG_INFINITY, NONE);
        for &h in &g.finals {
            let h = h as usize;
            let (v, from) =
                best_exit(&self.model.tmats[g.nodes[h].tmat], &self.score[h], &self.hist[h]);
            if v > best {
                (best, at) = (v, from);
            }
        }
        (at != NONE).then(|| self.trace(at, best))
    }

    pub(crate) fn trace(&self, mut at: u32, score: f32) -> Path {
        let (mut entries, mut entry_scores) = (Vec::new(), Vec::new());
        while at != NONE {
            let (node, start, prev, entered) = self.records[at as usize];
            entries.push((node, start));
            entry_scores.push(f64::from(entered));
            at = prev;
        }
        entries.reverse();
        entry_scores.reverse();
        Path {
            entries,
            entry_scores,
            score: f64::from(score),
        }
    }

    /// Drops the records no live hypothesis leads back to, renumbering the rest.
    pub(crate) fn compact(&mut self) {
        let mut keep = vec![false; self.records.len()];
        let mut stack: Vec<u32> = self
            .hist
            .iter()
            .zip(&self.active)
            .filter(|(_, a)| **a)
            .flat_map(|(h, _)| h.iter().copied())
            .filter(|&r| r != NONE)
            .collect();
        while let Some(r) = stack.pop() {
            if !std::mem::replace(&mut keep[r as usize], true) {
                let prev = self.records[r as usize].2;
                if prev != NONE {
                    stack.push(prev);
                }
            }
        }
        let mut new_index = vec![NONE; self.records.len()];
        let mut kept = Vec::with_capacity(keep.iter().filter(|&&k| k).count());
        for (r, record) in self.records.iter().enumerate() {
            if keep[r] {
                new_index[r] = kept.len() as u32;
                let prev = if record.2 == NONE { NONE } else { new_index[record.2 as usize] };
                kept.push((record.0, record.1, prev, record.3));
            }
        }
        self.records = kept;
        for (h, active) in self.hist.iter_mut().zip(&self.active) {
            for r in h.iter_mut() {
                *r = if *active && *r != NONE { new_index[*r as usize] } else { NONE };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bounded ranking against a full stable sort, over lengths that are and are not
    /// multiples of the sets and of eight, with many ties (values rounded to a coarse grid, or
    /// to one so coarse that the sets' greatest values are all equal).
    #[test]
    fn best_of_ranks_as_a_full_sort_does() {
        let mut rng = crate::rng::Rng::new(7);
        for len in [1, 3, 8, 31, 64, 100, 128, 130] {
            for k in 0..400 {
                // Every other vector on a grid so coarse that most values tie (three levels).
                let grid = if k % 2 == 0 { 2.0 } else { 0.1 };
                let values: Vec<f32> = (0..len).map(|_| (rng.range(-20.0, 0.0) * grid).round() as f32).collect();
                let mut order: Vec<usize> = (0..len).collect();
                order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
                let mut expected = [(0u16, f32::NEG_INFINITY); TOP_N];
                for (slot, &d) in expected.iter_mut().zip(&order) {
                    *slot = (d as u16, values[d]);
                }
                assert_eq!(best_of(&values, at_least), expected, "{values:?}");
                #[cfg(target_arch = "x86_64")]
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: this CPU has AVX2 (checked just above).
                    let by_avx = best_of(&values, |e, b| unsafe { at_least_avx2(e, b) });
                    assert_eq!(by_avx, expected, "{values:?}");
                }
            }
        }
    }

    /// Eight comparisons in one AVX instruction as one by one: ties, signed zeros, infinities
    /// and NaN (never at least anything).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn at_least_by_avx_as_one_by_one() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let odd = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, -1.5, 2.0, -1e30];
        for bound in [0.0, -0.0, -1.5, f32::NEG_INFINITY, f32::INFINITY, f32::NAN, 3.0] {
            for shift in 0..8 {
                let eight: [f32; 8] = std::array::from_fn(|i| odd[(i + shift) % 8]);
                // SAFETY: this CPU has AVX2 (checked above).
                let by_avx = unsafe { at_least_avx2(&eight, bound) };
                assert_eq!(by_avx, at_least(&eight, bound), "{eight:?} ≥ {bound}");
            }
        }
    }
}
