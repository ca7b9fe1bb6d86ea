//! The face from the sound alone (issue 34): a talker's learnt map from what a window of
//! sound says to the face-space shape ‖ appearance of the frame at its centre.
//!
//! Recognised phones are a poor route to the lips without words: a phone error rate of
//! about 64 % on GRID's talker, and the blend then draws every wrong phone. The acoustic
//! model hears more than its best path says. Per 10 ms frame the evidence is the 13
//! mean-normalised cepstra and, for each context-independent phone, a posterior from its
//! best state's likelihood, `exp(κ·(ℓ − max ℓ))` normalised over phones (κ softens the
//! model's over-sharp likelihoods), and its logarithm. A window of ±[`HALF_WINDOW`] frames every
//! [`TAP_STEP`]-th, and a constant, goes through a ridge regression
//! `W = (XᵀX + λ I)⁻¹ XᵀY` learnt on the talker's codebook sentences and their recordings:
//! the classic linear audio-to-visual mapping, with the phone posteriors as its nonlinear
//! features — and beside it one hidden layer of rectified units learnt on what the ridge
//! leaves ([`network`]). Window, κ, λ and the layer were chosen on GRID s1's validation
//! split (BENCHMARKS.md).
//!
//! Learnt from the same windows, the talker's own ear ([`PhoneClassifier`]) hears his phones
//! far better than the general acoustic model does: it recognises phones without words and
//! judges whether given words fit the sound.
//!
//! The folder: `sound-to-face.json` (its constants, the model's hash), `weights.npy`
//! (features × face-space parameters, f32), and for the layer `hidden_in.npy` (features ×
//! units) and `hidden_out.npy` (units × parameters): `face = x·W + relu(x·H_in)·H_out`,
//! `x = [window, 1]`; for the ear `phones_in.npy` (features × units), `phones_out.npy`
//! (units × phones) and `phones_bias.npy` (the outputs' bias, then each phone's log prior):
//! log-odds `relu(x·P_in)·P_out + bias`. Folders of versions 1 (the ridge alone) and 2 (no
//! ear) still load.

mod network;
mod phones;

pub use phones::{
    EAR_JUDGE, EAR_LEAST_EXAMPLES, GENERAL_FIT_WEIGHT, LEAST_FIT, LOOP_PENALTY, LOOP_WEIGHT, PhoneClassifier,
    WORST_WORD_WEIGHT, ear_fit, ear_matches, frame_labels,
};

use std::path::Path;

use nalgebra::DMatrix;
use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::align::{AlignError, Aligner};
use crate::codebook::Codebook;
use crate::facespace::Frames;
use crate::manifest::{self, ManifestError};
use crate::model::FaceModel;
use crate::phonemes::Segment;
use crate::{Progress, npy};

/// The folder format this build writes and reads.
pub const SOUND_TO_FACE_VERSION: u32 = 3;
const FORMAT: &str = "facespace-sound-to-face";
const MANIFEST: &str = "sound-to-face.json";
const WEIGHTS: &str = "weights.npy";
const HIDDEN_IN: &str = "hidden_in.npy";
const HIDDEN_OUT: &str = "hidden_out.npy";
const PHONES_IN: &str = "phones_in.npy";
const PHONES_OUT: &str = "phones_out.npy";
const PHONES_BIAS: &str = "phones_bias.npy";

/// Frames (10 ms) either side of a video frame's centre the map hears: ±200 ms, the span of
/// coarticulation (validation: ±100 ms lost 0.01 of r_pca, ±300 ms gained nothing).
pub const HALF_WINDOW: i64 = 20;
/// Every how many frames of the window a tap is taken.
pub const TAP_STEP: usize = 2;
/// Softening of the phone likelihoods into posteriors (validation: 0.1 and 1 worse than 0.3).
pub const KAPPA: f32 = 0.3;
/// Scale of the posteriors beside the cepstra (units of about 10).
const POSTERIOR_SCALE: f32 = 10.0;
/// The log posteriors too, clipped here (what is that unlikely is unlikely alike), and scaled
/// (validation: r_pca 0.778 → 0.798 with them).
const LEAST_LOG_POSTERIOR: f32 = -20.0;
const LOG_POSTERIOR_SCALE: f32 = 0.5;
/// The predicted motion about the utterance's mean, scaled up: a regression's output is a
/// conditional mean, and moves less than the face did. Chosen by the talker's own rule (lip
/// motion ≥ 0.9× real, the inner mouth's s.d. nearest real; GRID s1 validation, through
/// `say`): with the hidden layer s.d. 0.94× at 1, **0.98× at 1.05**, 1.03× at 1.1, lip motion
/// 1.01× / 1.06× / 1.10×, r unchanged (the ridge alone needed 1.15: s.d. 0.87× at 1).
pub const AMPLITUDE_GAIN: f32 = 1.05;
/// The least video frames of speech a map is learnt from by default: GRID s1's validation
/// split (30 clips) through `say`, mouth r_pca / inner r_h against 0.512 / 0.638 from
/// recognised phones — 2 sentences (150 frames) −0.008 / 0.292, 6 (450) 0.393 / 0.607, 20
/// (1 500, a minute of speech) 0.579 / 0.747, 80 0.737 / 0.807, 250 0.791 / 0.830, 741 0.798 /
/// 0.834.
pub const LEAST_FRAMES: usize = 1500;
/// Video frames predicted at a time.
const PREDICT_BLOCK: usize = 250;
/// Sentences heard side by side between two progress reports.
const CHUNK: usize = 32;
/// Sentences summed one after another (a chunk's groups are heard side by side).
const GROUP: usize = 4;
/// The ridge, per learnt frame of evidence summed (validation: flat from 100 to 1 000).
pub const RIDGE: f64 = 1000.0;

/// The map's share of the face, away from the bilabials, when the phones were heard by the
/// talker's own ear: the rest is the phones' own synthesis — two estimates of the face, each
/// wrong in its own way (GRID s1 validation, mouth r_pca / inner r_h: the map alone 0.854 /
/// 0.873, the ear's phones alone 0.853 / 0.864, shares 0.3 0.869 / 0.879, 0.5 and 0.7 0.874 /
/// 0.884, 0.7 with the lip motion nearer the recording's: 0.94× against 0.90×).
pub const MAP_SHARE: f32 = 0.7;

/// What can go wrong learning, loading or using a map.
#[derive(Debug, Error)]
pub enum SoundToFaceError {
    /// The manifest or weights are damaged or of another build.
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    /// The folder could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The folder.
        path: std::path::PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The sound could not be read or heard.
    #[error("{path}: {source}")]
    Sound {
        /// The recording.
        path: std::path::PathBuf,
        /// Why.
        source: Box<AlignError>,
    },
    /// The map was learnt with another model or acoustic model.
    #[error("{0}")]
    Mismatch(String),
    /// Nothing to learn from, or the sums would not solve.
    #[error("{0}")]
    Learn(String),
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Manifest {
    format: String,
    version: u32,
    model_hash: String,
    /// Context-independent phones of the acoustic model the posteriors come from.
    phones: usize,
    half_window: i64,
    tap_step: usize,
    kappa: f32,
    ridge: f64,
    /// The sentences it was learnt from.
    sentences: usize,
    frames: usize,
    /// Units of the hidden layer; 0 for the ridge alone (version 1).
    #[serde(default)]
    hidden: usize,
    /// Units of the phone classifier's layer; 0 for none (versions 1 and 2).
    #[serde(default)]
    phone_units: usize,
}

/// A talker's map from sound to face (see the module).
#[derive(Clone, Debug)]
pub struct SoundToFace {
    manifest: Manifest,
    /// Features × face-space parameters (shape ‖ appearance).
    weights: DMatrix<f32>,
    hidden: Option<network::Hidden>,
    phones: Option<PhoneClassifier>,
}

/// The evidence of every 10 ms frame of `samples`: 13 cepstra, then each phone's posterior,
/// then its log posterior.
fn evidence(aligner: &Aligner, samples: &[f32], rate: u32) -> Result<Vec<Vec<f32>>, AlignError> {
    Ok(evidence_rows(&aligner.acoustic_evidence(samples, rate)?))
}

/// The map's evidence rows of the aligner's [`crate::align::Evidence`].
pub fn evidence_rows(heard: &crate::align::Evidence) -> Vec<Vec<f32>> {
    heard
        .cepstra
        .iter()
        .zip(&heard.scores)
        .map(|(c, scores)| {
            let mut row: Vec<f32> = c.to_vec();
            let e: Vec<f32> = scores.iter().map(|s| (s * KAPPA).exp()).collect();
            let z: f32 = e.iter().sum();
            row.extend(e.iter().map(|v| v / z * POSTERIOR_SCALE));
            let log_z = z.ln();
            row.extend(
                scores
                    .iter()
                    .map(|s| (s * KAPPA - log_z).max(LEAST_LOG_POSTERIOR) * LOG_POSTERIOR_SCALE),
            );
            row
        })
        .collect()
}

fn taps() -> impl Iterator<Item = i64> {
    (-HALF_WINDOW..=HALF_WINDOW).step_by(TAP_STEP)
}

/// How much of the phones' own synthesis a frame at `t` seconds keeps: 1 inside a bilabial
/// /p b m/ of `target` (the lips must close there, and a regression's conditional mean only
/// narrows them — the recogniser finds these phones well), ½ within a frame of one, else 0.
pub fn closure_weight(target: &[Segment], t: f64, fps: f64) -> f32 {
    let near = |margin: f64| {
        target.iter().any(|p| {
            matches!(p.phone.name(), "p" | "b" | "m") && t >= p.start - margin && t < p.end + margin
        })
    };
    if near(0.0) {
        1.0
    } else if near(1.0 / fps) {
        0.5
    } else {
        0.0
    }
}

/// The feature rows of the video frames `frames` (at `fps`): the evidence window around each
/// frame's time, edges repeated, then a constant.
fn design(evidence: &[Vec<f32>], frames: std::ops::Range<usize>, fps: f64) -> DMatrix<f64> {
    design_at(evidence, frames.len(), |i| centre(frames.start + i, fps))
}

/// The evidence frame (10 ms) at the time of video frame `frame` at `fps`.
fn centre(frame: usize, fps: f64) -> i64 {
    (frame as f64 / fps * 100.0).round() as i64
}

/// A sentence heard while learning: its evidence rows, frame rate, face (frames ×
/// shape ‖ appearance) and the phone of each evidence row ([`frame_labels`]).
struct Heard {
    evidence: Vec<Vec<f32>>,
    fps: f64,
    face: DMatrix<f64>,
    labels: Vec<Option<u8>>,
}

/// Each feature of a window's design row standardised (for the hidden layer and the ear):
/// the mean and s.d. of its evidence feature over every frame heard, alike at every tap.
fn standardisation(heard: &[Heard]) -> (Vec<f32>, Vec<f32>) {
    let width = heard[0].evidence[0].len();
    let stats: Vec<(f64, f64)> = (0..width)
        .map(|k| {
            let values: Vec<f64> = heard
                .iter()
                .flat_map(|h| h.evidence.iter().map(move |row| f64::from(row[k])))
                .collect();
            crate::eval::mean_and_sd(&values)
        })
        .collect();
    let d = taps().count() * width;
    let mean = (0..d).map(|j| stats[j % width].0 as f32).collect();
    let scale = (0..d).map(|j| stats[j % width].1 as f32).collect();
    (mean, scale)
}

/// Learns the hidden layer on what the ridge `weights` leave of `heard`, and adds its
/// outputs' bias to the ridge's constant.
fn learn_hidden(
    heard: &[Heard],
    (mean, scale): (&[f32], &[f32]),
    weights: &mut DMatrix<f64>,
    mut progress: impl FnMut(usize),
) -> network::Hidden {
    let d = weights.nrows() - 1;
    let index: Vec<(usize, i64)> = heard
        .iter()
        .enumerate()
        .flat_map(|(s, h)| (0..h.face.nrows()).map(move |i| (s, centre(i, h.fps))))
        .collect();
    let k = weights.ncols();
    let mut residual = DMatrix::<f32>::zeros(index.len(), k);
    let mut start = 0;
    for h in heard {
        let n = h.face.nrows();
        let left = &h.face - design(&h.evidence, 0..n, h.fps) * &*weights;
        residual
            .rows_mut(start, n)
            .copy_from(&left.map(|v| v as f32));
        start += n;
    }
    // The outputs in units of the face's own spread.
    let target_scale: Vec<f32> = (0..k)
        .map(|c| {
            let values: Vec<f64> = heard
                .iter()
                .flat_map(|h| (0..h.face.nrows()).map(move |i| h.face[(i, c)]))
                .collect();
            (crate::eval::mean_and_sd(&values).1 as f32).max(1e-12)
        })
        .collect();
    let examples = network::Examples {
        rows: index.len(),
        features: d,
        row: |i: usize, out: &mut [f32]| {
            let (s, centre) = index[i];
            window_into(&heard[s].evidence, centre, out);
        },
        mean,
        scale,
        target: network::Target::Values {
            residual: &residual,
            scale: &target_scale,
        },
    };
    let (hidden, bias) = network::learn(&examples, network::MAP, &mut progress);
    for (c, b) in bias.into_iter().enumerate() {
        weights[(d, c)] += f64::from(b);
    }
    hidden
}

// The ear's even frames read only even frames' evidence ([`ear_scores`]).
const _: () = assert!(TAP_STEP.is_multiple_of(2), "the ear's even frames must read only even frames");

/// The classifier's scores of every phone in every frame `heard`, a block of frames at a time:
/// heard at every other frame (pocketsphinx's frame downsampling, `-ds 2`: the window's taps
/// are [`TAP_STEP`] apart, so those frames read only each other's evidence), the frames
/// between taken midway.
fn ear_scores(classifier: &PhoneClassifier, heard: &crate::align::Evidence) -> Vec<Vec<f32>> {
    let ev = evidence_rows(heard);
    let even: Vec<usize> = (0..ev.len()).step_by(2).collect();
    let mut scores = Vec::with_capacity(even.len());
    for block in even.chunks(PREDICT_BLOCK) {
        let x: DMatrix<f32> = design_at(&ev, block.len(), |i| block[i] as i64);
        scores.extend(classifier.scores(&x));
    }
    crate::align::every_other(scores, ev.len(), |a, b| a.iter().zip(b).map(|(x, y)| 0.5 * (x + y)).collect())
}

/// The feature rows of `rows` windows, the `i`-th centred on evidence frame `centre(i)`, in
/// f64 to learn from or straight in f32 to predict with.
fn design_at<T: nalgebra::RealField + Copy + From<f32>>(
    evidence: &[Vec<f32>],
    rows: usize,
    centre: impl Fn(usize) -> i64,
) -> DMatrix<T> {
    let width = evidence.first().map_or(0, Vec::len);
    let d = taps().count() * width + 1;
    let mut x = DMatrix::zeros(rows, d);
    let mut row = vec![0f32; d - 1];
    for i in 0..rows {
        window_into(evidence, centre(i), &mut row);
        for (j, &v) in row.iter().enumerate() {
            x[(i, j)] = T::from(v);
        }
        x[(i, d - 1)] = T::one();
    }
    x
}

/// The window of evidence around frame `centre` (every tap's row in turn, edges repeated)
/// into `out`, without the constant.
fn window_into(evidence: &[Vec<f32>], centre: i64, out: &mut [f32]) {
    let width = evidence.first().map_or(0, Vec::len);
    let last = evidence.len() as i64 - 1;
    for (tap, offset) in taps().enumerate() {
        let t = (centre + offset).clamp(0, last) as usize;
        out[tap * width..(tap + 1) * width].copy_from_slice(&evidence[t]);
    }
}

/// The ridge regression's weights from its sums: `(XᵀX + λ I)⁻¹ XᵀY`, the last feature (the
/// constant) not shrunk.
fn ridge(mut xtx: DMatrix<f64>, xty: DMatrix<f64>, lambda: f64) -> Option<DMatrix<f64>> {
    let d = xtx.nrows();
    for j in 0..d.saturating_sub(1) {
        xtx[(j, j)] += lambda;
    }
    let l = cholesky(xtx)?;
    let inner = solve_lower(&l, xty)?;
    solve_lower_transposed(&l, inner)
}

/// `L⁻¹ B` for a lower-triangular `l`, by blocks of rows: each block's earlier rows taken off
/// by one matrix product, then its own small triangle solved — nalgebra's solve subtracts a
/// column at a time. `None` for a zero on the diagonal.
fn solve_lower(l: &DMatrix<f64>, mut b: DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = l.nrows();
    let mut k = 0;
    while k < n {
        let s = CHOLESKY_BLOCK.min(n - k);
        let (done, mut block) = b.rows_range_pair_mut(..k, k..k + s);
        block.gemm(-1.0, &l.view((k, 0), (s, k)), &done, 1.0);
        let solved = l.view((k, k), (s, s)).solve_lower_triangular(&block)?;
        block.copy_from(&solved);
        k += s;
    }
    Some(b)
}

/// `L⁻ᵀ B` for a lower-triangular `l`, by blocks of rows from the last, as [`solve_lower`].
fn solve_lower_transposed(l: &DMatrix<f64>, mut b: DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = l.nrows();
    let mut end = n;
    while end > 0 {
        let k = end.saturating_sub(CHOLESKY_BLOCK);
        let (mut block, done) = b.rows_range_pair_mut(k..end, end..);
        // The rows below the block, transposed once so the product runs blocked.
        let below = l.view((end, k), (n - end, end - k)).transpose();
        block.gemm(-1.0, &below, &done, 1.0);
        let solved = l.view((k, k), (end - k, end - k)).tr_solve_lower_triangular(&block)?;
        block.copy_from(&solved);
        end = k;
    }
    Some(b)
}

/// Columns factored at a time by [`cholesky`].
const CHOLESKY_BLOCK: usize = 64;

/// The lower Cholesky factor L (A = L Lᵀ) of a symmetric positive definite `a`, by blocks of
/// columns (Golub & Van Loan, Algorithm 4.2.10's right-looking form): each diagonal block by
/// nalgebra, the panel below it by a triangular solve, and the rest updated by one matrix
/// product, which runs at matrix-product speed where nalgebra's own factorisation updates a
/// vector at a time (2 038 × 2 038: most of a one-sentence `talker sound-to-face`). `None`
/// when `a` is not positive definite.
fn cholesky(mut a: DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = a.nrows();
    let mut k = 0;
    while k < n {
        let b = CHOLESKY_BLOCK.min(n - k);
        let l11 = a.view((k, k), (b, b)).into_owned().cholesky()?.l();
        let rest = n - k - b;
        if rest > 0 {
            // L21 = A21 L11⁻ᵀ, i.e. L11 L21ᵀ = A21ᵀ; then A22 −= L21 L21ᵀ.
            let l21t = l11.solve_lower_triangular(&a.view((k + b, k), (rest, b)).transpose())?;
            let l21 = l21t.transpose();
            a.view_mut((k + b, k + b), (rest, rest))
                .gemm(-1.0, &l21, &l21t, 1.0);
            a.view_mut((k + b, k), (rest, b)).copy_from(&l21);
        }
        a.view_mut((k, k), (b, b)).copy_from(&l11);
        k += b;
    }
    a.fill_upper_triangle(0.0, 1);
    Some(a)
}

impl SoundToFace {
    /// Learns the map from `codebook`'s sentences and their recordings in `recordings`
    /// (`NAME.mp4`, by sentence name); sentences without a recording, or whose recording has
    /// no sound, are skipped. Refused under `least_frames` video frames heard
    /// ([`LEAST_FRAMES`]).
    pub fn learn(
        model: &FaceModel,
        codebook: &Codebook,
        aligner: &Aligner,
        recordings: &Path,
        least_frames: usize,
        mut progress: impl FnMut(Progress),
    ) -> Result<SoundToFace, SoundToFaceError> {
        codebook
            .check_model(model)
            .map_err(|e| SoundToFaceError::Mismatch(e.to_string()))?;
        let params = codebook.layout.params_range();
        let total = codebook.sentences.len();
        let stage = "learning the face from the sound";
        // The sums XᵀX and XᵀY over chunks heard side by side (the progress told between
        // them), each chunk summed as it is heard: one sentence's XᵀX is 33 MB. The
        // sentences' evidence is kept for the hidden layer.
        type Sums = Option<(DMatrix<f64>, DMatrix<f64>, Vec<Heard>)>;
        let add = |a: Sums, b: Sums| match (a, b) {
            (Some(mut a), Some(b)) => {
                a.2.extend(b.2);
                Some((a.0 + b.0, a.1 + b.1, a.2))
            }
            (a, b) => a.or(b),
        };
        let mut sums: Sums = None;
        for (c, chunk) in codebook.sentences.chunks(CHUNK).enumerate() {
            progress(Progress { stage, done: c * CHUNK, total });
            let hear = |s: &crate::corpus::Sentence| -> Result<Sums, SoundToFaceError> {
                let path = recordings.join(format!("{}.mp4", s.name));
                if !path.is_file() {
                    return Ok(None);
                }
                let sound_error = |source: AlignError| SoundToFaceError::Sound {
                    path: path.clone(),
                    source: Box::new(source),
                };
                let sound = match crate::audio::read(
                    &path,
                    crate::align::frontend::SAMPLE_RATE,
                    crate::align::MAX_SECONDS,
                ) {
                    Ok(sound) => sound,
                    // A silent video teaches nothing here, and is no error.
                    Err(crate::audio::AudioError::NoAudio { .. }) => return Ok(None),
                    Err(e) => return Err(sound_error(e.into())),
                };
                let ev = evidence(aligner, &sound.samples, sound.rate).map_err(sound_error)?;
                let x = design(&ev, 0..s.frames.len(), s.frames.fps());
                let y = DMatrix::from_fn(s.frames.len(), params.len(), |i, j| {
                    f64::from(s.frames.row(i)[params.start + j])
                });
                // Through the transpose's copy, so that the products run as blocked matrix
                // products (`matrixmultiply`); `tr_mul` takes one dot product per element, half
                // of a whole `talker sound-to-face`.
                let xt = x.transpose();
                let sums = (&xt * &x, &xt * &y);
                let heard = Heard {
                    labels: frame_labels(&s.segments, ev.len(), &aligner.model),
                    evidence: ev,
                    fps: s.frames.fps(),
                    face: y,
                };
                Ok(Some((sums.0, sums.1, vec![heard])))
            };
            // Summed in groups of a fixed size and then in order, so that the sums — and the
            // map — do not depend on how the threads shared the work.
            let groups = chunk
                .par_chunks(GROUP)
                .map(|group| group.iter().try_fold(None, |a, s| Ok(add(a, hear(s)?))))
                .collect::<Result<Vec<Sums>, SoundToFaceError>>()?;
            sums = groups.into_iter().fold(sums, add);
        }
        progress(Progress { stage, done: total, total });
        let Some((xtx, xty, heard)) = sums else {
            return Err(SoundToFaceError::Learn(format!(
                "no recording of the codebook's sentences with sound in {} (give the folder of the codebook's videos, NAME.mp4)",
                recordings.display()
            )));
        };
        let (frames, sentences) = (heard.iter().map(|h| h.face.nrows()).sum::<usize>(), heard.len());
        if frames < least_frames {
            return Err(SoundToFaceError::Learn(format!(
                "only {frames} frames of the codebook's recordings have sound (at least {least_frames} needed: a map learnt on less follows the lips worse than recognised phones)"
            )));
        }
        let mut weights = ridge(xtx, xty, RIDGE)
            .ok_or_else(|| SoundToFaceError::Learn("the sums are not positive definite".into()))?;
        // One standardisation of the windows serves the hidden layer and the ear.
        let (mean, scale) = standardisation(&heard);
        let stage = "learning the face from the sound: its hidden layer";
        let hidden = learn_hidden(&heard, (&mean, &scale), &mut weights, |done| {
            progress(Progress { stage, done, total: network::EPOCHS })
        });
        let phones = aligner.model.ci_names.len();
        let stage = "learning the talker's phones";
        let classifier = PhoneClassifier::learn(&heard, phones, (&mean, &scale), |done| {
            progress(Progress { stage, done, total: phones::SCHEDULE.epochs })
        });
        Ok(SoundToFace {
            manifest: Manifest {
                format: FORMAT.into(),
                version: SOUND_TO_FACE_VERSION,
                model_hash: model.hash(),
                phones,
                half_window: HALF_WINDOW,
                tap_step: TAP_STEP,
                kappa: KAPPA,
                ridge: RIDGE,
                sentences,
                frames,
                hidden: network::UNITS,
                phone_units: phones::SCHEDULE.units,
            },
            weights: weights.map(|v| v as f32),
            hidden: Some(hidden),
            phones: Some(classifier),
        })
    }

    /// The face-space shape ‖ appearance of each of `frames` frames at `fps` (rows), from
    /// what the acoustic model heard in the sound ([`Aligner::acoustic_evidence`]).
    pub fn predict(&self, heard: &crate::align::Evidence, frames: usize, fps: f64) -> DMatrix<f32> {
        let ev = evidence_rows(heard);
        // In blocks of frames: ten minutes of speech would make a 0.25 GB design matrix.
        let mut face = DMatrix::zeros(frames, self.weights.ncols());
        for start in (0..frames).step_by(PREDICT_BLOCK) {
            let block = start..(start + PREDICT_BLOCK).min(frames);
            let x = design(&ev, block.clone(), fps).map(|v| v as f32);
            face.rows_mut(start, block.len()).copy_from(&self.face_of(&x));
        }
        face
    }

    /// The shape ‖ appearance of frames centred on the evidence frames `centres` of
    /// `evidence` (rows of [`evidence_rows`]; windows reaching past either end repeat it),
    /// the motion scaled by [`AMPLITUDE_GAIN`] about `mean`: a live session's frames, whose
    /// utterance is not over.
    pub fn predict_centred(&self, evidence: &[Vec<f32>], centres: &[i64], mean: &[f32]) -> Vec<Vec<f32>> {
        if evidence.is_empty() {
            return vec![mean.to_vec(); centres.len()];
        }
        let x: DMatrix<f32> = design_at(evidence, centres.len(), |i| centres[i]);
        let face = self.face_of(&x);
        face.row_iter()
            .map(|row| {
                row.iter()
                    .zip(mean)
                    .map(|(v, m)| m + AMPLITUDE_GAIN * (v - m))
                    .collect()
            })
            .collect()
    }

    /// [`Self::predict`] with the motion scaled by [`AMPLITUDE_GAIN`] about the utterance's
    /// own mean: the face a whole recording without its words says.
    pub fn predict_utterance(&self, heard: &crate::align::Evidence, frames: usize, fps: f64) -> DMatrix<f32> {
        let mut face = self.predict(heard, frames, fps);
        for mut column in face.column_iter_mut() {
            let mean = column.mean();
            column.apply(|v| *v = mean + AMPLITUDE_GAIN * (*v - mean));
        }
        face
    }

    /// Writes `face` (frames × shape ‖ appearance, [`Self::predict_utterance`]) into
    /// `frames`, keeping their poses, and their own shape and appearance at the bilabials of
    /// `target`, the phones they were synthesised from ([`closure_weight`]); elsewhere the
    /// map's face takes [`MAP_SHARE`] when this map's own ear heard those phones, all of it
    /// when the general acoustic model did (its phones are too often wrong to blend in).
    pub fn apply(&self, face: &DMatrix<f32>, frames: &mut Frames, target: &[Segment]) {
        let share = if self.hears_phones() { MAP_SHARE } else { 1.0 };
        let params = frames.layout().params_range();
        let fps = frames.fps();
        let n = frames.len().min(face.nrows());
        let mut values = frames.values_mut();
        for i in 0..n {
            let keep = closure_weight(target, i as f64 / fps, fps);
            let keep = keep + (1.0 - keep) * (1.0 - share);
            for (j, p) in params.clone().enumerate() {
                values[(i, p)] = keep * values[(i, p)] + (1.0 - keep) * face[(i, j)];
            }
        }
    }

    /// The face of the design rows `x`: the ridge's, plus the hidden layer's.
    fn face_of(&self, x: &DMatrix<f32>) -> DMatrix<f32> {
        let mut face = x * &self.weights;
        if let Some(hidden) = &self.hidden {
            hidden.add_to(x, &mut face);
        }
        face
    }

    /// The phones of `samples` at `rate` (16 kHz) heard by the talker's own classifier
    /// ([`PhoneClassifier`]) through the phone loop its scores were weighed with
    /// ([`phones::LOOP_WEIGHT`], [`phones::LOOP_PENALTY`]); `None` for a map without one
    /// (learnt before it). Sound that is not speech is refused as [`Aligner::recognise`]
    /// refuses it. With the phones, the evidence they were heard by
    /// ([`Self::predict_utterance`] draws the face from it).
    pub fn recognise(
        &self,
        aligner: &Aligner,
        samples: &[f32],
        rate: u32,
    ) -> Result<Option<(Vec<crate::align::TimedPhone>, crate::align::Evidence)>, AlignError> {
        let lm = aligner.phone_loop(phones::LOOP_WEIGHT, phones::LOOP_PENALTY);
        self.recognise_through(aligner, samples, rate, &lm)
    }

    /// The phones of `text` aligned to `samples` at `rate` (16 kHz) by the general acoustic
    /// model, refused when the words
    /// do not fit the sound as the talker's own classifier and the general model hear it
    /// ([`ear_fit`] under [`LEAST_FIT`]: [`AlignError::WordsDoNotMatch`] naming the worst
    /// words); `None` for a map without a classifier.
    pub fn hear_words(
        &self,
        aligner: &Aligner,
        samples: &[f32],
        rate: u32,
        text: &str,
    ) -> Result<Option<Vec<crate::align::TimedPhone>>, AlignError> {
        let Some((alignment, fit, general)) = self.align_checked(aligner, samples, rate, text)? else {
            return Ok(None);
        };
        if !ear_matches(&fit, &general) {
            return Err(AlignError::WordsDoNotMatch {
                judge: EAR_JUDGE,
                overall: ear_fit(&fit, &general),
                least: LEAST_FIT,
                worst: fit.worst_words(&alignment.words, 3),
            });
        }
        Ok(Some(alignment.phones))
    }

    /// Whether the map has its own phone classifier ([`Self::recognise`]).
    pub fn hears_phones(&self) -> bool {
        self.phones.is_some()
    }

    /// [`Self::recognise`] through the phone loop `lm`.
    pub fn recognise_through(
        &self,
        aligner: &Aligner,
        samples: &[f32],
        rate: u32,
        lm: &crate::align::PhoneLoop,
    ) -> Result<Option<(Vec<crate::align::TimedPhone>, crate::align::Evidence)>, AlignError> {
        let Some(classifier) = &self.phones else {
            return Ok(None);
        };
        let ear = |heard: &crate::align::Evidence| ear_scores(classifier, heard);
        let free = aligner.phone_loop(crate::align::PHONE_WEIGHT, crate::align::PHONE_PENALTY);
        aligner.recognise_by(samples, rate, &free, ear, lm).map(Some)
    }

    /// `text` aligned to `samples` at `rate` (16 kHz), and how well its words fit the sound
    /// as the talker's own classifier hears it (sharper than the general acoustic model's
    /// fit) and as the general model does ([`Aligner::align_checked_by`]; together
    /// [`ear_fit`]); `None` for a map without a classifier.
    pub fn align_checked(
        &self,
        aligner: &Aligner,
        samples: &[f32],
        rate: u32,
        text: &str,
    ) -> Result<Option<(crate::align::Alignment, crate::align::WordFit, crate::align::WordFit)>, AlignError> {
        let Some(classifier) = &self.phones else {
            return Ok(None);
        };
        let general = aligner.phone_loop(crate::align::PHONE_WEIGHT, crate::align::PHONE_PENALTY);
        let lm = aligner.phone_loop(phones::LOOP_WEIGHT, phones::LOOP_PENALTY);
        let ear = |heard: &crate::align::Evidence| ear_scores(classifier, heard);
        aligner.align_checked_by(samples, rate, text, &general, ear, &lm).map(Some)
    }

    /// Sentences and frames it was learnt from.
    pub fn learnt_from(&self) -> (usize, usize) {
        (self.manifest.sentences, self.manifest.frames)
    }

    /// Writes the folder `dir` atomically (replacing an earlier map).
    pub fn save(&self, dir: &Path) -> Result<(), SoundToFaceError> {
        let io = |source| SoundToFaceError::Io {
            path: dir.into(),
            source,
        };
        let array = |m: &DMatrix<f32>| Array2::from_shape_fn(m.shape(), |(i, j)| m[(i, j)]);
        let write = |staged: &Path, name: &str, m: &DMatrix<f32>| {
            npy::write(&staged.join(name), array(m).view())
                .map_err(|e| SoundToFaceError::Manifest(e.into()))
        };
        crate::atomic::replace_dir(
            dir,
            FORMAT,
            |staged| {
                write(staged, WEIGHTS, &self.weights)?;
                if let Some(hidden) = &self.hidden {
                    write(staged, HIDDEN_IN, &hidden.input)?;
                    write(staged, HIDDEN_OUT, &hidden.output)?;
                }
                if let Some(phones) = &self.phones {
                    write(staged, PHONES_IN, &phones.hidden.input)?;
                    write(staged, PHONES_OUT, &phones.hidden.output)?;
                    write(staged, PHONES_BIAS, &phones.bias_and_prior)?;
                }
                let json = serde_json::to_vec_pretty(&self.manifest).expect("manifest serialises");
                crate::atomic::write_file(&staged.join(MANIFEST), &json).map_err(io)
            },
            io,
        )
    }

    /// Loads the folder `dir` for `model` (its hash checked) and the acoustic model of
    /// `aligner` (its phone count checked).
    pub fn load(dir: &Path, model: &FaceModel, phones: usize) -> Result<SoundToFace, SoundToFaceError> {
        Self::load_for(dir, model, &model.hash(), phones)
    }

    /// [`SoundToFace::load`] with the model's hash already taken (it reads every array of it).
    pub(crate) fn load_for(
        dir: &Path,
        model: &FaceModel,
        model_hash: &str,
        phones: usize,
    ) -> Result<SoundToFace, SoundToFaceError> {
        let (m, _): (Manifest, _) =
            manifest::read_versions(&dir.join(MANIFEST), FORMAT, 1..=SOUND_TO_FACE_VERSION)?;
        if m.model_hash != model_hash {
            return Err(SoundToFaceError::Mismatch(format!(
                "{}: learnt with another face model (learn it again)",
                dir.display()
            )));
        }
        if (m.half_window, m.tap_step, m.kappa) != (HALF_WINDOW, TAP_STEP, KAPPA) || m.phones != phones {
            return Err(SoundToFaceError::Mismatch(format!(
                "{}: learnt with other constants or another acoustic model (learn it again)",
                dir.display()
            )));
        }
        let width = crate::align::frontend::N_CEP + 2 * phones;
        let d = taps().count() * width + 1;
        let k = model.layout().params_range().len();
        let read = |name: &str, rows: usize, cols: usize| -> Result<DMatrix<f32>, SoundToFaceError> {
            let w: Array2<f32> = manifest::read_array(dir, name, &[Some(rows), Some(cols)])?;
            if w.iter().any(|v| !v.is_finite()) {
                return Err(SoundToFaceError::Mismatch(format!(
                    "{}: {name} not finite",
                    dir.display()
                )));
            }
            Ok(DMatrix::from_fn(rows, cols, |i, j| w[(i, j)]))
        };
        let weights = read(WEIGHTS, d, k)?;
        let hidden = match m.hidden {
            0 => None,
            units => Some(network::Hidden {
                input: read(HIDDEN_IN, d, units)?,
                output: read(HIDDEN_OUT, units, k)?,
            }),
        };
        let phones = match m.phone_units {
            0 => None,
            units => Some(PhoneClassifier {
                hidden: network::Hidden {
                    input: read(PHONES_IN, d, units)?,
                    output: read(PHONES_OUT, units, phones)?,
                },
                bias_and_prior: read(PHONES_BIAS, 2, phones)?,
            }),
        };
        Ok(SoundToFace {
            manifest: m,
            weights,
            hidden,
            phones,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against an independent reference: the least-squares solution of X stacked over
    /// √λ·I (the constant's row left out), by SVD.
    #[test]
    fn ridge_is_the_least_squares_of_the_augmented_system() {
        let mut rng = crate::rng::Rng::new(7);
        let (n, d, k, lambda) = (40, 6, 3, 2.5);
        let x = DMatrix::from_fn(n, d, |_, j| if j == d - 1 { 1.0 } else { rng.normal() });
        let y = DMatrix::from_fn(n, k, |_, _| rng.normal());
        let w = ridge(x.tr_mul(&x), x.tr_mul(&y), lambda).unwrap();
        let mut a = DMatrix::zeros(n + d - 1, d);
        a.rows_mut(0, n).copy_from(&x);
        for j in 0..d - 1 {
            a[(n + j, j)] = lambda.sqrt();
        }
        let mut b = DMatrix::zeros(n + d - 1, k);
        b.rows_mut(0, n).copy_from(&y);
        let reference = a.svd(true, true).solve(&b, 1e-12).unwrap();
        assert!((w - reference).abs().max() < 1e-10);
    }

    /// The blocked solves are nalgebra's column-at-a-time ones, over sizes with a partial last
    /// block, and a zero on the diagonal is refused.
    #[test]
    fn blocked_triangular_solves_match_nalgebras() {
        let mut rng = crate::rng::Rng::new(7);
        for n in [1, 63, 64, 65, 200] {
            let m = DMatrix::from_fn(n + 3, n, |_, _| rng.normal());
            let l = cholesky(m.tr_mul(&m) + DMatrix::identity(n, n)).unwrap();
            let b = DMatrix::from_fn(n, 5, |_, _| rng.normal());
            let forward = solve_lower(&l, b.clone()).unwrap();
            let backward = solve_lower_transposed(&l, b.clone()).unwrap();
            assert!((&forward - l.solve_lower_triangular(&b).unwrap()).amax() < 1e-9);
            assert!((&backward - l.tr_solve_lower_triangular(&b).unwrap()).amax() < 1e-9);
            assert!((&l * &forward - &b).amax() < 1e-9);
            assert!((l.transpose() * &backward - &b).amax() < 1e-9);
        }
        let singular = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 1.0, 0.0]);
        assert!(solve_lower(&singular, DMatrix::identity(2, 1)).is_none());
    }

    /// The blocked factor is nalgebra's unblocked one (an independent implementation), over
    /// sizes with a partial last block, and a matrix that is not positive definite is refused.
    #[test]
    fn blocked_cholesky_is_the_cholesky_factor() {
        let mut rng = crate::rng::Rng::new(9);
        for n in [1, 63, 64, 150] {
            let m = DMatrix::from_fn(n + 5, n, |_, _| rng.normal());
            let a = m.tr_mul(&m) + DMatrix::identity(n, n);
            let ours = cholesky(a.clone()).unwrap();
            let reference = a.clone().cholesky().unwrap().l();
            assert!((&ours - &reference).abs().max() < 1e-9 * reference.abs().max(), "n = {n}");
        }
        let mut a = DMatrix::<f64>::identity(100, 100);
        a[(80, 80)] = -1.0;
        assert!(cholesky(a).is_none());
    }

    /// With no ridge an exact linear relation comes back exactly.
    #[test]
    fn ridge_without_shrinkage_recovers_an_exact_map() {
        let mut rng = crate::rng::Rng::new(3);
        let x = DMatrix::from_fn(30, 4, |_, j| if j == 3 { 1.0 } else { rng.normal() });
        let truth = DMatrix::from_fn(4, 2, |i, j| (i as f64) - 2.0 * j as f64);
        let w = ridge(x.tr_mul(&x), x.tr_mul(&(&x * &truth)), 0.0).unwrap();
        assert!((w - truth).abs().max() < 1e-9);
    }

    /// Inside a /p b m/ the phones' frame is kept whole, within a frame of one half, else not.
    #[test]
    fn closures_keep_the_phones_frames() {
        let seg = |phone: &str, start: f64, end: f64| Segment {
            phone: crate::phonemes::Phone::parse(phone).unwrap(),
            start,
            end,
        };
        let target = [seg("ah", 0.0, 0.4), seg("m", 0.4, 0.5), seg("iy", 0.5, 1.0)];
        let at = |t: f64| closure_weight(&target, t, 25.0);
        assert_eq!((at(0.2), at(0.37), at(0.4), at(0.49), at(0.52), at(0.6)), (0.0, 0.5, 1.0, 1.0, 0.5, 0.0));
        let vowels = [seg("ah", 0.0, 1.0)];
        assert_eq!(closure_weight(&vowels, 0.5, 25.0), 0.0);
    }

    /// Row i holds the evidence at i's time (100 frames a second) ± the window, edges repeated.
    #[test]
    fn the_design_reads_the_window_around_each_frame() {
        let evidence: Vec<Vec<f32>> = (0..300).map(|t| vec![t as f32, -(t as f32)]).collect();
        let x = design(&evidence, 0..75, 25.0);
        let taps: Vec<i64> = taps().collect();
        assert_eq!(x.ncols(), taps.len() * 2 + 1);
        for i in [0usize, 1, 37, 74] {
            for (k, t) in taps.iter().enumerate() {
                let at = (i as i64 * 4 + t).clamp(0, 299) as f64;
                assert_eq!(x[(i, 2 * k)], at);
                assert_eq!(x[(i, 2 * k + 1)], -at);
            }
            assert_eq!(x[(i, x.ncols() - 1)], 1.0);
        }
        // A block later in the recording reads the same rows as the whole.
        assert_eq!(design(&evidence, 30..60, 25.0), x.rows(30, 30).into_owned());
    }
}
