//! facespace — talking-face animation from independent statistical shape and appearance
//! models (Theobald et al. \[blend\]; Liu & Ostermann \[unitsel\]; see `DESIGN.md`).
//!
//! The pipeline, and the module that owns each step:
//!
//! 1. [`shape`]: iBUG `.pts` landmarks → generalised Procrustes → [`shape::ShapeModel`]
//!    (pose kept apart as a [`shape::Similarity`]).
//! 2. [`mesh`]: Delaunay triangulation of the mean shape → [`mesh::ReferenceFrame`] with a
//!    precomputed per-pixel triangle and barycentric map.
//! 3. [`warp`]: piecewise affine warps, image ↔ reference frame (bilinear, rayon).
//! 4. [`appearance`]: PCA of the shape-normalised RGB textures ([`pca`] does the maths).
//! 5. [`model`]: [`model::FaceModel`] = the two independent models + the frame; build,
//!    project a frame to face-space, reconstruct a frame from face-space, save and load as
//!    `model.json` + `.npy` arrays.
//! 6. [`fit`]: AAM search and the frame-to-frame tracker; [`video`]: frame sources and sinks
//!    (MP4 built in); [`codec`]: video → face-space clip → video.
//!
//! The library never prints: long work reports through a [`Progress`] callback.

pub mod appearance;
pub mod atomic;
pub mod codebook;
pub mod codec;
pub mod corpus;
pub mod eval;
pub mod fit;
pub mod manifest;
pub mod mesh;
pub mod model;
pub mod npy;
pub mod pca;
pub mod phonemes;
pub mod plot;
pub mod render;
pub mod rng;
pub mod shape;
pub mod synth;
pub mod trajectory;
pub mod video;
pub mod warp;

/// A progress report from long-running work: `done` of `total` units of `stage`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    pub stage: &'static str,
    pub done: usize,
    pub total: usize,
}

/// A progress callback that ignores every report.
pub fn no_progress(_: Progress) {}
