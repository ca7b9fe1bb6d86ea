//! The random-lips baseline of \[blend\] §6: the mouth of a randomly chosen codebook sentence,
//! whatever it said, linearly time-warped onto the target utterance. It shows what viewers
//! (and the measures) make of plausible motion that is not driven by the phones.

use super::{PhoneReport, SynthError, Synthesis, Synthesiser, validate_request};
use crate::codebook::Codebook;
use crate::facespace::Frames;
use crate::phonemes::Segment;
use crate::rng::Rng;

/// A random codebook sentence, time-warped to the target.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct RandomLips {
    /// Seed of the choice; each target mixes in its own phones and timings, so different
    /// utterances draw different sentences, the same utterance always the same one.
    pub seed: u64,
}

impl Synthesiser for RandomLips {
    fn name(&self) -> String {
        "random lips".into()
    }

    fn synthesise(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
    ) -> Result<Synthesis, SynthError> {
        validate_request(target, fps)?;
        if codebook.sentences.is_empty() {
            return Err(SynthError::Empty);
        }
        let mut h = self.seed;
        for s in target {
            for v in [s.start.to_bits(), s.end.to_bits(), s.phone.index() as u64] {
                h = (h ^ v).wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
        let pick = (Rng::new(h).uniform() * codebook.sentences.len() as f64) as usize;
        let pick = pick.min(codebook.sentences.len() - 1);
        let trajectory = &codebook.trajectories[pick];
        let (start, end) = (target[0].start, target[target.len() - 1].end);
        let span = (end - start).max(1e-9);
        let rate = (trajectory.end() - trajectory.start()) / span;
        let dims = codebook.dims();
        let times = super::frame_times(target, fps);
        let mut rows = Vec::with_capacity(times.len() * dims);
        let mut value = vec![0.0; dims];
        for t in times {
            trajectory.eval_into(trajectory.start() + t * rate, &mut value);
            rows.extend(value.iter().map(|&v| v as f32));
        }
        let name = codebook.sentences[pick].name.clone();
        Ok(Synthesis {
            frames: Frames::from_rows(codebook.layout, fps, rows)?,
            phones: target
                .iter()
                .map(|s| PhoneReport {
                    phone: s.phone,
                    used: s.phone,
                    start: s.start,
                    end: s.end,
                    chosen: vec![super::Chosen {
                        sentence: name.clone(),
                        segment: 0,
                        score: 0.0,
                        weight: 1.0,
                    }],
                })
                .collect(),
            warnings: vec![format!(
                "random lips: the whole of sentence {name}, time-warped"
            )],
            selection: None,
        })
    }
}
