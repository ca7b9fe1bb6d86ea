//! The mouth drawn from recorded frames (issue 38): the CPU renderer with each frame's
//! recorded detail, chosen for a whole sequence before any of its frames is drawn (each
//! sequence its own: the smoothed and unsmoothed variants of an A/B pick apart).

use std::sync::{Arc, Mutex};

use image::RgbImage;

use super::{Chooser, Mouths, Pick};
use crate::facespace::{FaceParams, Frames};
use crate::model::FaceModel;
use crate::render::{CpuRenderer, Edge, RenderError, Renderer};

/// Draws a sequence's faces with the recorded detail [`Chooser`] picked for each frame.
pub struct SampledRenderer<'m> {
    cpu: CpuRenderer<'m>,
    mouths: &'m Mouths,
    switch_cost: f32,
    /// The picks of each sequence seen, by [`sequence_key`]; the first is the one given.
    picks: Mutex<Vec<(SequenceKey, Arc<Vec<Pick>>)>>,
}

/// A sequence's identity: its length and a hash of its values (cheap beside drawing it).
type SequenceKey = (usize, u64);

fn sequence_key(frames: &Frames) -> SequenceKey {
    use std::hash::{Hash, Hasher};
    let mut hash = std::collections::hash_map::DefaultHasher::new();
    frames.values().iter().for_each(|v| v.to_bits().hash(&mut hash));
    (frames.len(), hash.finish())
}

impl<'m> SampledRenderer<'m> {
    /// A renderer of `frames` (the sequence [`Renderer::render_batch`] will be given) in
    /// `model`'s faces, meeting the canvas as `edge` says, with `mouths`' detail.
    pub fn new(model: &'m FaceModel, edge: Edge, mouths: &'m Mouths, frames: &Frames) -> Self {
        Self::with_switch_cost(model, edge, mouths, frames, super::SWITCH_COST)
    }

    /// [`SampledRenderer::new`] whose chooser leaves a run at `switch_cost` pixels.
    pub fn with_switch_cost(
        model: &'m FaceModel,
        edge: Edge,
        mouths: &'m Mouths,
        frames: &Frames,
        switch_cost: f32,
    ) -> Self {
        let renderer = SampledRenderer {
            cpu: CpuRenderer::with_edge(model, edge),
            mouths,
            switch_cost,
            picks: Mutex::new(Vec::new()),
        };
        renderer.picks_of(frames);
        renderer
    }

    /// The detail chosen for each frame of `frames`, chosen now if this sequence is new.
    fn picks_of(&self, frames: &Frames) -> Arc<Vec<Pick>> {
        let key = sequence_key(frames);
        let mut seen = self.picks.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, picks)) = seen.iter().find(|(k, _)| *k == key) {
            return picks.clone();
        }
        let mut chooser = Chooser::with_switch_cost(self.mouths, self.cpu.model(), self.switch_cost);
        let picks: Arc<Vec<Pick>> = Arc::new(frames.iter().map(|p| chooser.next(p)).collect());
        seen.push((key, picks.clone()));
        picks
    }

    /// Frame `t` of `frames` with its pick's detail (the model's face alone past the picks).
    fn draw(&self, picks: &[Pick], frames: &Frames, t: usize, canvas: &mut RgbImage) -> Result<(), RenderError> {
        match picks.get(t) {
            Some(pick) => self.cpu.render_with(frames.params(t), self.mouths.drawing(pick), canvas),
            None => self.cpu.render_into(frames.params(t), canvas),
        }
    }

    /// The detail chosen for each frame of the sequence the renderer was made for.
    pub fn picks(&self) -> Vec<Pick> {
        let seen = self.picks.lock().unwrap_or_else(|e| e.into_inner());
        seen.first().map(|(_, p)| p.to_vec()).unwrap_or_default()
    }
}

impl Renderer for SampledRenderer<'_> {
    fn model(&self) -> &FaceModel {
        self.cpu.model()
    }

    /// A point alone has no place in the sequence: the model's own face, as
    /// [`CpuRenderer`] draws it.
    fn render_into(&self, params: FaceParams<'_>, canvas: &mut RgbImage) -> Result<(), RenderError> {
        self.cpu.render_into(params, canvas)
    }

    fn render_frame(
        &self,
        frames: &Frames,
        t: usize,
        canvas: &mut RgbImage,
    ) -> Result<(), RenderError> {
        self.draw(&self.picks_of(frames), frames, t, canvas)
    }

    /// The picks looked up once for the batch, not once a frame.
    fn render_batch(
        &self,
        frames: &Frames,
        start: usize,
        canvases: &mut [RgbImage],
    ) -> Result<(), RenderError> {
        use rayon::prelude::*;
        let picks = self.picks_of(frames);
        canvases
            .par_iter_mut()
            .enumerate()
            .try_for_each(|(k, canvas)| self.draw(&picks, frames, start + k, canvas))
    }

    fn describe(&self) -> String {
        "CPU, the mouth's detail from recorded frames".into()
    }
}
