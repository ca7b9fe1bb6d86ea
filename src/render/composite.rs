//! Feathered compositing onto background frames (DESIGN §10): the face's alpha falls smoothly
//! from 1 to 0 over the last `feather` reference-frame pixels inside the mesh boundary, so no
//! seam shows where the model's face meets the real one.

use rayon::prelude::*;

use crate::model::FaceModel;

/// Default feather width, in reference-frame pixels.
pub const DEFAULT_FEATHER: f64 = 6.0;

/// Alpha per mask pixel of `model`'s reference frame: the smoothstep of the pixel's distance
/// beyond the rim the mask leaves out ([`crate::mesh::Placement::margin`]) over `feather`
/// pixels — so the rim itself, and the mask pixels next to it, come from the background (0: a
/// hard edge, alpha 1 everywhere).
pub fn feather_alpha(model: &FaceModel, feather: f64) -> Vec<f32> {
    let frame = &model.frame;
    frame
        .rim_distances()
        .into_par_iter()
        .map(|d| {
            // Smoothstep of the distance: no visible kink where the ramp ends.
            let t = if feather > 0.0 {
                ((d - frame.margin) / feather).clamp(0.0, 1.0)
            } else {
                1.0
            };
            (t * t * (3.0 - 2.0 * t)) as f32
        })
        .collect()
}
