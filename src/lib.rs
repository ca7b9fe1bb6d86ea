//! facespace — talking-face animation from independent statistical shape and appearance
//! models (Theobald et al. \[blend\]; Liu & Ostermann \[unitsel\]; see `docs/DESIGN.md`).
//!
//! # A talker says something
//!
//! The front door: load a talker folder (the committed GRID s1 is `models/grid`) and have it
//! say a recording with its words — or text, phone labels, or a recording alone — into an MP4
//! with its sound; [`live::Session`] on the same talker does it as the speech arrives.
//!
//! ```no_run
//! use std::path::Path;
//!
//! use facespace::{SayRequest, Speech, Talker};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let talker = Talker::load(Path::new("models/grid"))?;
//! let speech = Speech::Recording {
//!     audio: "tests/data/grid/bbwtzp.mp4".into(),
//!     words: "bin blue with t zero please".into(),
//! };
//! let report = talker.say(&SayRequest::new(speech), Path::new("out/bbwtzp.mp4"), |_| {})?;
//! println!("{} frames", report.frames);
//! # Ok(())
//! # }
//! ```
//!
//! # The stages
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
//! 4. [`synth`]: synthesisers behind one trait, smoothing, the writer of an utterance and the
//!    systems a held-out evaluation compares; [`render`]: renderers behind one trait and the
//!    streaming render of a sequence; [`eval`]: objective measures; [`mouths`]: a talker's
//!    recorded mouths; [`footage`]: its idle footage and living frame.
//! 5. [`talker`]: a talker folder and the one pipeline, [`Talker::say`]; [`live`]: a session
//!    on a talker as the speech arrives; [`align`], [`sound_to_face`], [`tts`]: speech in and
//!    out. [`demo`], [`study`], [`annotate`], [`serve`] are the applications built on them.
//!
//! The library never prints: long work reports through a [`Progress`] callback.
//!
//! # The whole pipeline, on the committed test data
//!
//! Load the demo model, encode a clip of its talker through face-space, make the clip (with
//! phone labels — generated ones: the clip has no sound) a one-sentence codebook, synthesise
//! the phones again by top-N blending, and render the frames:
//!
//! ```
//! use std::path::Path;
//!
//! use facespace::codebook::{Codebook, SimilarityOptions};
//! use facespace::codec::{self, EncodeOptions};
//! use facespace::corpus::Sentence;
//! use facespace::model::FaceModel;
//! use facespace::phonemes::{self, PhoneMap};
//! use facespace::render::{self, Background, CpuRenderer, RenderError};
//! use facespace::synth::{self, Smoothing, blend::Blend};
//! use facespace::video::Source;
//! use facespace::{no_progress, shape};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let root = Path::new(env!("CARGO_MANIFEST_DIR"));
//! let model = FaceModel::load(&root.join("models/demo/model"))?;
//!
//! // Track and project every frame of a 50-frame clip of the same talker.
//! let options = EncodeOptions {
//!     init: Some(shape::read_pts(&root.join("tests/data/clip/01000.pts"))?),
//!     ..EncodeOptions::default()
//! };
//! let source = Source::open(&root.join("tests/data/clip"))?;
//! let clip = codec::encode(&model, source, &options, no_progress)?.clip;
//! assert_eq!(clip.frames.len(), 50);
//!
//! // The clip and its phone timings become a codebook (S and M included).
//! let labels = root.join("tests/data/labels/clip.lab");
//! let phones = phonemes::read_labels(&labels, None, &PhoneMap::default())?;
//! let sentence = Sentence {
//!     name: "clip".into(),
//!     source: "tests/data/clip".into(),
//!     frames: clip.frames.clone(),
//!     segments: phones.clone(),
//! };
//! let fps = clip.frames.fps();
//! let codebook = Codebook::build(
//!     vec![sentence],
//!     fps,
//!     model.layout(),
//!     Some(model.hash()),
//!     SimilarityOptions::default(),
//!     &mut no_progress,
//! )?;
//!
//! // Synthesise the same phones from the codebook, smoothed.
//! let smoothing = Smoothing::On(synth::DEFAULT_SMOOTHING);
//! let request = synth::Request::new(phones, fps, smoothing);
//! let utterance = synth::synthesise(&Blend::default(), &codebook, request)?;
//! let frames = &utterance.variants()[0].1;
//!
//! // Render every frame over a plain background.
//! let mut images = Vec::new();
//! let background = Background::plain_for(&model, frames);
//! render::stream(
//!     &CpuRenderer::new(&model),
//!     frames,
//!     background,
//!     |image| {
//!         images.push(image);
//!         Ok::<_, RenderError>(())
//!     },
//!     no_progress,
//! )?;
//! assert_eq!(images.len(), frames.len());
//! # Ok(())
//! # }
//! ```

#![warn(missing_docs)]

pub use live::{Screen, Session, Stage};
pub use talker::{SayRequest, Speech, Talker};

pub mod align;
pub mod annotate;
pub mod appearance;
pub mod atomic;
pub mod audio;
pub mod codebook;
pub mod codec;
pub mod corpus;
pub mod demo;
pub mod eval;
pub mod facespace;
pub mod fit;
pub mod footage;
pub mod http;
pub mod manifest;
pub mod live;
pub mod mesh;
pub mod model;
pub mod mp4_file;
pub mod mouths;
pub mod npy;
pub mod options;
pub mod pca;
pub mod phonemes;
pub mod plot;
pub mod programs;
pub mod render;
pub mod rng;
pub mod safe_read;
pub mod serve;
pub mod shape;
pub mod sound_to_face;
pub mod study;
pub mod suggest;
pub mod synth;
pub mod talker;
pub mod trajectory;
pub mod tts;
pub mod video;
pub mod visemes;
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

/// The Rust examples of docs/ compile as doctests (issue 68: every code block runs in a test).
#[cfg(doctest)]
#[doc = include_str!("../docs/LIVE.md")]
struct LiveDoc;
