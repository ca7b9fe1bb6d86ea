//! Renderers: face-space frames → images (DESIGN §10). [`CpuRenderer`] is the reference
//! (rayon across frames, the piecewise affine warp of `warp`); a GPU renderer will sit
//! behind the same trait.

use image::{Rgb, RgbImage};
use rayon::prelude::*;

use crate::model::{FaceModel, ModelError};

pub trait Renderer {
    /// Renders each `dims`-long face-space row over a copy of `background`.
    fn render(
        &self,
        model: &FaceModel,
        frames: &[f64],
        background: &RgbImage,
    ) -> Result<Vec<RgbImage>, ModelError>;
}

/// The reference renderer on the CPU.
#[derive(Clone, Copy, Debug, Default)]
pub struct CpuRenderer;

impl Renderer for CpuRenderer {
    fn render(
        &self,
        model: &FaceModel,
        frames: &[f64],
        background: &RgbImage,
    ) -> Result<Vec<RgbImage>, ModelError> {
        frames
            .par_chunks_exact(model.n_params())
            .map(|row| {
                let v: Vec<f32> = row.iter().map(|&x| x as f32).collect();
                let params = model.params_from_vector(&v)?;
                let mut canvas = background.clone();
                model.render_into(&params, &mut canvas)?;
                Ok(canvas)
            })
            .collect()
    }
}

/// A plain grey canvas large enough for every frame's face (pose included), for when no
/// background frame is given.
pub fn plain_background(model: &FaceModel, frames: &[f64]) -> RgbImage {
    let dims = model.n_params();
    let (mut w, mut h) = (16.0f64, 16.0f64);
    for row in frames.chunks_exact(dims) {
        let v: Vec<f32> = row.iter().map(|&x| x as f32).collect();
        if let Ok(p) = model.params_from_vector(&v) {
            let l = model.shape.instance(&p.pose, &p.shape);
            let (_, hi) = l.bounds();
            w = w.max(hi[0] + 20.0);
            h = h.max(hi[1] + 20.0);
        }
    }
    // Even sizes keep 4:2:0 encoders happy.
    let even = |v: f64| ((v.min(4096.0).ceil() as u32) + 1) & !1;
    RgbImage::from_pixel(even(w), even(h), Rgb([96, 96, 96]))
}
