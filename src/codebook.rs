//! The synthesis codebook (DESIGN §7): every corpus sentence as a continuous face-space
//! trajectory with its phone segments, an index of phone occurrences, the phoneme similarity
//! matrix S ([blend] §4.2) and the phoneme distance matrix M ([unitsel] eq. 5).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::manifest::{self, ManifestError};
use crate::npy::{self, NpyError};
use crate::phonemes::{self, Phone, PhoneMap, PhonemeError, Segment};
use crate::trajectory::{Trajectory, TrajectoryError};
use crate::{Progress, atomic};

pub const CODEBOOK_VERSION: u32 = 1;
const FORMAT: &str = "facespace-codebook";

#[derive(Debug, Error)]
pub enum CodebookError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Npy(#[from] NpyError),
    #[error(transparent)]
    Phonemes(#[from] PhonemeError),
    #[error("sentence {name}: {source}")]
    Trajectory {
        name: String,
        source: TrajectoryError,
    },
    #[error("{dir}: no .npy trajectories with label files")]
    EmptyCorpus { dir: PathBuf },
    #[error("{npy}: no label file of the same name (.lab, .TextGrid or .tsv)")]
    MissingLabels { npy: PathBuf },
    #[error(
        "{npy} lasts {frames_s:.3} s ({frames} frames at {fps} fps) but {labels} ends at {labels_s:.3} s"
    )]
    DurationMismatch {
        npy: PathBuf,
        labels: PathBuf,
        frames: usize,
        fps: f64,
        frames_s: f64,
        labels_s: f64,
    },
    #[error("{path}: {found} values per frame, the layout has {expected}")]
    Dims {
        path: PathBuf,
        expected: usize,
        found: usize,
    },
    #[error("sentence {name}: {reason}")]
    BadSentence { name: String, reason: String },
    #[error("{path}: {reason}")]
    Manifest { path: PathBuf, reason: String },
    #[error("{path}: codebook version {found}, this build reads version {supported}")]
    Version {
        path: PathBuf,
        found: u32,
        supported: u32,
    },
    #[error("{path}: array shape {found:?}, expected {expected:?}")]
    ArrayShape {
        path: PathBuf,
        expected: Vec<usize>,
        found: Vec<usize>,
    },
    #[error("{path}: value {index} is not finite")]
    NotFinite { path: PathBuf, index: usize },
    #[error("invalid option: {0}")]
    Options(String),
}

/// Where the blocks of a face-space vector lie: `[pose | shape | appearance]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Layout {
    pub pose: usize,
    pub shape: usize,
    pub appearance: usize,
}

impl Layout {
    pub fn of(model: &crate::model::FaceModel) -> Self {
        Layout {
            pose: 4,
            shape: model.shape.n_params(),
            appearance: model.appearance.n_params(),
        }
    }

    pub fn dims(&self) -> usize {
        self.pose + self.shape + self.appearance
    }

    /// The shape and appearance parameters (pose excluded).
    pub fn params(&self) -> std::ops::Range<usize> {
        self.pose..self.dims()
    }

    pub fn appearance_range(&self) -> std::ops::Range<usize> {
        self.pose + self.shape..self.dims()
    }
}

/// Constants of S and M (DESIGN §7); every one configurable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimilarityOptions {
    /// Equidistant samples per phone occurrence (the source: 5).
    pub samples: usize,
    /// γ of `S = exp(−γ D)`; `None`: 1 / median off-diagonal D.
    pub gamma: Option<f64>,
    /// Weight parameters by their variance (`w_k`); else uniformly.
    pub variance_weights: bool,
    /// Scale distances by each phone's context variability (`v_i`); else `v = 1`.
    pub context_weights: bool,
    /// β₂ and K of M's weights `γ_k = exp(β₂ |k − K|)`, k counting appearance parameters from 1.
    pub beta2: f64,
    pub k_centre: usize,
}

impl Default for SimilarityOptions {
    fn default() -> Self {
        SimilarityOptions {
            samples: 5,
            gamma: None,
            variance_weights: true,
            context_weights: true,
            beta2: 0.1,
            k_centre: 12,
        }
    }
}

/// One corpus sentence: face-space frames at the codebook's frame rate and its phones.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sentence {
    pub name: String,
    /// Where the frames and labels came from.
    pub source: String,
    /// `frames × dims`, row-major (stored as `.npy`, not in the JSON).
    #[serde(skip)]
    pub frames: Vec<f32>,
    pub segments: Vec<Segment>,
}

/// Where a phone occurs: sentence index and segment index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Occurrence {
    pub sentence: usize,
    pub segment: usize,
}

/// The codebook: sentences, their trajectories, the occurrence index, S and M.
#[derive(Clone, Debug, PartialEq)]
pub struct Codebook {
    pub fps: f64,
    pub layout: Layout,
    pub model_hash: Option<String>,
    pub options: SimilarityOptions,
    pub sentences: Vec<Sentence>,
    /// One PCHIP trajectory per sentence over all dims (pose included).
    pub trajectories: Vec<Trajectory>,
    /// Occurrences of each phone, indexed by [`Phone::index`] (zero-length segments left out).
    pub occurrences: Vec<Vec<Occurrence>>,
    /// S, `Phone::COUNT²` row-major; 1 on the diagonal, 0 to and from absent phones.
    pub similarity: Vec<f64>,
    /// M, `Phone::COUNT²` row-major; 0 to and from absent phones.
    pub distance: Vec<f64>,
}

const N: usize = Phone::COUNT;

impl Codebook {
    /// Builds trajectories, the occurrence index, S and M.
    pub fn build(
        sentences: Vec<Sentence>,
        fps: f64,
        layout: Layout,
        model_hash: Option<String>,
        options: SimilarityOptions,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Self, CodebookError> {
        if !(fps > 0.0 && fps.is_finite()) {
            return Err(CodebookError::Options(format!("frame rate {fps}")));
        }
        if options.samples < 2 {
            return Err(CodebookError::Options(format!(
                "{} samples per occurrence (need at least 2)",
                options.samples
            )));
        }
        if options.gamma.is_some_and(|g| !(g > 0.0 && g.is_finite())) {
            return Err(CodebookError::Options(format!("gamma {:?}", options.gamma)));
        }
        let dims = layout.dims();
        let total = sentences.len() + 1;
        let mut trajectories = Vec::with_capacity(sentences.len());
        for (i, s) in sentences.iter().enumerate() {
            let bad = |reason: String| CodebookError::BadSentence {
                name: s.name.clone(),
                reason,
            };
            if s.frames.len() % dims != 0 || s.frames.len() < 2 * dims {
                return Err(bad(format!(
                    "{} values are not ≥ 2 frames of {dims}",
                    s.frames.len()
                )));
            }
            if s.segments.is_empty() {
                return Err(bad("no phone segments".into()));
            }
            let n = s.frames.len() / dims;
            let end = s.segments[s.segments.len() - 1].end;
            if end > (n + 1) as f64 / fps + 1e-9 {
                return Err(bad(format!(
                    "labels end at {end:.3} s, after the {n} frames ({:.3} s)",
                    n as f64 / fps
                )));
            }
            trajectories.push(
                Trajectory::from_frames(&s.frames, dims, fps).map_err(|source| {
                    CodebookError::Trajectory {
                        name: s.name.clone(),
                        source,
                    }
                })?,
            );
            progress(Progress {
                stage: "trajectories",
                done: i + 1,
                total,
            });
        }
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
        let mut cb = Codebook {
            fps,
            layout,
            model_hash,
            options,
            sentences,
            trajectories,
            occurrences,
            similarity: vec![],
            distance: vec![],
        };
        cb.similarity = cb.similarity_matrix();
        cb.distance = cb.distance_matrix();
        progress(Progress {
            stage: "similarity",
            done: total,
            total,
        });
        Ok(cb)
    }

    pub fn dims(&self) -> usize {
        self.layout.dims()
    }

    /// Phones with at least one (non-empty) occurrence.
    pub fn present(&self) -> Vec<Phone> {
        Phone::all()
            .filter(|p| !self.occurrences[p.index()].is_empty())
            .collect()
    }

    pub fn similarity(&self, a: Phone, b: Phone) -> f64 {
        self.similarity[a.index() * N + b.index()]
    }

    pub fn distance(&self, a: Phone, b: Phone) -> f64 {
        self.distance[a.index() * N + b.index()]
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

    pub fn segment(&self, o: Occurrence) -> &Segment {
        &self.sentences[o.sentence].segments[o.segment]
    }

    /// Parameter weights `w_k` (variance of each shape/appearance parameter over all frames,
    /// normalised to sum 1), indexed over `layout.params()`.
    fn parameter_weights(&self) -> Vec<f64> {
        let range = self.layout.params();
        let d = range.len();
        if !self.options.variance_weights {
            return vec![1.0 / d as f64; d];
        }
        let (mut sum, mut sq, mut n) = (vec![0.0; d], vec![0.0; d], 0.0);
        for t in &self.trajectories {
            for row in t.values.chunks_exact(t.dims) {
                for (k, &v) in row[range.clone()].iter().enumerate() {
                    sum[k] += v;
                    sq[k] += v * v;
                }
                n += 1.0;
            }
        }
        let var: Vec<f64> = (0..d)
            .map(|k| (sq[k] / n - (sum[k] / n).powi(2)).max(0.0))
            .collect();
        let total: f64 = var.iter().sum();
        if total > 0.0 {
            var.iter().map(|v| v / total).collect()
        } else {
            vec![1.0 / d as f64; d]
        }
    }

    /// An occurrence sampled at `samples` equidistant points over its duration, shape and
    /// appearance parameters only (`samples × d`).
    fn occurrence_samples(&self, o: Occurrence) -> Vec<f64> {
        let g = self.segment(o);
        let n = self.options.samples;
        let times: Vec<f64> = (0..n)
            .map(|j| g.start + g.duration() * j as f64 / (n - 1) as f64)
            .collect();
        let all = self.trajectories[o.sentence].sample(&times);
        all.chunks_exact(self.dims())
            .flat_map(|row| row[self.layout.params()].to_vec())
            .collect()
    }

    /// S ([blend] §4.2, DESIGN §7): `D_ij = v_i v_j Σ_k w_k Σ_t (P̄_i[t,k] − P̄_j[t,k])²`,
    /// `S = exp(−γ D)`. `v_i`: the mean w-weighted area between phone i's occurrences and its
    /// mean trajectory, normalised to mean 1 over present phones (phones seen once get 1).
    fn similarity_matrix(&self) -> Vec<f64> {
        let w = self.parameter_weights();
        let d = w.len();
        let n = self.options.samples;
        let present = self.present();
        let mut means = vec![vec![0.0; n * d]; N];
        let mut spread = vec![f64::NAN; N];
        for &p in &present {
            let occ = &self.occurrences[p.index()];
            let samples: Vec<Vec<f64>> = occ.iter().map(|&o| self.occurrence_samples(o)).collect();
            let mean = &mut means[p.index()];
            for s in &samples {
                mean.iter_mut()
                    .zip(s)
                    .for_each(|(m, v)| *m += v / samples.len() as f64);
            }
            if samples.len() > 1 {
                let area = |s: &Vec<f64>| -> f64 {
                    s.chunks_exact(d)
                        .zip(mean.chunks_exact(d))
                        .map(|(a, b)| (0..d).map(|k| w[k] * (a[k] - b[k]).abs()).sum::<f64>())
                        .sum::<f64>()
                        / n as f64
                };
                spread[p.index()] = samples.iter().map(area).sum::<f64>() / samples.len() as f64;
            }
        }
        let seen: Vec<f64> = spread.iter().copied().filter(|v| v.is_finite()).collect();
        let mean_spread = seen.iter().sum::<f64>() / seen.len().max(1) as f64;
        let v: Vec<f64> = spread
            .iter()
            .map(|&s| {
                if self.options.context_weights && s.is_finite() && mean_spread > 0.0 {
                    s / mean_spread
                } else {
                    1.0
                }
            })
            .collect();
        let mut dist = vec![0.0; N * N];
        for &a in &present {
            for &b in &present {
                let (ma, mb) = (&means[a.index()], &means[b.index()]);
                let sq: f64 = ma
                    .chunks_exact(d)
                    .zip(mb.chunks_exact(d))
                    .map(|(x, y)| (0..d).map(|k| w[k] * (x[k] - y[k]).powi(2)).sum::<f64>())
                    .sum();
                dist[a.index() * N + b.index()] = v[a.index()] * v[b.index()] * sq;
            }
        }
        let dist_ref = &dist;
        let gamma = self.options.gamma.unwrap_or_else(|| {
            let dist = dist_ref;
            let mut off: Vec<f64> = present
                .iter()
                .flat_map(|a| {
                    present
                        .iter()
                        .filter(move |b| *b != a)
                        .map(move |b| dist[a.index() * N + b.index()])
                })
                .collect();
            off.sort_by(f64::total_cmp);
            let median = off.get(off.len() / 2).copied().unwrap_or(1.0);
            if median > 0.0 { 1.0 / median } else { 1.0 }
        });
        let mut s = vec![0.0; N * N];
        for i in 0..N {
            s[i * N + i] = 1.0;
        }
        for &a in &present {
            for &b in &present {
                s[a.index() * N + b.index()] = (-gamma * dist[a.index() * N + b.index()]).exp();
            }
        }
        s
    }

    /// M ([unitsel] eq. 5): `M(i,j) = sqrt(Σ_k γ_k (A_i,k − A_j,k)² / Σ_k γ_k)` over the mean
    /// appearance parameters `A_i` of the frames labelled i, `γ_k = exp(β₂ |k − K|)`.
    fn distance_matrix(&self) -> Vec<f64> {
        let range = self.layout.appearance_range();
        let na = range.len();
        let mut sums = vec![vec![0.0; na]; N];
        let mut counts = vec![0usize; N];
        for (s, t) in self.sentences.iter().zip(&self.trajectories) {
            for (i, row) in t.values.chunks_exact(t.dims).enumerate() {
                let time = t.times[i];
                if let Some(g) = s.segments.iter().find(|g| time >= g.start && time < g.end) {
                    let p = g.phone.index();
                    sums[p]
                        .iter_mut()
                        .zip(&row[range.clone()])
                        .for_each(|(a, v)| *a += v);
                    counts[p] += 1;
                }
            }
        }
        let gk: Vec<f64> = (1..=na)
            .map(|k| (self.options.beta2 * (k as f64 - self.options.k_centre as f64).abs()).exp())
            .collect();
        let gsum: f64 = gk.iter().sum();
        let mut m = vec![0.0; N * N];
        for a in 0..N {
            for b in 0..N {
                if counts[a] == 0 || counts[b] == 0 || na == 0 {
                    continue;
                }
                let sq: f64 = (0..na)
                    .map(|k| {
                        gk[k]
                            * (sums[a][k] / counts[a] as f64 - sums[b][k] / counts[b] as f64)
                                .powi(2)
                    })
                    .sum();
                m[a * N + b] = (sq / gsum).sqrt();
            }
        }
        m
    }

    /// Saves `codebook.json`, one `.npy` per sentence, `similarity.npy` and `distance.npy`,
    /// atomically.
    pub fn save(&self, dir: &Path) -> Result<(), CodebookError> {
        let manifest = Manifest {
            format: FORMAT.into(),
            version: CODEBOOK_VERSION,
            fps: self.fps,
            layout: self.layout,
            model_hash: self.model_hash.clone(),
            options: self.options.clone(),
            phones: crate::phonemes::PHONES
                .iter()
                .map(|s| s.to_string())
                .collect(),
            sentences: self
                .sentences
                .iter()
                .enumerate()
                .map(|(i, s)| (sentence_file(i), s.clone()))
                .collect(),
        };
        let json = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
        let dims = self.dims();
        atomic::replace_dir(
            dir,
            "codebook.json",
            |tmp| -> Result<(), CodebookError> {
                for (i, s) in self.sentences.iter().enumerate() {
                    npy::write(
                        &tmp.join(sentence_file(i)),
                        &[s.frames.len() / dims, dims],
                        &s.frames,
                    )?;
                }
                npy::write(&tmp.join("similarity.npy"), &[N, N], &self.similarity)?;
                npy::write(&tmp.join("distance.npy"), &[N, N], &self.distance)?;
                let path = tmp.join("codebook.json");
                std::fs::write(&path, json).map_err(|source| CodebookError::Io { path, source })
            },
            |source| CodebookError::Io {
                path: dir.into(),
                source,
            },
        )
    }

    /// Loads and validates a codebook folder; trajectories and the occurrence index are
    /// rebuilt, and S and M are checked against the stored matrices' shapes and finiteness.
    pub fn load(dir: &Path) -> Result<Self, CodebookError> {
        let path = dir.join("codebook.json");
        let m: Manifest = manifest::read(&path, FORMAT, CODEBOOK_VERSION).map_err(|e| match e {
            ManifestError::Io(source) => CodebookError::Io {
                path: path.clone(),
                source,
            },
            ManifestError::Invalid(reason) => CodebookError::Manifest {
                path: path.clone(),
                reason,
            },
            ManifestError::Version(found) => CodebookError::Version {
                path: path.clone(),
                found,
                supported: CODEBOOK_VERSION,
            },
        })?;
        if m.phones.len() != N
            || m.phones
                .iter()
                .zip(crate::phonemes::PHONES)
                .any(|(a, b)| a != b)
        {
            return Err(CodebookError::Manifest {
                path,
                reason: "the phone list differs from this build's".into(),
            });
        }
        let dims = m.layout.dims();
        let mut sentences = Vec::with_capacity(m.sentences.len());
        for (file, mut s) in m.sentences {
            let p = dir.join(&file);
            let a = npy::read::<f32>(&p)?;
            if a.shape.len() != 2 || a.shape[1] != dims {
                return Err(CodebookError::ArrayShape {
                    path: p,
                    expected: vec![a.shape.first().copied().unwrap_or(0), dims],
                    found: a.shape,
                });
            }
            if let Some(index) = a.data.iter().position(|v| !v.is_finite()) {
                return Err(CodebookError::NotFinite { path: p, index });
            }
            s.frames = a.data;
            sentences.push(s);
        }
        let stored_s = read_matrix(&dir.join("similarity.npy"))?;
        let stored_m = read_matrix(&dir.join("distance.npy"))?;
        let mut cb = Codebook::build(
            sentences,
            m.fps,
            m.layout,
            m.model_hash,
            m.options,
            &mut crate::no_progress,
        )?;
        // The stored matrices are what was computed at build time; keep them (a Python user
        // may read them), after checking they are what this build computes.
        let close = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .all(|(x, y)| (x - y).abs() <= 1e-9 * (1.0 + x.abs()))
        };
        if !close(&stored_s, &cb.similarity) || !close(&stored_m, &cb.distance) {
            return Err(CodebookError::Manifest {
                path,
                reason:
                    "similarity.npy or distance.npy differ from the matrices its sentences give"
                        .into(),
            });
        }
        cb.similarity = stored_s;
        cb.distance = stored_m;
        Ok(cb)
    }
}

fn sentence_file(i: usize) -> String {
    format!("sentence_{i:04}.npy")
}

fn read_matrix(path: &Path) -> Result<Vec<f64>, CodebookError> {
    let a = npy::read::<f64>(path)?;
    if a.shape != [N, N] {
        return Err(CodebookError::ArrayShape {
            path: path.into(),
            expected: vec![N, N],
            found: a.shape,
        });
    }
    if let Some(index) = a.data.iter().position(|v| !v.is_finite()) {
        return Err(CodebookError::NotFinite {
            path: path.into(),
            index,
        });
    }
    Ok(a.data)
}

/// `codebook.json`.
#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    format: String,
    version: u32,
    fps: f64,
    layout: Layout,
    model_hash: Option<String>,
    options: SimilarityOptions,
    /// The phone order of S and M's rows and columns.
    phones: Vec<String>,
    /// (array file, sentence).
    sentences: Vec<(String, Sentence)>,
}

/// Label file extensions tried, in order, beside each `.npy`.
const LABEL_EXTENSIONS: [&str; 4] = ["lab", "TextGrid", "textgrid", "tsv"];

/// Reads a corpus folder: every `NAME.npy` (frames × dims face-space parameters at `fps`) with
/// `NAME.lab`, `NAME.TextGrid` or `NAME.tsv`. The labels must end within two frames of the
/// frames' duration.
pub fn load_corpus(
    dir: &Path,
    fps: f64,
    dims: usize,
    tier: Option<&str>,
    map: &PhoneMap,
) -> Result<Vec<Sentence>, CodebookError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| CodebookError::Io {
            path: dir.into(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "npy"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(CodebookError::EmptyCorpus { dir: dir.into() });
    }
    let mut sentences = Vec::with_capacity(files.len());
    for npy_path in files {
        let labels = LABEL_EXTENSIONS
            .iter()
            .map(|e| npy_path.with_extension(e))
            .find(|p| p.is_file())
            .ok_or_else(|| CodebookError::MissingLabels {
                npy: npy_path.clone(),
            })?;
        let a = npy::read::<f32>(&npy_path)?;
        if a.shape.len() != 2 || a.shape[1] != dims {
            return Err(CodebookError::Dims {
                path: npy_path,
                expected: dims,
                found: a.shape.get(1).copied().unwrap_or(0),
            });
        }
        if let Some(index) = a.data.iter().position(|v| !v.is_finite()) {
            return Err(CodebookError::NotFinite {
                path: npy_path,
                index,
            });
        }
        let segments = phonemes::read_labels(&labels, tier, map)?;
        let frames = a.shape[0];
        let (frames_s, labels_s) = (frames as f64 / fps, segments[segments.len() - 1].end);
        if (frames_s - labels_s).abs() > 2.0 / fps {
            return Err(CodebookError::DurationMismatch {
                npy: npy_path,
                labels,
                frames,
                fps,
                frames_s,
                labels_s,
            });
        }
        let name = npy_path
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let source = format!("{} + {}", npy_path.display(), labels.display());
        sentences.push(Sentence {
            name,
            source,
            frames: a.data,
            segments,
        });
    }
    Ok(sentences)
}
