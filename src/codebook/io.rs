//! The codebook folder (DESIGN §12): `codebook.json` + one `.npy` per sentence +
//! `similarity.npy` and `distance.npy`, saved atomically; loading rebuilds the trajectories
//! and checks the stored matrices against them.

use std::path::Path;

use ndarray::Array2;
use serde::{Deserialize, Serialize};

use super::{Codebook, CodebookError, N, SimilarityOptions};
use crate::atomic;
use crate::corpus::Sentence;
use crate::facespace::{Frames, Layout};
use crate::manifest::{self, ManifestError};
use crate::npy;
use crate::phonemes::{PHONES, Segment};

/// The codebook folder format this build writes and reads.
pub const CODEBOOK_VERSION: u32 = 1;
const FORMAT: &str = "facespace-codebook";
const MANIFEST: &str = "codebook.json";
/// Sentences a codebook may hold (a cap for damaged manifests).
const MAX_SENTENCES: usize = 1_000_000;

/// `codebook.json`.
#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    format: String,
    version: u32,
    fps: f64,
    layout: Layout,
    model_hash: Option<String>,
    options: SimilarityOptions,
    /// Absent in codebooks written before it was recorded: none.
    #[serde(default)]
    photometric: crate::corpus::Photometric,
    /// The phone order of S and M's rows and columns.
    phones: Vec<String>,
    /// [`Codebook::content_hash`] when S and M were saved (absent in older codebooks: S and M
    /// are then computed again at load and compared).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    content_hash: Option<String>,
    /// (array file, sentence).
    sentences: Vec<(String, SentenceEntry)>,
}

/// A sentence as the manifest lists it (its frames are in the array file).
#[derive(Debug, Serialize, Deserialize)]
struct SentenceEntry {
    name: String,
    source: String,
    segments: Vec<Segment>,
}

fn sentence_file(i: usize) -> String {
    format!("sentence_{i:04}.npy")
}

impl Codebook {
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
            photometric: self.photometric,
            phones: PHONES.iter().map(|s| s.to_string()).collect(),
            content_hash: Some(self.content_hash()),
            sentences: self
                .sentences
                .iter()
                .enumerate()
                .map(|(i, s)| {
                    let entry = SentenceEntry {
                        name: s.name.clone(),
                        source: s.source.clone(),
                        segments: s.segments.clone(),
                    };
                    (sentence_file(i), entry)
                })
                .collect(),
        };
        let json = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
        atomic::replace_dir(
            dir,
            "codebook",
            |tmp| -> Result<(), CodebookError> {
                for (i, s) in self.sentences.iter().enumerate() {
                    npy::write(&tmp.join(sentence_file(i)), s.frames.values())?;
                }
                npy::write(&tmp.join("similarity.npy"), self.similarity.view())?;
                npy::write(&tmp.join("distance.npy"), self.distance.view())?;
                let path = tmp.join(MANIFEST);
                std::fs::write(&path, json).map_err(|source| CodebookError::Io { path, source })
            },
            |source| CodebookError::Io {
                path: dir.into(),
                source,
            },
        )
    }

    /// Loads and validates a codebook folder: the manifest's version and phone list, every
    /// sentence array (a plain file of the folder, of the layout's width, finite), and S and
    /// M — kept as stored when the sentences hash to what they were saved with
    /// ([`Codebook::content_hash`]), else computed again and compared.
    /// (The folder is read whole from one version: retried if it was swapped meanwhile.)
    pub fn load(dir: &Path) -> Result<Self, CodebookError> {
        crate::atomic::read_consistent(dir, || Self::load_once(dir))
    }

    fn load_once(dir: &Path) -> Result<Self, CodebookError> {
        let path = dir.join(MANIFEST);
        let m: Manifest = manifest::read(&path, FORMAT, CODEBOOK_VERSION)?;
        let invalid = |reason: String| ManifestError::Invalid {
            path: path.clone(),
            reason,
        };
        if m.phones.len() != N || m.phones.iter().zip(PHONES).any(|(a, b)| a != b) {
            return Err(invalid("the phone list differs from this build's".into()).into());
        }
        if m.sentences.len() > MAX_SENTENCES {
            return Err(invalid(format!("{} sentences", m.sentences.len())).into());
        }
        let dims = m.layout.dims();
        let mut sentences = Vec::with_capacity(m.sentences.len());
        for (file, s) in m.sentences {
            let values: Array2<f32> = manifest::read_array(dir, &file, &[None, Some(dims)])?;
            let frames =
                Frames::new(m.layout, m.fps, values).map_err(|source| CodebookError::Frames {
                    name: s.name.clone(),
                    source,
                })?;
            sentences.push(Sentence {
                name: s.name,
                source: s.source,
                frames,
                segments: s.segments,
            });
        }
        let stored_s: Array2<f64> = manifest::read_array(dir, "similarity.npy", &[Some(N); 2])?;
        let stored_m: Array2<f64> = manifest::read_array(dir, "distance.npy", &[Some(N); 2])?;
        let mut cb = Codebook::assemble(
            sentences,
            m.fps,
            m.layout,
            m.model_hash,
            m.options,
            &mut crate::no_progress,
        )?;
        cb.photometric = m.photometric;
        cb.similarity = stored_s.clone();
        cb.distance = stored_m.clone();
        let unchanged = m.content_hash.is_some_and(|h| h == cb.content_hash());
        if !unchanged {
            // An older codebook, or sentences changed since S and M were computed: compute
            // them again and require the stored ones to be what this build computes.
            cb.similarity = super::similarity::similarity_matrix(&cb);
            cb.distance = super::similarity::distance_matrix(&cb);
            let close = |a: &Array2<f64>, b: &Array2<f64>| {
                a.iter()
                    .zip(b)
                    .all(|(x, y)| (x - y).abs() <= 1e-9 * (1.0 + x.abs()))
            };
            if !close(&stored_s, &cb.similarity) || !close(&stored_m, &cb.distance) {
                return Err(invalid(
                    "similarity.npy or distance.npy differ from the matrices its sentences give"
                        .into(),
                )
                .into());
            }
        }
        cb.similarity = stored_s;
        cb.distance = stored_m;
        Ok(cb)
    }
}
