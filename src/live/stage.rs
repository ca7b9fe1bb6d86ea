//! The living frame under a live session's face ([`Stage`]).

use super::{LiveError, LiveFrame};
use crate::facespace::Frames;
use crate::synth::SynthError;
use crate::talker::Talker;

/// Seconds of footage the living frame of a live session plays before it starts again
/// ([`Stage`]): long enough that the loop's one jump is rarely seen, short enough to plan at
/// once (each frame's pose and landmarks are kept: 2 minutes at 25 fps is ~2.5 MB).
pub const STAGE_SECONDS: f64 = 120.0;

/// The living frame under a live session's face: the talker's footage planned as stretches
/// joined where they match ([`crate::footage::Footage::plan`]) for [`STAGE_SECONDS`],
/// then again from its start. Frame `index` of any session shows loop frame
/// `index mod len`; while nothing is said the footage plays as it is (its own face), and a
/// spoken frame takes that footage frame's pose, keeps all but the lips and chin where the
/// footage's face has them, and is re-lit to the footage — as `say` draws over its own living
/// frame. One stage serves every session of a talker.
pub struct Stage<'t> {
    pub(super) talker: &'t Talker,
    plan: crate::footage::Plan,
    poses: Vec<crate::shape::Similarity>,
    pub(super) landmarks: Vec<crate::shape::Landmarks>,
    articulators: Option<Vec<u32>>,
    lighting: Option<Vec<f32>>,
}

/// What a page shows at one frame: the footage frame (and, in a dissolve, the one it is
/// joining with its weight).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shown {
    /// Footage frame.
    pub footage: usize,
    /// During a dissolve: the frame entered and its weight.
    pub mix: Option<(usize, f32)>,
}

impl<'t> Stage<'t> {
    /// The living frame of `talker`'s footage from clip `seed mod clips`.
    pub fn new(talker: &'t Talker, seed: u64) -> Result<Self, LiveError> {
        let frames = (STAGE_SECONDS * talker.footage.fps).round().max(1.0) as usize;
        let plan = talker.footage.plan(frames, seed);
        let backdrop = crate::synth::backdrop::Backdrop::footage(&talker.footage, &plan)
            .map_err(|e| LiveError::Synth(SynthError::from(e)))?;
        let lighting = backdrop.lighting_shift(&talker.model, &talker.codebook);
        let poses = match &backdrop.pose {
            crate::synth::Pose::Replay(p) => p.clone(),
            _ => Vec::new(),
        };
        Ok(Stage {
            talker,
            plan,
            poses,
            landmarks: backdrop.landmarks,
            articulators: talker.model.articulators(),
            lighting,
        })
    }

    /// Frames in the loop.
    pub fn len(&self) -> usize {
        self.landmarks.len()
    }

    /// Whether the loop is empty (never: a talker's footage has at least a second).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The plan of the loop.
    pub fn plan(&self) -> &crate::footage::Plan {
        &self.plan
    }

    /// What is shown at session frame `index`.
    pub fn shown(&self, index: usize) -> Shown {
        let plan = self.plan();
        let t = index % self.len().max(1);
        Shown {
            footage: plan.frames[t],
            mix: plan.mix[t],
        }
    }

    /// Puts live frames on the stage: each takes its footage frame's pose, is anchored to its
    /// face (all but lips and chin) and re-lit to the footage.
    pub fn place(&self, frames: &mut [LiveFrame]) -> Result<(), LiveError> {
        if frames.is_empty() {
            return Ok(());
        }
        let layout = self.talker.model.layout();
        let n = self.len().max(1);
        let rows: Vec<f32> = frames.iter().flat_map(|f| f.values.iter().copied()).collect();
        let mut placed = Frames::from_rows(layout, self.talker.footage.fps, rows)?;
        for (k, f) in frames.iter().enumerate() {
            if let Some(pose) = self.poses.get(f.index % n) {
                placed.set_pose(k, *pose);
            }
        }
        if let Some(articulators) = &self.articulators {
            let landmarks: Vec<_> = frames
                .iter()
                .map(|f| self.landmarks[f.index % n].clone())
                .collect();
            crate::synth::backdrop::anchor(&self.talker.model, &mut placed, &landmarks, articulators)?;
        }
        if let Some(shift) = &self.lighting {
            crate::synth::backdrop::relight(&mut placed, shift);
        }
        for (k, f) in frames.iter_mut().enumerate() {
            f.values.copy_from_slice(placed.row(k));
        }
        Ok(())
    }
}
