//! The face model: independent shape and appearance models over one reference frame
//! (DESIGN §3, §11). A face-space point is `[pose (4) | b_s | b_a]`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use image::RgbImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::appearance::AppearanceModel;
use crate::manifest::{self, ManifestError};
use crate::mesh::{self, MeshError, Placement, ReferenceFrame, Triangle};
use crate::npy::{self, Element, NpyError};
use crate::pca::{Components, PcaError, PcaModel};
use crate::shape::{self, Landmarks, ShapeError, ShapeModel, Similarity};
use crate::warp::{self, WarpError};
use crate::{Progress, atomic};

/// The model folder format this build writes and reads.
pub const MODEL_VERSION: u32 = 1;
const FORMAT: &str = "facespace-model";
/// Image file extensions a training folder may hold.
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "ppm", "pgm", "pnm"];
/// How far (as a fraction of the image size) a landmark may lie outside its image before the
/// pair is taken to be from different frames.
const OUTSIDE_TOLERANCE: f64 = 0.05;

#[derive(Debug, Error)]
pub enum ModelError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot read image: {source}")]
    Image {
        path: PathBuf,
        source: image::ImageError,
    },
    #[error("{dir}: no images ({} files)", IMAGE_EXTENSIONS.join(", "))]
    NoImages { dir: PathBuf },
    #[error("{image}: no landmarks file {pts}")]
    MissingLandmarks { image: PathBuf, pts: PathBuf },
    #[error("{pts}: landmarks file has no image of the same name")]
    OrphanLandmarks { pts: PathBuf },
    #[error("{path}: {found} landmarks, but {first} has {expected}")]
    LandmarkCount {
        path: PathBuf,
        expected: usize,
        found: usize,
        first: PathBuf,
    },
    #[error(
        "{pts}: landmark {index} at ({:.1}, {:.1}) lies outside its image {image} ({width}×{height}); are they from different frames?",
        point[0], point[1]
    )]
    LandmarksOutsideImage {
        pts: PathBuf,
        image: PathBuf,
        index: usize,
        point: shape::Point,
        width: u32,
        height: u32,
    },
    #[error("need at least 2 training examples, got {0}")]
    TooFewExamples(usize),
    #[error("{path}: {reason}")]
    Manifest { path: PathBuf, reason: String },
    #[error("{path}: model version {found}, this build reads version {supported}")]
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
    #[error("{path}: {reason}")]
    Inconsistent { path: PathBuf, reason: String },
    #[error(
        "{found} face-space values given, the model has {expected} (4 pose + shape + appearance)"
    )]
    ParamCount { expected: usize, found: usize },
    #[error(transparent)]
    Shape(#[from] ShapeError),
    #[error("mesh: {0}")]
    Mesh(#[from] MeshError),
    #[error("appearance PCA: {0}")]
    Pca(#[from] PcaError),
    #[error("warp: {0}")]
    Warp(#[from] WarpError),
    #[error(transparent)]
    Npy(#[from] NpyError),
}

/// One training image with its hand-marked landmarks.
#[derive(Clone, Debug)]
pub struct TrainingExample {
    /// Where it came from (recorded in the model's `source`).
    pub name: String,
    pub image: RgbImage,
    pub landmarks: Landmarks,
}

/// Loads every image in `images` with the `.pts` file of the same stem from `landmarks`
/// (default: the same folder), checking that the pairs belong together.
pub fn load_training_set(
    images: &Path,
    landmarks: Option<&Path>,
) -> Result<Vec<TrainingExample>, ModelError> {
    let pts_dir = landmarks.unwrap_or(images);
    let list = |dir: &Path| -> Result<Vec<PathBuf>, ModelError> {
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|source| ModelError::Io {
                path: dir.into(),
                source,
            })?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        Ok(files)
    };
    let ext = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
    };
    let image_paths: Vec<PathBuf> = list(images)?
        .into_iter()
        .filter(|p| ext(p).is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.as_str())))
        .collect();
    if image_paths.is_empty() {
        return Err(ModelError::NoImages { dir: images.into() });
    }
    let stems: Vec<&std::ffi::OsStr> = image_paths.iter().filter_map(|p| p.file_stem()).collect();
    if let Some(orphan) = list(pts_dir)?.into_iter().find(|p| {
        ext(p).as_deref() == Some("pts") && !p.file_stem().is_some_and(|s| stems.contains(&s))
    }) {
        return Err(ModelError::OrphanLandmarks { pts: orphan });
    }
    let examples = image_paths
        .par_iter()
        .map(|image_path| {
            let pts = pts_dir
                .join(image_path.file_stem().unwrap_or_default())
                .with_extension("pts");
            if !pts.is_file() {
                return Err(ModelError::MissingLandmarks {
                    image: image_path.clone(),
                    pts,
                });
            }
            let landmarks = shape::read_pts(&pts)?;
            let image = image::open(image_path)
                .map_err(|source| ModelError::Image {
                    path: image_path.clone(),
                    source,
                })?
                .to_rgb8();
            check_inside(&landmarks, &image, &pts, image_path)?;
            Ok((
                pts,
                TrainingExample {
                    name: image_path.display().to_string(),
                    image,
                    landmarks,
                },
            ))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (first_pts, first) = &examples[0];
    for (pts, ex) in &examples {
        if ex.landmarks.len() != first.landmarks.len() {
            return Err(ModelError::LandmarkCount {
                path: pts.clone(),
                expected: first.landmarks.len(),
                found: ex.landmarks.len(),
                first: first_pts.clone(),
            });
        }
    }
    Ok(examples.into_iter().map(|(_, e)| e).collect())
}

fn check_inside(
    landmarks: &Landmarks,
    image: &RgbImage,
    pts: &Path,
    image_path: &Path,
) -> Result<(), ModelError> {
    let (w, h) = (image.width() as f64, image.height() as f64);
    let (mx, my) = (OUTSIDE_TOLERANCE * w, OUTSIDE_TOLERANCE * h);
    match landmarks
        .points
        .iter()
        .position(|p| p[0] < -mx || p[1] < -my || p[0] > w + mx || p[1] > h + my)
    {
        Some(index) => Err(ModelError::LandmarksOutsideImage {
            pts: pts.into(),
            image: image_path.into(),
            index,
            point: landmarks.points[index],
            width: image.width(),
            height: image.height(),
        }),
        None => Ok(()),
    }
}

/// Options for [`FaceModel::build`].
#[derive(Clone, Debug, PartialEq)]
pub struct BuildOptions {
    /// Approximate pixel count of the reference frame's mesh (default 40 000).
    pub pixels: usize,
    pub shape: Components,
    pub appearance: Components,
    /// A fixed triangle list; `None` triangulates the mean shape (Delaunay).
    pub triangles: Option<Vec<Triangle>>,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            pixels: 40_000,
            shape: Components::Variance {
                fraction: 0.95,
                max: None,
            },
            appearance: Components::Variance {
                fraction: 0.98,
                max: Some(80),
            },
            triangles: None,
        }
    }
}

/// A point in face-space: pose, shape parameters, appearance parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FaceParams {
    pub pose: Similarity,
    pub shape: Vec<f32>,
    pub appearance: Vec<f32>,
}

impl FaceParams {
    /// `[a, b, tx, ty | b_s | b_a]`.
    pub fn to_vector(&self) -> Vec<f32> {
        let pose = self.pose.to_array().map(|v| v as f32);
        pose.iter()
            .chain(&self.shape)
            .chain(&self.appearance)
            .copied()
            .collect()
    }
}

/// A frame rebuilt from face-space: its landmarks and its shape-normalised texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Reconstruction {
    pub landmarks: Landmarks,
    pub texture: Vec<f32>,
}

/// Independent shape and appearance models over one reference frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceModel {
    pub shape: ShapeModel,
    pub appearance: AppearanceModel,
    pub frame: ReferenceFrame,
    pub placement: Placement,
    /// The training examples' names.
    pub source: Vec<String>,
}

impl FaceModel {
    /// Builds both models: Procrustes + shape PCA, the reference frame, every example warped
    /// to it (in parallel), appearance PCA.
    pub fn build(
        examples: &[TrainingExample],
        options: &BuildOptions,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Self, ModelError> {
        if examples.len() < 2 {
            return Err(ModelError::TooFewExamples(examples.len()));
        }
        let steps = examples.len() + 2;
        progress(Progress {
            stage: "shape model",
            done: 0,
            total: steps,
        });
        let shapes: Vec<Landmarks> = examples.iter().map(|e| e.landmarks.clone()).collect();
        for (e, s) in examples.iter().zip(&shapes) {
            s.validate(Some(shapes[0].len()), &e.name)?;
        }
        let shape = ShapeModel::build(&shapes, options.shape)?;
        // The frame is placed from the f32 mean as stored, so loading rebuilds it exactly.
        let mean = shape.mean();
        let triangles = match &options.triangles {
            Some(t) => t.clone(),
            None => mesh::delaunay(&mean)?,
        };
        let (frame, placement) = ReferenceFrame::fit_mean(&mean, triangles, options.pixels)?;
        progress(Progress {
            stage: "warping",
            done: 1,
            total: steps,
        });
        // Each warp is parallel inside, so examples go one after another with a report each.
        let mut textures = Vec::with_capacity(examples.len());
        for (i, e) in examples.iter().enumerate() {
            textures.push(warp::to_reference(&frame, &e.image, &e.landmarks.points)?);
            progress(Progress {
                stage: "warping",
                done: i + 2,
                total: steps,
            });
        }
        progress(Progress {
            stage: "appearance model",
            done: steps - 1,
            total: steps,
        });
        let appearance = AppearanceModel::build(&textures, options.appearance)?;
        progress(Progress {
            stage: "done",
            done: steps,
            total: steps,
        });
        Ok(FaceModel {
            shape,
            appearance,
            frame,
            placement,
            source: examples.iter().map(|e| e.name.clone()).collect(),
        })
    }

    /// A content hash of the model (FNV-1a 64 over the mesh, placement and every array), in
    /// hex: codebooks and encoded clips record it to refuse parameters of another model.
    pub fn hash(&self) -> String {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bytes: &[u8]| {
            for &b in bytes {
                h = (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        for t in &self.frame.triangles {
            t.iter().for_each(|v| eat(&v.to_le_bytes()));
        }
        eat(&self.placement.scale.to_le_bytes());
        self.placement
            .offset
            .iter()
            .for_each(|v| eat(&v.to_le_bytes()));
        for pca in [&self.shape.pca, &self.appearance.pca] {
            for array in [&pca.mean, &pca.components, &pca.variances] {
                array.iter().for_each(|v| eat(&v.to_le_bytes()));
            }
        }
        format!("{h:016x}")
    }

    /// Length of a face-space vector: 4 pose values + shape + appearance parameters.
    pub fn n_params(&self) -> usize {
        4 + self.shape.n_params() + self.appearance.n_params()
    }

    /// Projects a frame to face-space: pose and `b_s` from the landmarks, `b_a` from the
    /// image warped to the reference frame.
    pub fn project(
        &self,
        image: &RgbImage,
        landmarks: &Landmarks,
    ) -> Result<FaceParams, ModelError> {
        let (pose, shape) = self.shape.project(landmarks)?;
        let texture = warp::to_reference(&self.frame, image, &landmarks.points)?;
        Ok(FaceParams {
            pose,
            shape,
            appearance: self.appearance.project(&texture),
        })
    }

    /// Standard deviation of each shape then appearance parameter (the face-space columns
    /// after the pose), for errors measured in σ.
    pub fn standard_deviations(&self) -> Vec<f64> {
        self.shape
            .pca
            .variances
            .iter()
            .chain(&self.appearance.pca.variances)
            .map(|&v| f64::from(v).sqrt())
            .collect()
    }

    /// Splits a face-space vector, checking its length.
    pub fn params_from_vector(&self, v: &[f32]) -> Result<FaceParams, ModelError> {
        if v.len() != self.n_params() {
            return Err(ModelError::ParamCount {
                expected: self.n_params(),
                found: v.len(),
            });
        }
        let ns = self.shape.n_params();
        Ok(FaceParams {
            pose: Similarity::from_array([v[0], v[1], v[2], v[3]].map(|x| x as f64)),
            shape: v[4..4 + ns].to_vec(),
            appearance: v[4 + ns..].to_vec(),
        })
    }

    /// Landmarks `pose(x̄ + P_s b_s)` and texture `ā + P_a b_a`.
    pub fn reconstruct(&self, params: &FaceParams) -> Result<Reconstruction, ModelError> {
        let (ns, na) = (params.shape.len(), params.appearance.len());
        if ns != self.shape.n_params() || na != self.appearance.n_params() {
            return Err(ModelError::ParamCount {
                expected: self.n_params(),
                found: 4 + ns + na,
            });
        }
        Ok(Reconstruction {
            landmarks: self.shape.instance(&params.pose, &params.shape),
            texture: self.appearance.instance(&params.appearance),
        })
    }

    /// Draws the reconstructed face onto `canvas` (pixels outside the face are kept).
    pub fn render_into(
        &self,
        params: &FaceParams,
        canvas: &mut RgbImage,
    ) -> Result<Reconstruction, ModelError> {
        let r = self.reconstruct(params)?;
        warp::from_reference_into(&self.frame, &r.texture, &r.landmarks.points, canvas)?;
        Ok(r)
    }

    /// Saves the model folder atomically: `model.json` + `.npy` arrays (DESIGN §11).
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
            arrays: array_files(),
        };
        let json = serde_json::to_string_pretty(&manifest).expect("manifest serialises");
        atomic::replace_dir(
            dir,
            "model.json",
            |tmp| -> Result<(), ModelError> {
                let (s, a) = (&self.shape.pca, &self.appearance.pca);
                npy::write(&tmp.join("shape_mean.npy"), &[n, 2], &s.mean)?;
                npy::write(
                    &tmp.join("shape_components.npy"),
                    &[s.n_components(), 2 * n],
                    &s.components,
                )?;
                npy::write(
                    &tmp.join("shape_variances.npy"),
                    &[s.n_components()],
                    &s.variances,
                )?;
                npy::write(&tmp.join("appearance_mean.npy"), &[p, 3], &a.mean)?;
                npy::write(
                    &tmp.join("appearance_components.npy"),
                    &[a.n_components(), 3 * p],
                    &a.components,
                )?;
                npy::write(
                    &tmp.join("appearance_variances.npy"),
                    &[a.n_components()],
                    &a.variances,
                )?;
                npy::write(
                    &tmp.join("mask.npy"),
                    &[self.frame.height, self.frame.width],
                    &self.frame.mask_image(),
                )?;
                let path = tmp.join("model.json");
                std::fs::write(&path, json).map_err(|source| ModelError::Io { path, source })
            },
            |source| ModelError::Io {
                path: dir.into(),
                source,
            },
        )
    }

    /// Loads and validates a model folder: format and version, every array's shape against
    /// the manifest, finiteness, and that the stored mask matches the rebuilt frame.
    pub fn load(dir: &Path) -> Result<Self, ModelError> {
        let path = dir.join("model.json");
        let m: Manifest = manifest::read(&path, FORMAT, MODEL_VERSION).map_err(|e| match e {
            ManifestError::Io(source) => ModelError::Io {
                path: path.clone(),
                source,
            },
            ManifestError::Invalid(reason) => ModelError::Manifest {
                path: path.clone(),
                reason,
            },
            ManifestError::Version(found) => ModelError::Version {
                path: path.clone(),
                found,
                supported: MODEL_VERSION,
            },
        })?;
        let (n, p) = (m.n_landmarks, m.reference.n_pixels);
        let (ks, ka) = (m.shape.n_components, m.appearance.n_components);
        let shape = PcaModel {
            mean: read_array(dir, "shape_mean", &[n, 2])?,
            components: read_array(dir, "shape_components", &[ks, 2 * n])?,
            variances: read_array(dir, "shape_variances", &[ks])?,
            total_variance: m.shape.total_variance,
        };
        let appearance = PcaModel {
            mean: read_array(dir, "appearance_mean", &[p, 3])?,
            components: read_array(dir, "appearance_components", &[ka, 3 * p])?,
            variances: read_array(dir, "appearance_variances", &[ka])?,
            total_variance: m.appearance.total_variance,
        };
        let shape = ShapeModel { pca: shape };
        let frame =
            ReferenceFrame::place(&shape.mean(), m.triangles.clone(), m.reference.placement)
                .map_err(|e| ModelError::Inconsistent {
                    path: path.clone(),
                    reason: format!("mesh: {e}"),
                })?;
        let mask: Vec<u8> = read_array(dir, "mask", &[frame.height, frame.width]).map_err(|e| {
            ModelError::Inconsistent {
                path: path.clone(),
                reason: format!("reference frame does not match the mask: {e}"),
            }
        })?;
        if frame.width != m.reference.width
            || frame.height != m.reference.height
            || frame.n_pixels() != p
            || mask != frame.mask_image()
        {
            return Err(ModelError::Inconsistent {
                path,
                reason: format!(
                    "the rebuilt reference frame ({}×{}, {} pixels) differs from the stored one ({}×{}, {} pixels, mask.npy)",
                    frame.width,
                    frame.height,
                    frame.n_pixels(),
                    m.reference.width,
                    m.reference.height,
                    p
                ),
            });
        }
        Ok(FaceModel {
            shape,
            appearance: AppearanceModel { pca: appearance },
            frame,
            placement: m.reference.placement,
            source: m.source,
        })
    }
}

fn read_array<T: Element + CheckFinite>(
    dir: &Path,
    name: &str,
    expected: &[usize],
) -> Result<Vec<T>, ModelError> {
    let path = dir.join(format!("{name}.npy"));
    let a = npy::read::<T>(&path)?;
    if a.shape != expected {
        return Err(ModelError::ArrayShape {
            path,
            expected: expected.to_vec(),
            found: a.shape,
        });
    }
    if let Some(index) = a.data.iter().position(|x| !x.finite()) {
        return Err(ModelError::NotFinite { path, index });
    }
    Ok(a.data)
}

trait CheckFinite {
    fn finite(&self) -> bool;
}
impl CheckFinite for f32 {
    fn finite(&self) -> bool {
        self.is_finite()
    }
}
impl CheckFinite for u8 {
    fn finite(&self) -> bool {
        true
    }
}

fn array_files() -> BTreeMap<String, String> {
    [
        "shape_mean",
        "shape_components",
        "shape_variances",
        "appearance_mean",
        "appearance_components",
        "appearance_variances",
        "mask",
    ]
    .iter()
    .map(|n| (n.to_string(), format!("{n}.npy")))
    .collect()
}

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
