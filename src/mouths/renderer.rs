//! The mouth drawn from recorded frames (issue 38): the CPU renderer with each frame's
//! recorded detail, chosen for the whole sequence before it is drawn.

use image::RgbImage;

use super::{Chooser, Mouths, Pick};
use crate::facespace::{FaceParams, Frames};
use crate::model::FaceModel;
use crate::render::{CpuRenderer, Edge, RenderError, Renderer};

/// Draws a sequence's faces with the recorded detail [`Chooser`] picked for each frame.
pub struct SampledRenderer<'m> {
    cpu: CpuRenderer<'m>,
    mouths: &'m Mouths,
    picks: Vec<Pick>,
}

impl<'m> SampledRenderer<'m> {
    /// A renderer of `frames` (the sequence [`Renderer::render_batch`] will be given) in
    /// `model`'s faces, meeting the canvas as `edge` says, with `mouths`' detail.
    pub fn new(model: &'m FaceModel, edge: Edge, mouths: &'m Mouths, frames: &Frames) -> Self {
        Self::with_chooser(model, edge, mouths, frames, Chooser::new(mouths, model))
    }

    /// [`SampledRenderer::new`] whose chooser leaves a run at `switch_cost` pixels.
    pub fn with_switch_cost(
        model: &'m FaceModel,
        edge: Edge,
        mouths: &'m Mouths,
        frames: &Frames,
        switch_cost: f32,
    ) -> Self {
        let chooser = Chooser::with_switch_cost(mouths, model, switch_cost);
        Self::with_chooser(model, edge, mouths, frames, chooser)
    }

    fn with_chooser(
        model: &'m FaceModel,
        edge: Edge,
        mouths: &'m Mouths,
        frames: &Frames,
        mut chooser: Chooser<'m>,
    ) -> Self {
        let picks = frames.iter().map(|p| chooser.next(p)).collect();
        SampledRenderer {
            cpu: CpuRenderer::with_edge(model, edge),
            mouths,
            picks,
        }
    }

    /// The detail chosen for each frame.
    pub fn picks(&self) -> &[Pick] {
        &self.picks
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
        match self.picks.get(t) {
            Some(pick) => self.cpu.render_with(frames.params(t), self.mouths.drawing(pick), canvas),
            None => self.cpu.render_into(frames.params(t), canvas),
        }
    }

    fn describe(&self) -> String {
        "CPU, the mouth's detail from recorded frames".into()
    }
}
