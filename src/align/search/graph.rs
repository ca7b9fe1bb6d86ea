//! The alignment graph: phone HMMs of every pronunciation with optional silences, a phone
//! loop, and the best path read back as phones and words.

use super::*;

/// Language weight, silence probability and word insertion penalty of the reference
/// alignment (pocketsphinx `-lw 6.5 -silprob 0.1 -wip 0.65`): an optional silence costs
/// `lw · (ln silprob + ln wip)` nats against the acoustic log-likelihood.
pub(crate) const LW: f64 = 6.5;
pub(crate) const SILPROB: f64 = 0.1;
pub(crate) const WIP: f64 = 0.65;
/// Hypotheses more than `−ln 1e-80` below the frame's best are dropped (pocketsphinx
/// `-beam 1e-80`).
pub(crate) const BEAM: f32 = 184.2;

pub(crate) fn silence_cost() -> f32 {
    (LW * (SILPROB.ln() + WIP.ln())) as f32
}

pub(crate) const NONE: u32 = u32::MAX;

/// One phone HMM of the graph.
pub(crate) struct Node {
    pub(crate) senones: [u16; STATES],
    pub(crate) tmat: usize,
    /// CI phone id.
    pub(crate) phone: u8,
    /// (word index, pronunciation) for word phones; `None` for silence.
    pub(crate) word: Option<(usize, usize)>,
}

/// HMMs, their predecessors with the cost of the transition, the entry and final HMMs.
pub(crate) struct Graph {
    pub(crate) nodes: Vec<Node>,
    pub(crate) preds: Vec<Vec<(u32, f32)>>,
    pub(crate) start: Vec<(u32, f32)>,
    pub(crate) finals: Vec<u32>,
}

/// The entry and exit HMMs of one pronunciation, keyed by the context they assume.
pub(crate) struct WordEnds {
    /// (left context, first HMM).
    pub(crate) entries: Vec<(usize, u32)>,
    /// (right context, last HMM).
    pub(crate) exits: Vec<(usize, u32)>,
    pub(crate) first: usize,
    pub(crate) last: usize,
}

impl Graph {
    /// A phone loop: every context-independent phone, fillers included (they take the
    /// noises and tones no phone explains, so that music is not read as speech), each
    /// reachable from each with the cost `transition[from][to]` (`from` = the previous
    /// phone's id; the utterance starts as if after silence), entering and leaving anywhere.
    // Node `c` is phone `c`: the index reads the transitions and names the node alike.
    #[allow(clippy::needless_range_loop)]
    pub(crate) fn phone_loop(model: &AcousticModel, transition: &[Vec<f32>]) -> Graph {
        let mut g = Graph {
            nodes: Vec::new(),
            preds: Vec::new(),
            start: Vec::new(),
            finals: Vec::new(),
        };
        // Node `c` is CI phone `c`.
        let phones = model.ci_names.len();
        for c in 0..phones {
            let (senones, tmat) = model.context_independent(c);
            let h = g.add(Node {
                senones,
                tmat,
                phone: c as u8,
                word: None,
            });
            g.start.push((h, transition[model.sil][c]));
            g.finals.push(h);
        }
        for b in 0..phones {
            for a in 0..phones {
                g.edge(a as u32, b as u32, transition[a][b]);
            }
        }
        g
    }

    /// The path's HMMs as phones with times (a phone loop's output).
    pub(crate) fn phones(&self, model: &AcousticModel, path: &Path, frames: usize) -> Vec<TimedPhone> {
        self.phone_spans(path, frames)
            .into_iter()
            .map(|(phone, start, end)| timed_phone(model, phone, start, end))
            .collect()
    }

    /// The path's HMMs as (CI phone, first frame, end frame).
    pub(crate) fn phone_spans(&self, path: &Path, frames: usize) -> Vec<(u8, u32, u32)> {
        path.entries
            .iter()
            .enumerate()
            .map(|(k, &(node, start))| {
                let end = path.entries.get(k + 1).map_or(frames as u32, |e| e.1);
                (self.nodes[node as usize].phone, start, end)
            })
            .collect()
    }

    pub(crate) fn add(&mut self, node: Node) -> u32 {
        self.nodes.push(node);
        self.preds.push(Vec::new());
        (self.nodes.len() - 1) as u32
    }

    pub(crate) fn edge(&mut self, from: u32, to: u32, cost: f32) {
        self.preds[to as usize].push((from, cost));
    }

    /// Words × pronunciations → HMMs with exact cross-word triphone contexts: a word's first
    /// (last) phone is duplicated for each left (right) context it can meet — silence or the
    /// edge phone of each neighbouring pronunciation.
    pub(crate) fn build(model: &AcousticModel, words: &[String], prons: &[&[Vec<u8>]]) -> Graph {
        let sil = model.sil;
        let n = words.len();
        let mut g = Graph {
            nodes: Vec::new(),
            preds: Vec::new(),
            start: Vec::new(),
            finals: Vec::new(),
        };
        let contexts = |i: usize, first: bool| -> Vec<usize> {
            let mut c = vec![sil];
            let neighbour = if first {
                i.checked_sub(1)
            } else {
                Some(i + 1).filter(|&j| j < n)
            };
            if let Some(j) = neighbour {
                for p in prons[j] {
                    let ph = if first { *p.last().unwrap() } else { p[0] } as usize;
                    if !c.contains(&ph) {
                        c.push(ph);
                    }
                }
            }
            c
        };
        let mut ends: Vec<Vec<WordEnds>> = Vec::with_capacity(n);
        for (i, variants) in prons.iter().enumerate() {
            let (lcs, rcs) = (contexts(i, true), contexts(i, false));
            let mut word_ends = Vec::new();
            for (v, pron) in variants.iter().enumerate() {
                let p: Vec<usize> = pron.iter().map(|&c| c as usize).collect();
                let len = p.len();
                let node = |g: &mut Graph, base: usize, l: usize, r: usize, pos| {
                    let (senones, tmat) = model.triphone(base, l, r, pos);
                    g.add(Node {
                        senones,
                        tmat,
                        phone: base as u8,
                        word: Some((i, v)),
                    })
                };
                let mut e = WordEnds {
                    entries: Vec::new(),
                    exits: Vec::new(),
                    first: p[0],
                    last: p[len - 1],
                };
                if len == 1 {
                    for &l in &lcs {
                        for &r in &rcs {
                            let h = node(&mut g, p[0], l, r, WordPosition::Single);
                            e.entries.push((l, h));
                            e.exits.push((r, h));
                        }
                    }
                    // One HMM per (l, r): listed under l among the entries and under r among
                    // the exits, so it is entered only from l and left only towards r.
                } else {
                    let firsts: Vec<u32> = lcs
                        .iter()
                        .map(|&l| node(&mut g, p[0], l, p[1], WordPosition::Begin))
                        .collect();
                    let mut tails = firsts.clone();
                    for k in 1..len - 1 {
                        let h = node(&mut g, p[k], p[k - 1], p[k + 1], WordPosition::Internal);
                        for &t in &tails {
                            g.edge(t, h, 0.0);
                        }
                        tails = vec![h];
                    }
                    for &r in &rcs {
                        let h = node(&mut g, p[len - 1], p[len - 2], r, WordPosition::End);
                        for &t in &tails {
                            g.edge(t, h, 0.0);
                        }
                        e.exits.push((r, h));
                    }
                    e.entries = lcs.iter().copied().zip(firsts).collect();
                }
                word_ends.push(e);
            }
            ends.push(word_ends);
        }
        let sil_node = |g: &mut Graph| {
            let (senones, tmat) = model.triphone(sil, sil, sil, WordPosition::Single);
            g.add(Node {
                senones,
                tmat,
                phone: sil as u8,
                word: None,
            })
        };
        let cost = silence_cost();
        for j in 0..=n {
            let s = sil_node(&mut g);
            if j == 0 {
                g.start.push((s, cost));
            } else {
                for e in &ends[j - 1] {
                    for &(r, h) in &e.exits {
                        if r == sil {
                            g.edge(h, s, cost);
                        }
                    }
                }
            }
            if j == n {
                g.finals.push(s);
                for e in &ends[n - 1] {
                    for &(r, h) in &e.exits {
                        if r == sil {
                            g.finals.push(h);
                        }
                    }
                }
                break;
            }
            for e in &ends[j] {
                for &(l, h) in &e.entries {
                    if l != sil {
                        continue;
                    }
                    g.edge(s, h, 0.0);
                    if j == 0 {
                        g.start.push((h, 0.0));
                    }
                }
            }
            if j > 0 {
                // Direct word-to-word transitions, contexts matching on both sides.
                let mut direct = Vec::new();
                for prev in &ends[j - 1] {
                    for next in &ends[j] {
                        for &(r, from) in &prev.exits {
                            if r != next.first {
                                continue;
                            }
                            for &(l, to) in &next.entries {
                                if l == prev.last {
                                    direct.push((from, to));
                                }
                            }
                        }
                    }
                }
                for (from, to) in direct {
                    g.edge(from, to, 0.0);
                }
            }
        }
        g
    }

    /// The path's HMMs → phones and words with times.
    pub(crate) fn alignment(
        &self,
        model: &AcousticModel,
        words: &[String],
        path: &Path,
        frames: usize,
    ) -> Alignment {
        let mut phones = Vec::with_capacity(path.entries.len());
        let mut timed_words: Vec<TimedWord> = Vec::new();
        let mut word_of_node: Vec<Option<usize>> = Vec::new();
        for (k, &(node, start)) in path.entries.iter().enumerate() {
            let end = path.entries.get(k + 1).map_or(frames as u32, |e| e.1);
            // Divided, not multiplied by 0.01, so that times read back from files compare equal.
            let (start, end) = (
                start as f64 / FRAMES_PER_SECOND,
                end as f64 / FRAMES_PER_SECOND,
            );
            let n = &self.nodes[node as usize];
            let word = n.word.map(|(i, v)| {
                match timed_words.last_mut() {
                    Some(w) if word_of_node.last().copied().flatten() == Some(i) => w.end = end,
                    _ => timed_words.push(TimedWord {
                        word: words[i].clone(),
                        pronunciation: v,
                        start,
                        end,
                    }),
                }
                timed_words.len() - 1
            });
            word_of_node.push(n.word.map(|(i, _)| i));
            phones.push(TimedPhone {
                phone: model.ci_names[n.phone as usize].clone(),
                start,
                end,
                word,
            });
        }
        Alignment {
            words: timed_words,
            phones,
            frames,
            score_per_frame: path.score / frames.max(1) as f64,
        }
    }
}

/// A phone of a phone loop's path, frames `start..end`; fillers (noises) come out as `SIL`.
pub(crate) fn timed_phone(model: &AcousticModel, phone: u8, start: u32, end: u32) -> TimedPhone {
    let phone = if model.is_filler(phone as usize) { model.sil } else { phone as usize };
    TimedPhone {
        phone: model.ci_names[phone].clone(),
        start: start as f64 / FRAMES_PER_SECOND,
        end: end as f64 / FRAMES_PER_SECOND,
        word: None,
    }
}

/// The best path: (HMM, first frame) in order, and its log-likelihood.
pub(crate) struct Path {
    pub(crate) entries: Vec<(u32, u32)>,
    /// The path's log-likelihood up to each entry (the frames before it).
    pub(crate) entry_scores: Vec<f64>,
    pub(crate) score: f64,
}

impl Path {
    /// The log-likelihood of the path's first `frame` frames (of `frames`): exact at each
    /// HMM's entry, linear in between (the HMM's frames share its score evenly).
    pub(crate) fn up_to(&self, frame: f64, frames: usize) -> f64 {
        let at = |k: usize| -> (f64, f64) {
            match self.entries.get(k) {
                Some(e) => (f64::from(e.1), self.entry_scores[k]),
                None => (frames as f64, self.score),
            }
        };
        let k = self
            .entries
            .iter()
            .rposition(|e| f64::from(e.1) <= frame)
            .unwrap_or(0);
        let ((f0, s0), (f1, s1)) = (at(k), at(k + 1));
        if f1 <= f0 {
            return s1;
        }
        s0 + (s1 - s0) * ((frame - f0) / (f1 - f0)).clamp(0.0, 1.0)
    }
}
