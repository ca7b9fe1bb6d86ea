//! Feathered compositing onto background frames (DESIGN §10): the face's alpha falls smoothly
//! from 1 to 0 over the last `feather` reference-frame pixels inside the mesh boundary, so no
//! seam shows where the model's face meets the real one. A region model that knows its
//! articulators ([`crate::mesh::Region::articulators`]) also fades out away from them, so its
//! border runs around the lips and chin and the cheeks and nose are the background's own.

use rayon::prelude::*;

use crate::model::FaceModel;

/// Default feather width, in reference-frame pixels.
pub const DEFAULT_FEATHER: f64 = 6.0;

/// A region model's face is drawn whole this far beyond its articulators (lips and chin), as
/// a fraction of their width...
pub const ARTICULATION_HOLD: f64 = 0.05;
/// ...then fades out to the background over this fraction of their width. Away from the
/// lips the region's appearance changes with no motion to show for it: on the FGNet demo its
/// cheeks beside the nose changed 15× more per frame than the real video under them, most of
/// it the region's whole-face appearance components (BENCHMARKS.md, issue 25).
pub const ARTICULATION_FADE: f64 = 0.25;

/// Alpha per mask pixel of `model`'s reference frame: the smoothstep of the pixel's distance
/// beyond the rim the mask leaves out ([`crate::mesh::Placement::margin`]) over `feather`
/// pixels — so the rim itself, and the mask pixels next to it, come from the background (0: a
/// hard edge, alpha 1 everywhere).
///
/// For a region model with articulators, times the fade away from them: 1 within
/// [`ARTICULATION_HOLD`] × their width of the triangles between them, falling by a smoothstep
/// to 0 over the next [`ARTICULATION_FADE`] × their width.
pub fn feather_alpha(model: &FaceModel, feather: f64) -> Vec<f32> {
    faded_alpha(
        model,
        feather,
        model.region.as_ref().and_then(|r| r.articulators()),
    )
}

/// How a drawn face meets its canvas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Edge {
    /// Every mask pixel drawn whole.
    Hard,
    /// Faded in over this many reference-frame pixels inside the rim ([`feather_alpha`]; a
    /// region model also fades out away from its articulators).
    Feathered(f64),
    /// Feathered, and faded out away from the articulators ([`FaceModel::articulators`])
    /// whatever the model: over the talker's own face only the lips and jaw are drawn, so the
    /// eyes, their lids and their texture stay the frame's own (issue 33: a whole-face
    /// codebook over a video otherwise gave open irises inside the video's closed lids).
    Articulators(f64),
}

impl From<Option<f64>> for Edge {
    /// `None`: a hard edge; `Some(f)`: feathered over `f` pixels.
    fn from(feather: Option<f64>) -> Self {
        feather.map_or(Edge::Hard, Edge::Feathered)
    }
}

impl Edge {
    /// The alpha per mask pixel of `model`'s reference frame, or `None` for a hard edge.
    pub fn alpha(self, model: &FaceModel) -> Option<Vec<f32>> {
        match self {
            Edge::Hard => None,
            Edge::Feathered(f) => Some(feather_alpha(model, f)),
            Edge::Articulators(f) => Some(faded_alpha(model, f, model.articulators())),
        }
    }
}

/// [`feather_alpha`] with the fade away from `articulators` when there are some.
fn faded_alpha(model: &FaceModel, feather: f64, articulators: Option<Vec<u32>>) -> Vec<f32> {
    let frame = &model.frame;
    let smoothstep = |t: f64| {
        let t = t.clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    let rim: Vec<f64> = frame
        .rim_distances()
        .into_par_iter()
        .map(|d| {
            if feather > 0.0 {
                smoothstep((d - frame.margin) / feather)
            } else {
                1.0
            }
        })
        .collect();
    let Some(articulators) = articulators else {
        return rim.into_iter().map(|a| a as f32).collect();
    };
    let xs = articulators
        .iter()
        .filter_map(|&v| frame.landmarks.get(v as usize))
        .map(|p| p[0]);
    let width = xs.clone().fold(f64::NEG_INFINITY, f64::max) - xs.fold(f64::INFINITY, f64::min);
    let (hold, fade) = (ARTICULATION_HOLD * width, ARTICULATION_FADE * width);
    rim.iter()
        .zip(frame.part_distances(&articulators))
        .map(|(a, d)| {
            let near = if d.is_finite() && fade > 0.0 {
                1.0 - smoothstep((d - hold) / fade)
            } else {
                1.0
            };
            (a * near) as f32
        })
        .collect()
}
