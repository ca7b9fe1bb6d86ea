//! Synthesis of face-space sequences from phones (DESIGN §8).
//!
//! A [`Synthesiser`] turns target phones with timings into frames ([`blend`]: top-N context
//! blending); [`synthesise`] runs one and applies the smoothing spline ([`smooth`]) as asked,
//! keeping both variants for an A/B comparison; [`output`] renders and writes the result.

pub mod backdrop;
pub mod blend;
pub mod graph;
pub mod output;
pub mod pareto;
pub mod random;
pub mod smooth;
pub mod systems;
pub mod unit;
pub mod viterbi;

use serde::Serialize;
use thiserror::Error;

use crate::codebook::Codebook;
use crate::facespace::{FacespaceError, Frames};
use crate::options::{self, InvalidOption};
use crate::phonemes::{Phone, Segment};
use crate::shape::Similarity;
use smooth::{SmoothError, SmoothingSpline};

/// Default smoothing weight λ of the cubic smoothing spline (seconds³ per parameter unit²):
/// the value `facespace eval --validation` chose on GRID s1's 73 validation sentences (lowest
/// mean DTW of blend N = 3; BENCHMARKS.md) — recorded speech, never the sentences reported.
pub const DEFAULT_SMOOTHING: f64 = 3e-5;

/// The largest smoothing weight λ taken: 10⁴ times the largest ever chosen on validation
/// sentences (1e-4), where the spline is already a straight line through the utterance.
pub const MAX_SMOOTHING: f64 = 1.0;

/// λ chosen on the generated FGNet demo corpus's validation split (BENCHMARKS.md): that
/// corpus's trajectories are smoother than recorded ones.
pub const GENERATED_SMOOTHING: f64 = 3e-6;

/// What can go wrong synthesising.
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum SynthError {
    /// No phones with a duration.
    #[error("nothing to synthesise: the target has no phones")]
    Empty,
    /// A phone with a negative or non-finite time.
    #[error("target phone {index} ({phone}) has a negative or non-finite duration")]
    BadSegment {
        /// Its position in the target.
        index: usize,
        /// The phone.
        phone: Phone,
    },
    /// Overlapping or unordered phones.
    #[error("target phones overlap or are out of order at phone {0}")]
    Unsorted(usize),
    /// A phone neither the codebook nor its viseme class has.
    #[error(
        "phone {phone} is absent from the codebook and nothing can stand in for it (the codebook has no phone of any viseme class but silence)"
    )]
    NoFallback {
        /// The phone.
        phone: Phone,
    },
    /// An option out of range.
    #[error(transparent)]
    Option(#[from] InvalidOption),
    /// Frames that do not fit (non-finite values, say).
    #[error(transparent)]
    Frames(#[from] FacespaceError),
    /// The smoothing spline failed.
    #[error("smoothing: {0}")]
    Smooth(#[from] SmoothError),
}

/// One example chosen for a target phone.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Chosen {
    /// The codebook sentence.
    pub sentence: String,
    /// The segment within it.
    pub segment: usize,
    /// Its score.
    pub score: f64,
    /// Its weight in the mix.
    pub weight: f64,
}

/// What was done for one target phone.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PhoneReport {
    /// The target phone.
    pub phone: Phone,
    /// The phone whose examples were used (differs from `phone` after a fallback).
    pub used: Phone,
    /// Start, seconds.
    pub start: f64,
    /// End, seconds.
    pub end: f64,
    /// The examples used.
    pub chosen: Vec<Chosen>,
}

/// A synthesised sequence and what was chosen for it.
#[derive(Clone, Debug, PartialEq)]
pub struct Synthesis {
    /// The frames, from the first target phone's start.
    pub frames: Frames,
    /// Per target phone, what was used.
    pub phones: Vec<PhoneReport>,
    /// Human-readable notes: fallbacks, skipped zero-length phones.
    pub warnings: Vec<String>,
    /// For a synthesiser that picks codebook frames: how the selection fared.
    pub selection: Option<unit::SelectionStats>,
}

/// Turns target phones into face-space frames: shape and appearance. The pose columns are
/// not the synthesiser's to choose — [`synthesise`] sets them as the [`Request`] asks.
pub trait Synthesiser: Send + Sync {
    /// A short description for reports and evaluation tables, e.g. `blend C=1 N=3`.
    fn name(&self) -> String;

    /// Frames at `fps` for `target` (validated first with [`validate_target`]).
    fn synthesise(
        &self,
        codebook: &Codebook,
        target: &[Segment],
        fps: f64,
    ) -> Result<Synthesis, SynthError>;
}

/// Checks the target: non-empty, finite non-negative durations, in order.
pub fn validate_target(target: &[Segment]) -> Result<(), SynthError> {
    if target.is_empty() {
        return Err(SynthError::Empty);
    }
    for (index, s) in target.iter().enumerate() {
        if !(s.start.is_finite() && s.end.is_finite()) || s.end < s.start || s.start < 0.0 {
            return Err(SynthError::BadSegment {
                index,
                phone: s.phone,
            });
        }
        if index > 0 && s.start < target[index - 1].end - 1e-9 {
            return Err(SynthError::Unsorted(index));
        }
    }
    if target.iter().all(|s| s.duration() <= 0.0) {
        return Err(SynthError::Empty);
    }
    Ok(())
}

pub use crate::facespace::MAX_DURATION;

/// Checks the target and the frame rate together: the frame count they imply is bounded.
pub fn validate_request(target: &[Segment], fps: f64) -> Result<(), SynthError> {
    crate::facespace::check_fps(fps)?;
    validate_target(target)?;
    let span = target[target.len() - 1].end - target[0].start;
    options::in_range("utterance length (s)", span, 0.0, MAX_DURATION)?;
    Ok(())
}

/// Output frames for `target` at `fps`: the frames `i / fps` that start within the utterance,
/// so a sentence labelled over `[0, N / fps]` has its N frames (at least one).
pub fn frame_count(target: &[Segment], fps: f64) -> usize {
    match (target.first(), target.last()) {
        (Some(a), Some(b)) => (((b.end - a.start) * fps - 1e-6).ceil() as usize).max(1),
        _ => 0,
    }
}

/// The output frame times for `target` at `fps`, from 0 (the first phone's start).
pub fn frame_times(target: &[Segment], fps: f64) -> Vec<f64> {
    (0..frame_count(target, fps))
        .map(|i| i as f64 / fps)
        .collect()
}

/// The phone whose examples stand in for `p`: itself if present, else the most frequent
/// present phone of its viseme class, else of the nearest class present by mouth shape (S
/// has no row for a phone the corpus never shows, so the data cannot say which is nearest).
pub fn stand_in(codebook: &Codebook, p: Phone) -> Option<Phone> {
    if !codebook.occurrences[p.index()].is_empty() {
        return Some(p);
    }
    // The class's most frequent phone; else the nearest class by mouth shape
    // (`phonemes::VISEME_MOUTHS`), silence only ever standing in for silence.
    let present = codebook.present();
    crate::phonemes::nearest_visemes(p.viseme())
        .into_iter()
        .filter(|&c| (c == 0) == (p.viseme() == 0))
        .find_map(|class| {
            present
                .iter()
                .filter(|q| q.viseme() == class)
                .max_by_key(|q| {
                    (
                        codebook.occurrences[q.index()].len(),
                        std::cmp::Reverse(**q),
                    )
                })
                .copied()
        })
}

/// Smooths the shape and appearance columns of `frames` with the cubic smoothing spline of
/// weight `lambda` over the frame times (fewer than 3 frames are returned as they are). The
/// pose columns are left alone: the pose is never synthesised, so never smoothed.
pub fn smoothed(frames: &Frames, lambda: f64) -> Result<Frames, SynthError> {
    let mut out = frames.clone();
    if frames.len() >= 3 {
        let spline = SmoothingSpline::new(&frames.times(), None, lambda)?;
        let mut column = vec![0.0; frames.len()];
        let params = frames.layout().params_range();
        for mut col in out
            .values_mut()
            .columns_mut()
            .into_iter()
            .skip(params.start)
        {
            column
                .iter_mut()
                .zip(col.iter())
                .for_each(|(c, &v)| *c = f64::from(v));
            for (v, s) in col.iter_mut().zip(spline.smooth(&column)?) {
                *v = s as f32;
            }
        }
    }
    Ok(out)
}

/// Whether and how an utterance is smoothed.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Smoothing {
    /// As synthesised.
    Off,
    /// Smoothed with weight λ.
    On(f64),
    /// Both, for an A/B comparison: smoothed with weight λ, and as synthesised.
    Ab(f64),
}

/// Where each output frame's pose comes from (DESIGN §7: the pose is never blended).
#[derive(Clone, Debug, PartialEq)]
pub enum Pose {
    /// The codebook's median pose, still.
    Codebook,
    /// One pose throughout (a background frame's).
    Hold(Similarity),
    /// Frame by frame from a recorded sequence (a tracked background video or a talker's
    /// living frame, as long as the utterance; a shorter list is played forwards then
    /// backwards, [`ping_pong`]).
    Replay(Vec<Similarity>),
}

impl Pose {
    /// A short description for reports.
    pub fn describe(&self) -> String {
        match self {
            Pose::Codebook => "held at the codebook's median pose".into(),
            Pose::Hold(_) => "held at the background frame's pose".into(),
            Pose::Replay(p) => format!("replayed from {} background frames", p.len()),
        }
    }
}

pub use crate::render::ping_pong;

/// What to synthesise: the phones with their timings, the frame rate, the smoothing and where
/// the pose comes from.
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    /// The phones spoken.
    pub target: Vec<Segment>,
    /// Output frames per second.
    pub fps: f64,
    /// Smoothing of the shape and appearance.
    pub smoothing: Smoothing,
    /// The pose of every frame.
    pub pose: Pose,
}

impl Request {
    /// `target` at `fps`, smoothed as `smoothing` asks, at the codebook's median pose.
    pub fn new(target: Vec<Segment>, fps: f64, smoothing: Smoothing) -> Self {
        Request {
            target,
            fps,
            smoothing,
            pose: Pose::Codebook,
        }
    }
}

/// An utterance: its target, the synthesis, and the variants its smoothing asks for.
#[derive(Clone, Debug, PartialEq)]
pub struct Utterance {
    /// The phones spoken.
    pub target: Vec<Segment>,
    /// What the synthesiser was.
    pub method: String,
    /// The frames as synthesised, and what was chosen.
    pub synthesis: Synthesis,
    /// The smoothed frames, when smoothing is on or A/B.
    pub smoothed: Option<Frames>,
    /// The smoothing asked for.
    pub smoothing: Smoothing,
    /// Where the pose came from.
    pub pose: String,
}

impl Utterance {
    /// The variants to write: `("smoothed", …)`, `("unsmoothed", …)` or both.
    pub fn variants(&self) -> Vec<(&'static str, &Frames)> {
        let raw = ("unsmoothed", &self.synthesis.frames);
        match (&self.smoothed, self.smoothing) {
            (Some(s), Smoothing::Ab(_)) => vec![("smoothed", s), raw],
            (Some(s), _) => vec![("smoothed", s)],
            (None, _) => vec![raw],
        }
    }
}

/// Synthesises as `request` asks — "synthesise, set the pose, then smooth" in one place for
/// the CLI, the demo, evaluation and benchmarks.
pub fn synthesise(
    synthesiser: &dyn Synthesiser,
    codebook: &Codebook,
    request: Request,
) -> Result<Utterance, SynthError> {
    let Request {
        target,
        fps,
        smoothing,
        pose,
    } = request;
    validate_request(&target, fps)?;
    if let Pose::Replay(p) = &pose
        && p.is_empty()
    {
        return Err(SynthError::Option(InvalidOption::new(
            "replayed poses",
            0,
            "at least one",
        )));
    }
    let mut synthesis = synthesiser.synthesise(codebook, &target, fps)?;
    let still = match &pose {
        Pose::Codebook => codebook.median_pose(),
        Pose::Hold(p) => *p,
        Pose::Replay(_) => Similarity::IDENTITY,
    };
    for t in 0..synthesis.frames.len() {
        let p = match &pose {
            Pose::Replay(poses) => poses[ping_pong(t, poses.len())],
            _ => still,
        };
        synthesis.frames.set_pose(t, p);
    }
    let smoothed = match smoothing {
        Smoothing::Off => None,
        Smoothing::On(l) | Smoothing::Ab(l) => {
            options::in_range("smoothing λ", l, 0.0, MAX_SMOOTHING)?;
            Some(smoothed(&synthesis.frames, l)?)
        }
    };
    Ok(Utterance {
        target,
        method: synthesiser.name(),
        synthesis,
        smoothed,
        smoothing,
        pose: pose.describe(),
    })
}
