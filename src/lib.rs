//! facespace — talking-face animation from independent statistical shape and appearance
//! models (Theobald et al. \[blend\]; Liu & Ostermann \[unitsel\]; see `DESIGN.md`).
//!
//! The face-space vector ([`facespace`]: `[pose | b_s | b_a]`, a [`facespace::Frames`]
//! sequence) is the currency every stage passes:
//!
//! 1. [`shape`] (landmarks, `.pts`, Procrustes, the point distribution model), [`mesh`]
//!    (triangulation, reference frame, per-pixel barycentric map), [`warp`] (piecewise affine
//!    warps), [`appearance`] and [`pca`] → [`model::FaceModel`]: build, project, reconstruct,
//!    save and load.
//! 2. [`fit`]: AAM search and the frame-to-frame tracker; [`video`]: frame sources and sinks
//!    (MP4 built in); [`codec`]: video → face-space clip → video, with its quality report.
//! 3. [`corpus`]: labelled sentences (and the generated demo corpus); [`phonemes`]: phone set,
//!    label files, text → phones; [`trajectory`]: PCHIP trajectories; [`codebook`]: the
//!    trajectories indexed by phone, with S and M.
//! 4. [`synth`]: synthesisers behind one trait, smoothing, and the writer of an utterance;
//!    [`render`]: renderers behind one trait and the streaming render of a sequence;
//!    [`eval`]: objective measures and the systems they compare; [`demo`]: the whole
//!    pipeline on the committed demo model.
//!
//! The library never prints: long work reports through a [`Progress`] callback.

pub mod appearance;
pub mod atomic;
pub mod codebook;
pub mod codec;
pub mod corpus;
pub mod demo;
pub mod eval;
pub mod facespace;
pub mod fit;
pub mod manifest;
pub mod mesh;
pub mod model;
pub mod npy;
pub mod options;
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
    /// What is being done.
    pub stage: &'static str,
    /// Units done.
    pub done: usize,
    /// Units in all.
    pub total: usize,
}

/// A progress callback that ignores every report.
pub fn no_progress(_: Progress) {}
