//! The model folder (DESIGN §12): `model.json` + `.npy` arrays, saved atomically, loaded with
//! every shape, value and the rebuilt reference frame checked against the manifest.

use std::collections::BTreeMap;
use std::path::Path;

use ndarray::{Array1, Array2, ArrayView, Ix2};
use serde::{Deserialize, Serialize};

use super::{FaceModel, MAX_PIXELS, ModelError};
use crate::appearance::AppearanceModel;
use crate::atomic;
use crate::manifest::{self, ManifestError};
use crate::mesh::{Placement, ReferenceFrame, Region, Triangle};
use crate::npy;
use crate::pca::PcaModel;
use crate::shape::ShapeModel;

/// The model folder format this build writes and reads.
pub const MODEL_VERSION: u32 = 1;
/// The folder inside a region model that holds its whole-face tracker.
const TRACKER: &str = "tracker";
const FORMAT: &str = "facespace-model";
const MANIFEST: &str = "model.json";

const ARRAYS: [&str; 7] = [
    "shape_mean",
    "shape_components",
    "shape_variances",
    "appearance_mean",
    "appearance_components",
    "appearance_variances",
    "mask",
];

/// `model.json`.
#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    format: String,
    version: u32,
    n_landmarks: usize,
    triangles: Vec<Triangle>,
    reference: ReferenceInfo,
    shape: PcaInfo,
    appearance: PcaInfo,
    source: Vec<String>,
    arrays: BTreeMap<String, String>,
    /// The face region the appearance model covers, if not the whole face.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    region: Option<Region>,
}

#[derive(Debug, Serialize, Deserialize)]
struct ReferenceInfo {
    width: usize,
    height: usize,
    n_pixels: usize,
    placement: Placement,
}

#[derive(Debug, Serialize, Deserialize)]
struct PcaInfo {
    n_components: usize,
    /// Fraction of the training variance the kept components explain.
    variance_kept: f64,
    total_variance: f64,
}

impl PcaInfo {
    fn of(p: &PcaModel) -> Self {
        PcaInfo {
            n_components: p.n_components(),
            variance_kept: p.variance_ratio(),
            total_variance: p.total_variance,
        }
    }
}

/// A flat vector as a 1-D or 2-D array view for writing.
fn view<'a>(data: &'a [f32], rows: usize, cols: usize) -> ArrayView<'a, f32, Ix2> {
    ArrayView::from_shape((rows, cols), data).expect("model arrays have their shapes")
}

impl FaceModel {
    /// Saves the model folder atomically: `model.json` + `.npy` arrays.
    pub fn save(&self, dir: &Path) -> Result<(), ModelError> {
        let n = self.shape.n_landmarks();
        let p = self.frame.n_pixels();
        let manifest = Manifest {
            format: FORMAT.into(),
            version: MODEL_VERSION,
            n_landmarks: n,
            triangles: self.frame.triangles.clone(),
            reference: ReferenceInfo {
                width: self.frame.width,
                height: self.frame.height,
                n_pixels: p,
                placement: self.placement,
            },
            shape: PcaInfo::of(&self.shape.pca),
            appearance: PcaInfo::of(&self.appearance.pca),
            source: self.source.clone(),
            region: self.region.clone(),
            arrays: ARRAYS
                .iter()
                .map(|n| (n.to_string(), format!("{n}.npy")))
                .collect(),
        };
        let json = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
        atomic::replace_dir(
            dir,
            "model",
            |tmp| -> Result<(), ModelError> {
                let (s, a) = (&self.shape.pca, &self.appearance.pca);
                let (ks, ka) = (s.n_components(), a.n_components());
                let mask = self.frame.mask_image();
                let write = |name: &str, array: ArrayView<'_, f32, Ix2>| {
                    npy::write(&tmp.join(format!("{name}.npy")), array)
                };
                write("shape_mean", view(&s.mean, n, 2))?;
                write("shape_components", view(&s.components, ks, 2 * n))?;
                npy::write(
                    &tmp.join("shape_variances.npy"),
                    ArrayView::from(&s.variances),
                )?;
                write("appearance_mean", view(&a.mean, p, 3))?;
                write("appearance_components", view(&a.components, ka, 3 * p))?;
                npy::write(
                    &tmp.join("appearance_variances.npy"),
                    ArrayView::from(&a.variances),
                )?;
                npy::write(
                    &tmp.join("mask.npy"),
                    ArrayView::from_shape((self.frame.height, self.frame.width), &mask)
                        .expect("mask is height × width"),
                )?;
                if let Some(tracker) = &self.tracker {
                    tracker.save(&tmp.join(TRACKER))?;
                }
                let path = tmp.join(MANIFEST);
                std::fs::write(&path, json).map_err(|source| ModelError::Io { path, source })
            },
            |source| ModelError::Io {
                path: dir.into(),
                source,
            },
        )
    }

    /// The first of `candidates` that is a model whose [`FaceModel::hash`] is `hash`, loaded
    /// (folders that are not models, or not loadable, are passed over): how a codebook, which
    /// records its model's hash, finds its model when none is named.
    pub fn find_by_hash(hash: &str, candidates: &[std::path::PathBuf]) -> Option<(std::path::PathBuf, FaceModel)> {
        candidates
            .iter()
            .filter(|c| c.join(MANIFEST).is_file())
            .find_map(|c| {
                FaceModel::load(c)
                    .ok()
                    .filter(|m| m.hash() == hash)
                    .map(|m| (c.clone(), m))
            })
    }

    /// Loads and validates a model folder: format and version, every array's shape against
    /// the manifest, finite values and non-negative variances, and that the stored mask
    /// matches the reference frame rebuilt from the placement.
    /// (The folder is read whole from one version: retried if it was swapped meanwhile.)
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        crate::atomic::read_consistent(dir, || Self::load_once(dir))
    }

    fn load_once(dir: &Path) -> Result<Self, ModelError> {
        let path = dir.join(MANIFEST);
        let m: Manifest = manifest::read(&path, FORMAT, MODEL_VERSION)?;
        let inconsistent = |reason: String| ModelError::Inconsistent {
            path: path.clone(),
            reason,
        };
        let (n, p) = (m.n_landmarks, m.reference.n_pixels);
        if p > MAX_PIXELS || m.reference.width * m.reference.height > 4 * MAX_PIXELS {
            return Err(inconsistent(format!(
                "a {}×{} reference frame of {p} pixels is larger than this build reads ({MAX_PIXELS} pixels)",
                m.reference.width, m.reference.height
            )));
        }
        let (ks, ka) = (m.shape.n_components, m.appearance.n_components);
        let matrix = |name: &str, rows: usize, cols: usize| -> Result<Vec<f32>, ModelError> {
            let a: Array2<f32> = read(dir, &m, name, &[Some(rows), Some(cols)])?;
            Ok(a.into_raw_vec_and_offset().0)
        };
        let variances = |name: &str, k: usize| -> Result<Vec<f32>, ModelError> {
            let a: Array1<f32> = read(dir, &m, name, &[Some(k)])?;
            if let Some(i) = a.iter().position(|&v| v < 0.0) {
                return Err(inconsistent(format!(
                    "{name}: variance {i} is negative ({})",
                    a[i]
                )));
            }
            Ok(a.to_vec())
        };
        let shape = PcaModel {
            mean: matrix("shape_mean", n, 2)?,
            components: matrix("shape_components", ks, 2 * n)?,
            variances: variances("shape_variances", ks)?,
            total_variance: m.shape.total_variance,
        };
        let appearance = PcaModel {
            mean: matrix("appearance_mean", p, 3)?,
            components: matrix("appearance_components", ka, 3 * p)?,
            variances: variances("appearance_variances", ka)?,
            total_variance: m.appearance.total_variance,
        };
        let shape = ShapeModel { pca: shape };
        let frame =
            ReferenceFrame::place(&shape.mean(), m.triangles.clone(), m.reference.placement)
                .map_err(|e| inconsistent(format!("mesh: {e}")))?;
        let mask: Array2<u8> = read(dir, &m, "mask", &[Some(frame.height), Some(frame.width)])
            .map_err(|e| inconsistent(format!("reference frame does not match the mask: {e}")))?;
        if frame.width != m.reference.width
            || frame.height != m.reference.height
            || frame.n_pixels() != p
            || mask.as_slice() != Some(frame.mask_image().as_slice())
        {
            return Err(inconsistent(format!(
                "the rebuilt reference frame ({}×{}, {} pixels) differs from the stored one ({}×{}, {} pixels, mask.npy)",
                frame.width,
                frame.height,
                frame.n_pixels(),
                m.reference.width,
                m.reference.height,
                p
            )));
        }
        let tracker = if m.region.is_some() && dir.join(TRACKER).join(MANIFEST).is_file() {
            let t = FaceModel::load_once(&dir.join(TRACKER))?;
            if t.shape.n_landmarks() != n || t.region.is_some() {
                return Err(inconsistent(format!(
                    "{TRACKER}/ is not a whole-face model of the same {n} landmarks"
                )));
            }
            Some(Box::new(t))
        } else {
            None
        };
        Ok(FaceModel {
            shape,
            appearance: AppearanceModel { pca: appearance },
            frame,
            placement: m.reference.placement,
            source: m.source,
            region: m.region,
            tracker,
        })
    }
}

/// Reads array `name` through the manifest's own file table.
fn read<T: npy::Element, D: ndarray::Dimension>(
    dir: &Path,
    m: &Manifest,
    name: &str,
    expected: &[Option<usize>],
) -> Result<ndarray::Array<T, D>, ModelError> {
    let file = m.arrays.get(name).ok_or_else(|| ManifestError::Invalid {
        path: dir.join(MANIFEST),
        reason: format!("no {name:?} in \"arrays\""),
    })?;
    Ok(manifest::read_array(dir, file, expected)?)
}
