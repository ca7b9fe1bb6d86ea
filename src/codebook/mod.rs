//! The synthesis codebook (DESIGN §7): every corpus sentence as a continuous face-space
//! trajectory with its phone segments, an index of phone occurrences, the phoneme similarity
//! matrix S (\[blend\] §4.2) and the phoneme distance matrix M (\[unitsel\] eq. 5) — computed in
//! [`similarity`], stored by the `io` submodule.

mod io;
pub mod similarity;

use ndarray::Array2;
use thiserror::Error;

pub use io::CODEBOOK_VERSION;
pub use similarity::{SimilarityOptions, parameter_weights};

use crate::Progress;
use crate::corpus::Sentence;
use crate::facespace::{self, FacespaceError, Layout};
use crate::manifest::ManifestError;
use crate::model::FaceModel;
use crate::npy::NpyError;
use crate::options::{self, InvalidOption};
use crate::phonemes::{self, Phone, Segment};
use crate::trajectory::{Trajectory, TrajectoryError};

/// What can go wrong building, loading or using a codebook.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CodebookError {
    /// A file or folder could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The folder's manifest or arrays are damaged or of another version.
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    /// An array could not be written.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// A sentence's frames do not form a trajectory.
    #[error("sentence {name}: {source}")]
    Trajectory {
        /// The sentence.
        name: String,
        /// The cause.
        source: TrajectoryError,
    },
    /// A sentence that cannot join the codebook.
    #[error("sentence {name}: {reason}")]
    BadSentence {
        /// The sentence.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// Sentences of another layout or rate than the codebook's.
    #[error("sentence {name}: {source}")]
    Frames {
        /// The sentence.
        name: String,
        /// What differs.
        source: FacespaceError,
    },
    /// The codebook belongs to another model.
    #[error(
        "the codebook was built with model {codebook}, but the model given is {model}; use the model it was built with"
    )]
    ModelMismatch {
        /// The codebook's model hash.
        codebook: String,
        /// The given model's hash.
        model: String,
    },
    /// The codebook's layout is not the model's.
    #[error(transparent)]
    Layout(#[from] FacespaceError),
    /// An option out of range.
    #[error(transparent)]
    Option(#[from] InvalidOption),
    /// The corpus folder could not be read.
    #[error(transparent)]
    Corpus(#[from] crate::corpus::CorpusError),
}

/// Where a phone occurs: sentence index and segment index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Occurrence {
    /// Index into [`Codebook::sentences`].
    pub sentence: usize,
    /// Index into that sentence's segments.
    pub segment: usize,
}

/// The codebook: sentences, their trajectories, the occurrence index, S and M.
#[derive(Clone, Debug, PartialEq)]
pub struct Codebook {
    /// Frame rate of every sentence.
    pub fps: f64,
    /// Face-space layout of every sentence.
    pub layout: Layout,
    /// [`FaceModel::hash`] of the model the frames belong to, if known.
    pub model_hash: Option<String>,
    /// The constants S and M were computed with.
    pub options: SimilarityOptions,
    /// The photometric normalisation its sentences had ([`crate::corpus::Photometric`]):
    /// with `Sentence`, synthesis has the corpus's mean lighting and is re-lit for the
    /// background it is drawn on ([`crate::synth::backdrop::Backdrop::match_lighting`]).
    pub photometric: crate::corpus::Photometric,
    /// The corpus sentences.
    pub sentences: Vec<Sentence>,
    /// One PCHIP trajectory per sentence over all dims (pose included).
    pub trajectories: Vec<Trajectory>,
    /// Occurrences of each phone, indexed by [`Phone::index`] (zero-length segments left out).
    pub occurrences: Vec<Vec<Occurrence>>,
    /// Per sentence, the phone of every frame (the segment holding the frame's time; the
    /// last segment's phone past the labels' end).
    pub frame_phones: Vec<Vec<Phone>>,
    /// S, `Phone::COUNT²`; 1 on the diagonal, 0 to and from absent phones.
    pub similarity: Array2<f64>,
    /// M, `Phone::COUNT²`; 0 to and from absent phones.
    pub distance: Array2<f64>,
}

const N: usize = Phone::COUNT;

/// Equidistant samples per occurrence allowed (S's `samples`).
pub const MAX_SAMPLES: usize = 1000;

/// The phone of the segment holding time `t` (the nearest segment outside them).
pub fn phone_at(segments: &[Segment], t: f64) -> Phone {
    let i = segments.partition_point(|g| g.end <= t);
    segments
        .get(i)
        .or(segments.last())
        .map_or(Phone::SIL, |g| g.phone)
}

impl Codebook {
    /// Builds trajectories, the occurrence index, S and M from sentences of one layout and
    /// frame rate.
    pub fn build(
        sentences: Vec<Sentence>,
        fps: f64,
        layout: Layout,
        model_hash: Option<String>,
        options: SimilarityOptions,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Self, CodebookError> {
        let total = sentences.len() + 1;
        let mut cb = Self::assemble(sentences, fps, layout, model_hash, options, progress)?;
        cb.similarity = similarity::similarity_matrix(&cb);
        cb.distance = similarity::distance_matrix(&cb);
        progress(Progress {
            stage: "similarity",
            done: total,
            total,
        });
        Ok(cb)
    }

    /// [`Codebook::build`] but for S and M (left zero): the sentences checked, their
    /// trajectories and the occurrence index.
    pub(crate) fn assemble(
        sentences: Vec<Sentence>,
        fps: f64,
        layout: Layout,
        model_hash: Option<String>,
        options: SimilarityOptions,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Self, CodebookError> {
        facespace::check_fps(fps)?;
        options::count_in("samples per occurrence", options.samples, 2, MAX_SAMPLES)?;
        if let Some(g) = options.gamma {
            options::in_range("gamma", g, f64::MIN_POSITIVE, f64::MAX)?;
        }
        let total = sentences.len() + 1;
        let trajectories;
        for s in &sentences {
            let bad = |reason: String| CodebookError::BadSentence {
                name: s.name.clone(),
                reason,
            };
            layout
                .expect(s.frames.layout())
                .map_err(|source| CodebookError::Frames {
                    name: s.name.clone(),
                    source,
                })?;
            if s.frames.fps() != fps {
                return Err(bad(format!(
                    "frames at {} fps, the codebook's rate is {fps}",
                    s.frames.fps()
                )));
            }
            if s.frames.len() < 2 {
                return Err(bad(format!("{} frames (need at least 2)", s.frames.len())));
            }
            if s.segments.is_empty() {
                return Err(bad("no phone segments".into()));
            }
            let n = s.frames.len();
            let end = s.segments[s.segments.len() - 1].end;
            if end > (n + 1) as f64 / fps + 1e-9 {
                return Err(bad(format!(
                    "labels end at {end:.3} s, after the {n} frames ({:.3} s)",
                    n as f64 / fps
                )));
            }
        }
        // The PCHIP slopes of every sentence, in parallel (most of a large codebook's load).
        {
            use rayon::prelude::*;
            trajectories = sentences
                .par_iter()
                .map(|s| {
                    Trajectory::from_frames(&s.frames).map_err(|source| {
                        CodebookError::Trajectory {
                            name: s.name.clone(),
                            source,
                        }
                    })
                })
                .collect::<Result<Vec<_>, _>>()?;
        }
        progress(Progress {
            stage: "trajectories",
            done: sentences.len(),
            total,
        });
        let mut occurrences = vec![Vec::new(); N];
        for (si, s) in sentences.iter().enumerate() {
            for (gi, g) in s.segments.iter().enumerate() {
                if g.duration() > 0.0 {
                    occurrences[g.phone.index()].push(Occurrence {
                        sentence: si,
                        segment: gi,
                    });
                }
            }
        }
        let frame_phones = sentences
            .iter()
            .map(|s| {
                (0..s.frames.len())
                    .map(|i| phone_at(&s.segments, i as f64 / fps))
                    .collect()
            })
            .collect();
        Ok(Codebook {
            fps,
            layout,
            model_hash,
            options,
            photometric: crate::corpus::Photometric::None,
            sentences,
            trajectories,
            occurrences,
            frame_phones,
            similarity: Array2::zeros((N, N)),
            distance: Array2::zeros((N, N)),
        })
    }

    /// A content hash of what S and M are computed from — the frame rate, layout, options,
    /// and every sentence's segments and frames — and of S and M, in hex: a codebook loaded
    /// with the hash it was saved with keeps its stored S and M instead of computing them
    /// again (0.3 s for GRID's 741 sentences). FNV-1a 64 over 32-bit words.
    pub fn content_hash(&self) -> String {
        let mut words: Vec<u32> = Vec::new();
        let eat64 = |words: &mut Vec<u32>, v: f64| {
            let b = v.to_bits();
            words.extend([b as u32, (b >> 32) as u32]);
        };
        eat64(&mut words, self.fps);
        eat64(&mut words, self.layout.shape as f64);
        eat64(&mut words, self.layout.appearance as f64);
        let options = serde_json::to_string(&self.options).expect("options serialise");
        words.extend(options.bytes().map(u32::from));
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |words: &mut Vec<u32>| {
            for &w in words.iter() {
                h ^= u64::from(w);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
            words.clear();
        };
        eat(&mut words);
        for s in &self.sentences {
            eat64(&mut words, s.segments.len() as f64);
            for g in &s.segments {
                eat64(&mut words, g.start);
                eat64(&mut words, g.end);
                words.push(g.phone.index() as u32);
            }
            eat64(&mut words, s.frames.len() as f64);
            words.extend(s.frames.as_slice().iter().map(|v| v.to_bits()));
            eat(&mut words);
        }
        self.similarity
            .iter()
            .chain(&self.distance)
            .for_each(|&v| eat64(&mut words, v));
        eat(&mut words);
        format!("{h:016x}")
    }

    /// Builds a codebook of `model`'s face-space from a corpus folder (see
    /// [`crate::corpus::load_checked`]; labels within `tolerance` seconds of the frames' end).
    #[allow(clippy::too_many_arguments)]
    pub fn from_corpus(
        dir: &std::path::Path,
        model: &FaceModel,
        fps: f64,
        tier: Option<&str>,
        map: &phonemes::PhoneMap,
        options: SimilarityOptions,
        photometric: crate::corpus::Photometric,
        tolerance: f64,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Self, CodebookError> {
        let sentences = crate::corpus::load_checked(
            dir,
            fps,
            model.layout(),
            Some(&model.hash()),
            tier,
            map,
            tolerance,
        )?;
        Self::from_sentences(sentences, model, fps, options, photometric, progress)
    }

    /// Builds a codebook of `model`'s face-space from sentences tracked with it, normalised
    /// by `photometric`.
    pub fn from_sentences(
        mut sentences: Vec<Sentence>,
        model: &FaceModel,
        fps: f64,
        options: SimilarityOptions,
        photometric: crate::corpus::Photometric,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Self, CodebookError> {
        if photometric == crate::corpus::Photometric::Sentence {
            crate::corpus::recentre_appearance(&mut sentences);
        }
        let mut cb = Codebook::build(
            sentences,
            fps,
            model.layout(),
            Some(model.hash()),
            options,
            progress,
        )?;
        cb.photometric = photometric;
        Ok(cb)
    }

    /// The mean of every value over every frame of every sentence: the talker's average face
    /// in face space, what blending's deviations are measured from.
    pub fn mean(&self) -> Vec<f64> {
        let mut sum = vec![0f64; self.dims()];
        let mut frames = 0usize;
        for s in &self.sentences {
            for row in s.frames.values().rows() {
                sum.iter_mut()
                    .zip(row)
                    .for_each(|(a, &x)| *a += f64::from(x));
                frames += 1;
            }
        }
        sum.iter_mut().for_each(|a| *a /= frames.max(1) as f64);
        sum
    }

    /// Sentence `k`'s mean of every value over its frames.
    pub fn sentence_mean(&self, k: usize) -> Vec<f64> {
        let v = self.sentences[k].frames.values();
        let n = v.nrows().max(1) as f64;
        v.columns()
            .into_iter()
            .map(|c| c.iter().map(|&x| f64::from(x)).sum::<f64>() / n)
            .collect()
    }

    /// The mean appearance over every frame of every sentence (with
    /// [`crate::corpus::Photometric::Sentence`], the mean each sentence was re-centred on).
    pub fn appearance_mean(&self) -> Vec<f64> {
        self.mean()[self.layout.appearance_range()].to_vec()
    }

    /// Checks that the codebook's frames are `model`'s: the recorded model hash (when there
    /// is one) and the layout.
    pub fn check_model(&self, model: &FaceModel) -> Result<(), CodebookError> {
        self.check_model_hash(&model.hash(), model.layout())
    }

    /// [`Codebook::check_model`] given the model's hash and layout (a caller that holds the
    /// hash already: hashing a model reads every array).
    pub fn check_model_hash(&self, hash: &str, layout: Layout) -> Result<(), CodebookError> {
        if let Some(h) = &self.model_hash
            && h != hash
        {
            return Err(CodebookError::ModelMismatch {
                codebook: h.clone(),
                model: hash.to_owned(),
            });
        }
        layout.expect(self.layout)?;
        Ok(())
    }

    /// The median of each pose value over every frame: a neutral still pose.
    pub fn median_pose(&self) -> crate::shape::Similarity {
        // Selected, not sorted: live synthesis asks for it with every batch.
        let mut v: Vec<f32> = Vec::with_capacity(self.n_frames());
        let median = |k: usize| {
            v.clear();
            for s in &self.sentences {
                v.extend(s.frames.column(k).iter());
            }
            if v.is_empty() {
                return 0.0;
            }
            let middle = v.len() / 2;
            f64::from(*v.select_nth_unstable_by(middle, f32::total_cmp).1)
        };
        crate::shape::Similarity::from_array(std::array::from_fn(median))
    }

    /// Values per frame.
    pub fn dims(&self) -> usize {
        self.layout.dims()
    }

    /// Frames over every sentence.
    pub fn n_frames(&self) -> usize {
        self.sentences.iter().map(|s| s.frames.len()).sum()
    }

    /// Phones with at least one (non-empty) occurrence.
    pub fn present(&self) -> Vec<Phone> {
        Phone::all()
            .filter(|p| !self.occurrences[p.index()].is_empty())
            .collect()
    }

    /// The phones its sentences never say, and the mouth shapes (viseme classes, each named
    /// by its phones) none of them shows: what synthesis must borrow from the nearest present
    /// (issue 67: `talker build` reports it, so a recording can be completed).
    pub fn absent(&self) -> (Vec<Phone>, Vec<Vec<Phone>>) {
        let absent: Vec<Phone> = Phone::all().filter(|p| self.occurrences[p.index()].is_empty()).collect();
        let mut classes: Vec<Vec<Phone>> = Vec::new();
        for p in Phone::all() {
            let class: Vec<Phone> = Phone::all().filter(|q| q.viseme() == p.viseme()).collect();
            if class.iter().all(|q| absent.contains(q)) && !classes.contains(&class) {
                classes.push(class);
            }
        }
        (absent, classes)
    }

    /// S recomputed with other options (the same trajectories), e.g. without the shape.
    pub fn similarity_with(&self, options: &SimilarityOptions) -> Array2<f64> {
        let other = Codebook {
            options: options.clone(),
            ..self.clone()
        };
        similarity::similarity_matrix(&other)
    }

    /// S between two phones.
    pub fn similarity(&self, a: Phone, b: Phone) -> f64 {
        self.similarity[[a.index(), b.index()]]
    }

    /// M between two phones.
    pub fn distance(&self, a: Phone, b: Phone) -> f64 {
        self.distance[[a.index(), b.index()]]
    }

    /// The `k` present phones most similar to `p` (itself excluded), most similar first.
    pub fn nearest(&self, p: Phone, k: usize) -> Vec<(Phone, f64)> {
        let mut v: Vec<(Phone, f64)> = self
            .present()
            .into_iter()
            .filter(|&q| q != p)
            .map(|q| (q, self.similarity(p, q)))
            .collect();
        v.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        v.truncate(k);
        v
    }

    /// Mean duration of each phone in the corpus (seconds), the built-in table where absent.
    pub fn mean_durations(&self) -> [f64; N] {
        let mut d = phonemes::DEFAULT_DURATIONS;
        for p in self.present() {
            let occ = &self.occurrences[p.index()];
            d[p.index()] =
                occ.iter().map(|o| self.segment(*o).duration()).sum::<f64>() / occ.len() as f64;
        }
        d
    }

    /// The segment of an occurrence.
    pub fn segment(&self, o: Occurrence) -> &Segment {
        &self.sentences[o.sentence].segments[o.segment]
    }
}
