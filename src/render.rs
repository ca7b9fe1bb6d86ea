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
        render_rows(model, frames, background, |row, canvas| {
            model.render_into(&model.params_from_vector(row)?, canvas)?;
            Ok(())
        })
    }
}

/// Each `dims`-long row drawn by `draw` over its own copy of `background`, rayon across rows.
fn render_rows(
    model: &FaceModel,
    frames: &[f64],
    background: &RgbImage,
    draw: impl Fn(&[f32], &mut RgbImage) -> Result<(), ModelError> + Sync,
) -> Result<Vec<RgbImage>, ModelError> {
    frames
        .par_chunks_exact(model.n_params())
        .map(|row| {
            let v: Vec<f32> = row.iter().map(|&x| x as f32).collect();
            let mut canvas = background.clone();
            draw(&v, &mut canvas)?;
            Ok(canvas)
        })
        .collect()
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

/// Feathered compositing onto background frames (DESIGN §10): the face's alpha falls
/// smoothly from 1 to 0 over the last `feather` reference-frame pixels inside the mesh
/// boundary, so no seam shows where the model's face meets the real one.
pub struct Compositor {
    alpha: Vec<f32>,
}

/// Default feather width, in reference-frame pixels.
pub const DEFAULT_FEATHER: f64 = 6.0;

impl Compositor {
    pub fn new(model: &FaceModel, feather: f64) -> Self {
        let frame = &model.frame;
        let mut edges = Vec::new();
        for (t, hull) in frame.triangles.iter().zip(&frame.hull_edges) {
            for i in 0..3 {
                if hull[i] {
                    let (p, q) = (t[(i + 1) % 3] as usize, t[(i + 2) % 3] as usize);
                    edges.push((frame.landmarks[p], frame.landmarks[q]));
                }
            }
        }
        let alpha = frame
            .pixels
            .par_iter()
            .map(|px| {
                let c = [px.x as f64, px.y as f64];
                let d = edges
                    .iter()
                    .map(|&(p, q)| point_segment_distance(c, p, q))
                    .fold(f64::INFINITY, f64::min);
                // Smoothstep of the distance: no visible kink where the ramp ends.
                let t = if feather > 0.0 {
                    (d / feather).min(1.0)
                } else {
                    1.0
                };
                (t * t * (3.0 - 2.0 * t)) as f32
            })
            .collect();
        Compositor { alpha }
    }

    /// Alpha per mask pixel.
    pub fn alpha(&self) -> &[f32] {
        &self.alpha
    }

    /// Draws one face-space row blended onto `canvas`.
    pub fn draw(
        &self,
        model: &FaceModel,
        row: &[f32],
        canvas: &mut RgbImage,
    ) -> Result<(), ModelError> {
        let params = model.params_from_vector(row)?;
        let r = model.reconstruct(&params)?;
        crate::warp::from_reference_blend_into(
            &model.frame,
            &r.texture,
            &self.alpha,
            &r.landmarks.points,
            canvas,
        )?;
        Ok(())
    }
}

impl Renderer for Compositor {
    /// Each row blended over a copy of `background` (rayon across frames).
    fn render(
        &self,
        model: &FaceModel,
        frames: &[f64],
        background: &RgbImage,
    ) -> Result<Vec<RgbImage>, ModelError> {
        render_rows(model, frames, background, |row, canvas| {
            self.draw(model, row, canvas)
        })
    }
}

fn point_segment_distance(c: [f64; 2], p: [f64; 2], q: [f64; 2]) -> f64 {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((c[0] - p[0]) * dx + (c[1] - p[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (c[0] - p[0] - t * dx).hypot(c[1] - p[1] - t * dy)
}
