//! Feathered compositing onto background frames (DESIGN §10): the face's alpha falls smoothly
//! from 1 to 0 over the last `feather` reference-frame pixels inside the mesh boundary, so no
//! seam shows where the model's face meets the real one.

use rayon::prelude::*;

use crate::model::FaceModel;

/// Default feather width, in reference-frame pixels.
pub const DEFAULT_FEATHER: f64 = 6.0;

/// Alpha per mask pixel of `model`'s reference frame: the smoothstep of the pixel's distance
/// to the mesh boundary over `feather` pixels (0: a hard edge, alpha 1 everywhere).
pub fn feather_alpha(model: &FaceModel, feather: f64) -> Vec<f32> {
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
    frame
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
        .collect()
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
