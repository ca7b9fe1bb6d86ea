//! A generated, phoneme-labelled demo corpus over real face-space points.
//!
//! No phoneme-labelled recording of the demo talker exists (the video has no audio), so the
//! corpus is **generated**, deterministically from a seed:
//!
//! * **Phones and timings**: each sentence's text goes through the embedded CMU dictionary;
//!   durations come from the built-in table, scaled by a per-sentence speaking rate (±10%)
//!   and a per-phone jitter (±20%).
//! * **Targets**: every viseme class (DESIGN §6) has a target mouth shape, given as quantiles
//!   of lip opening and mouth width over the real training frames. Each *phone* gets its own
//!   target near its class's (shifted by up to ±0.1 in each quantile, seeded), so phones of a
//!   class are close but not identical and S has to find the resemblance in the data; its
//!   candidates are the three training frames nearest its target, and their face-space
//!   points (the frames projected through the model) are the raw material. Each phone mixes
//!   its candidates with its own fixed weights; each occurrence perturbs those weights, so no
//!   two occurrences are identical.
//! * **Coarticulation**: dominance functions (after Cohen & Massaro 1993): segment s pulls the
//!   trajectory towards its target with weight `α_s exp(−max(0, |t − c_s| − d_s/4) / τ)`,
//!   `τ = 50 ms`; the face-space point at t is the dominance-weighted mean of the targets.
//!   Bilabials, labiodentals and silence dominate strongly (the lips must close or touch);
//!   /hh/, /k g ng/ weakly (they take the shape of their neighbours).
//! * The pose is held still at that of the training frame nearest the mean pose, which
//!   serves as the background when the corpus is rendered.

use serde::{Deserialize, Serialize};
use thiserror::Error;

mod save;

pub use save::SaveError;

use super::Sentence;
use crate::facespace::{FacespaceError, Frames, POSE_DIMS};
use crate::model::{FaceModel, ModelError, TrainingExample};
use crate::phonemes::{self, DEFAULT_DURATIONS, N_VISEMES, Phone, PhonemeError};
use crate::rng::Rng;
use crate::trajectory::frame_times;

/// What can go wrong generating the demo corpus.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum GenerateError {
    /// A training frame could not be projected.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A sentence's text did not become phones.
    #[error("sentence {index} ({text:?}): {source}")]
    Text {
        /// Its index in [`SENTENCES`].
        index: usize,
        /// Its text.
        text: String,
        /// The cause.
        source: PhonemeError,
    },
    /// Generated frames out of range (a model with non-finite parameters).
    #[error(transparent)]
    Frames(#[from] FacespaceError),
    /// Too few training frames to pick targets from.
    #[error("need at least 3 training frames with landmarks, got {0}")]
    TooFewFrames(usize),
}

/// The demo sentences: short original English sentences covering the phone set; the last
/// ones form the validation and test splits ([`split_of`]).
pub const SENTENCES: [&str; 60] = [
    "Bob bought a big blue boat.",
    "My mother made muffins in the morning.",
    "Five very fine voices filled the valley.",
    "The thin thief thought that the theatre was there.",
    "Two tired dogs dug a deep ditch today.",
    "Sally sells sea shells by the sea shore.",
    "She should choose a cheap chair for the show.",
    "Keep the good cake for the king.",
    "Lucy likes yellow lemons and limes.",
    "Red roses grow near the river road.",
    "We will walk with Willy to the woods.",
    "How now, brown cow?",
    "Oil and soil were in the noisy boy's toy.",
    "I might buy a white kite tonight.",
    "The old man rode home alone slowly.",
    "Father saw a large dark barn.",
    "Eat the green peas and the cheese.",
    "A pen, a bed, and ten eggs.",
    "The cat had a bad habit.",
    "Put the book on the wooden hook.",
    "The moon is blue and cool in June.",
    "Her first word was bird.",
    "Measure the treasure with pleasure.",
    "Jack enjoyed the orange juice.",
    "Thank you for the map of the bay.",
    "Please pass me a piece of pie.",
    "Every van moves over the bridge.",
    "Hold the hammer in your hand.",
    "Nine new nurses need money.",
    "The song was sung along the long road.",
    "Maybe my baby will be happy.",
    "Victor gave a brave wave.",
    "Zebras zigzag in the zoo.",
    "The quick fox jumps over the lazy dog.",
    "Paper plates make poor pillows.",
    "Her mother and father live by the ocean.",
    "Bring me the blue pencil from the box.",
    "Few people knew about the view.",
    "The team met at the main gate at eight.",
    "Open the window when the room is warm.",
    "Mark made a map of the moor.",
    "Bill will fill the big bowl with milk.",
    "The farmer feeds five fat pigs.",
    "Tom and Dad went to town at ten.",
    "Please bring both boxes back.",
    "A mouse ran about the house.",
    "The boy put the toy in the box.",
    "Pamela bought apples and plums.",
    "Give the visitor a warm welcome.",
    "The baby smiled at the bubbles.",
    "Mike fixed the bike in the morning.",
    "The puppy played by the pond.",
    "We made muffins with butter and berries.",
    "Vera moved the vase to the oven.",
    "My brother bought me a map.",
    "The pilot flew above the big blue bay.",
    "Beef and beans are fine food.",
    "Move the boat to the dock before noon.",
    "Mum put the pot of soup on the stove.",
    "Few volcanoes move every five years.",
];

/// How many of [`SENTENCES`] (the last ones) are the test split.
pub const HELD_OUT: usize = 6;
/// How many of [`SENTENCES`] (the ones before the test split) are the validation split.
pub const VALIDATION: usize = 6;

/// The split of sentence `index`: the last [`HELD_OUT`] test, the [`VALIDATION`] before them
/// validation, the rest training.
pub fn split_of(index: usize) -> Split {
    let n = SENTENCES.len();
    if index >= n - HELD_OUT {
        Split::Test
    } else if index >= n - HELD_OUT - VALIDATION {
        Split::Validation
    } else {
        Split::Train
    }
}

/// Dominance strength α per viseme class (the mouth shapes are
/// [`phonemes::VISEME_MOUTHS`]).
const DOMINANCE: [f64; N_VISEMES] = [
    1.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.2, 1.0, 1.0, 1.0, 1.0, 0.3, 0.8, 0.8, 1.0, 1.0, 0.9, 1.6,
    0.8, 0.5, 2.0,
];

/// Time constant of the dominance functions.
const TAU: f64 = 0.05;

/// Options of the generator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CorpusOptions {
    /// Seed of every random choice: same seed, same corpus.
    pub seed: u64,
    /// Frame rate.
    pub fps: f64,
    /// Candidate training frames per viseme class.
    pub candidates: usize,
}

impl Default for CorpusOptions {
    fn default() -> Self {
        CorpusOptions {
            seed: 2009,
            fps: 25.0,
            candidates: 3,
        }
    }
}

/// The part of the corpus a sentence belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Split {
    /// The codebook's sentences.
    Train,
    /// For choosing constants (λ, weights): never reported.
    Validation,
    /// Reported: never used to choose anything.
    Test,
}

impl Split {
    /// The corpus sub-folder of this split.
    pub fn folder(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Validation => "validation",
            Split::Test => "heldout",
        }
    }
}

/// One generated sentence.
#[derive(Clone, Debug, PartialEq)]
pub struct GeneratedSentence {
    /// Its frames and phones.
    pub sentence: Sentence,
    /// Its text.
    pub text: String,
    /// Its split.
    pub split: Split,
}

/// Lip opening (mean inner-lip gap) and mouth width, over the inter-ocular distance, of
/// 68-point iBUG landmarks.
pub fn mouth_shape(points: &[[f64; 2]]) -> (f64, f64) {
    let d = |a: usize, b: usize| (points[a][0] - points[b][0]).hypot(points[a][1] - points[b][1]);
    let centre = |r: std::ops::Range<usize>| {
        let n = r.len() as f64;
        r.fold([0.0, 0.0], |c, i| {
            [c[0] + points[i][0] / n, c[1] + points[i][1] / n]
        })
    };
    let [eye_r, eye_l, _] = crate::shape::IBUG_EYES_AND_MOUTH;
    let (l, r) = (centre(eye_r), centre(eye_l));
    let iod = (l[0] - r[0]).hypot(l[1] - r[1]);
    (
        (d(61, 67) + d(62, 66) + d(63, 65)) / 3.0 / iod,
        d(48, 54) / iod,
    )
}

/// The generated corpus and the training frame whose pose it holds (its background).
#[derive(Clone, Debug, PartialEq)]
pub struct Corpus {
    /// Every sentence, in [`SENTENCES`] order.
    pub sentences: Vec<GeneratedSentence>,
    /// Index into the training frames.
    pub still_frame: usize,
    /// Each phone's own target face-space point (indexed like [`Phone::index`]): the
    /// generator's ground truth, against which S's ranking can be checked.
    pub phone_targets: Vec<Vec<f32>>,
}

impl Corpus {
    /// The sentences of one split.
    pub fn part(&self, split: Split) -> Vec<Sentence> {
        self.sentences
            .iter()
            .filter(|s| s.split == split)
            .map(|s| s.sentence.clone())
            .collect()
    }
}

/// The frame whose pose `[a, b, tx, ty]` is nearest the mean pose (the rotation-scale part
/// relative to the mean scale, translation in units of 10 pixels).
fn still_frame(points: &[Vec<f32>]) -> usize {
    let n = points.len() as f32;
    let mean: Vec<f32> = (0..4)
        .map(|k| points.iter().map(|p| p[k]).sum::<f32>() / n)
        .collect();
    let scale = mean[0].hypot(mean[1]).max(f32::MIN_POSITIVE);
    let dist = |p: &Vec<f32>| {
        ((p[0] - mean[0]) / scale).powi(2)
            + ((p[1] - mean[1]) / scale).powi(2)
            + ((p[2] - mean[2]).powi(2) + (p[3] - mean[3]).powi(2)) / 100.0
    };
    (0..points.len())
        .min_by(|&a, &b| dist(&points[a]).total_cmp(&dist(&points[b])))
        .unwrap_or(0)
}

/// Generates the demo corpus from the model and its (68-point) training frames.
pub fn generate(
    model: &FaceModel,
    frames: &[TrainingExample],
    options: &CorpusOptions,
) -> Result<Corpus, GenerateError> {
    if frames.len() < 3 {
        return Err(GenerateError::TooFewFrames(frames.len()));
    }
    let points: Vec<Vec<f32>> = frames
        .iter()
        .map(|f| model.project(&f.image, &f.landmarks))
        .collect::<Result<_, _>>()?;
    let layout = model.layout();
    let dims = layout.dims();
    // The still head: the pose of the real frame nearest the mean pose, so the face can be
    // drawn back onto that very frame.
    let still = still_frame(&points);
    let pose: Vec<f32> = points[still][..POSE_DIMS].to_vec();
    // Mouth shapes as quantile ranks among the training frames.
    let shapes: Vec<(f64, f64)> = frames
        .iter()
        .map(|f| mouth_shape(&f.landmarks.points))
        .collect();
    let rank = |values: Vec<f64>| -> Vec<f64> {
        let mut order: Vec<usize> = (0..values.len()).collect();
        order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
        let mut r = vec![0.0; values.len()];
        for (k, &i) in order.iter().enumerate() {
            r[i] = k as f64 / (values.len() - 1) as f64;
        }
        r
    };
    let (open, wide) = (
        rank(shapes.iter().map(|s| s.0).collect()),
        rank(shapes.iter().map(|s| s.1).collect()),
    );
    let mut rng = Rng::new(options.seed);
    // Each phone's own target near its class's, its nearest training frames, and its own mix
    // of them.
    let candidates: Vec<Vec<usize>> = Phone::all()
        .map(|p| {
            let (o, w) = phonemes::VISEME_MOUTHS[p.viseme() as usize];
            let (o, w) = (o + rng.range(-0.1, 0.1), w + rng.range(-0.1, 0.1));
            let mut order: Vec<usize> = (0..frames.len()).collect();
            let dist = |i: usize| (open[i] - o).powi(2) + (wide[i] - w).powi(2);
            order.sort_by(|&a, &b| dist(a).total_cmp(&dist(b)).then(a.cmp(&b)));
            order.truncate(options.candidates.max(1));
            order
        })
        .collect();
    let phone_weights: Vec<Vec<f64>> = candidates
        .iter()
        .map(|c| c.iter().map(|_| rng.range(0.8, 1.0)).collect())
        .collect();
    let mut out = Vec::with_capacity(SENTENCES.len());
    for (index, text) in SENTENCES.iter().enumerate() {
        let rate = rng.range(0.9, 1.1);
        let mut durations = DEFAULT_DURATIONS;
        durations.iter_mut().for_each(|d| *d *= rate);
        let mut segments =
            phonemes::text_to_segments(text, &durations).map_err(|source| GenerateError::Text {
                index,
                text: text.to_string(),
                source,
            })?;
        // Per-phone jitter, keeping the segments contiguous.
        let mut t = 0.0;
        for s in &mut segments {
            let d = s.duration() * rng.range(0.8, 1.2);
            s.start = t;
            s.end = t + d;
            t += d;
        }
        // Occurrence targets: the phone's mix, perturbed.
        let targets: Vec<Vec<f64>> = segments
            .iter()
            .map(|s| {
                let cands = &candidates[s.phone.index()];
                let w: Vec<f64> = phone_weights[s.phone.index()]
                    .iter()
                    .map(|w| w * rng.range(0.85, 1.15))
                    .collect();
                let total: f64 = w.iter().sum();
                (0..dims)
                    .map(|k| {
                        cands
                            .iter()
                            .zip(&w)
                            .map(|(&c, wi)| points[c][k] as f64 * wi / total)
                            .sum()
                    })
                    .collect()
            })
            .collect();
        let times = frame_times(t, options.fps);
        let mut frames_out = Vec::with_capacity(times.len() * dims);
        for &time in &times {
            let mut acc = vec![0.0; dims];
            let mut wsum = 0.0;
            for (s, target) in segments.iter().zip(&targets) {
                let alpha = DOMINANCE[s.phone.viseme() as usize];
                let centre = 0.5 * (s.start + s.end);
                let gap = ((time - centre).abs() - s.duration() / 4.0).max(0.0);
                let w = alpha * (-gap / TAU).exp();
                acc.iter_mut().zip(target).for_each(|(a, v)| *a += w * v);
                wsum += w;
            }
            let row: Vec<f32> = acc.iter().map(|a| (a / wsum) as f32).collect();
            frames_out.extend_from_slice(&pose);
            frames_out.extend_from_slice(&row[POSE_DIMS..]);
        }
        // The labels end with the last frame's interval.
        let end = times.len() as f64 / options.fps;
        if let Some(last) = segments.last_mut() {
            last.end = end;
        }
        out.push(GeneratedSentence {
            sentence: Sentence {
                name: format!("demo{:02}", index + 1),
                source: "generated demo corpus".into(),
                frames: Frames::from_rows(layout, options.fps, frames_out)?,
                segments,
            },
            text: text.to_string(),
            split: split_of(index),
        });
    }
    let phone_targets = candidates
        .iter()
        .zip(&phone_weights)
        .map(|(cands, w)| {
            let total: f64 = w.iter().sum();
            (0..dims)
                .map(|k| {
                    cands
                        .iter()
                        .zip(w)
                        .map(|(&c, wi)| points[c][k] as f64 * wi / total)
                        .sum::<f64>() as f32
                })
                .collect()
        })
        .collect();
    Ok(Corpus {
        sentences: out,
        still_frame: still,
        phone_targets,
    })
}
