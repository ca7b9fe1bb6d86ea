//! The face model: independent shape and appearance models over one reference frame
//! (DESIGN §3). Projection turns a frame and its landmarks into a face-space point
//! ([`crate::facespace`]); reconstruction turns a point back into landmarks and a
//! shape-normalised texture. Persistence (`io`) and training sets (`training`) are submodules.

mod io;
mod training;

use std::path::PathBuf;

use image::RgbImage;
use thiserror::Error;

pub use io::MODEL_VERSION;
pub use training::{FACE_PIXELS, TrainingExample, face_pixels, load_marked, load_training_set};

use crate::Progress;
use crate::appearance::AppearanceModel;
use crate::facespace::{FaceParams, FacespaceError, Layout};
use crate::manifest::ManifestError;
use crate::mesh::{self, MeshError, Placement, ReferenceFrame, Region, Triangle};
use crate::options::{self, InvalidOption};
use crate::pca::{Components, PcaError};
use crate::shape::{self, Landmarks, ShapeError, ShapeModel};
use crate::warp::{self, WarpError};

/// Errors of building, loading and using a face model.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ModelError {
    /// A file or folder could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A training image could not be decoded.
    #[error("{path}: cannot read image: {source}")]
    Image {
        /// The image.
        path: PathBuf,
        /// The cause.
        source: image::ImageError,
    },
    /// A training folder without images.
    #[error("{dir}: no images ({} files)", crate::video::IMAGE_EXTENSIONS.join(", "))]
    NoImages {
        /// The folder.
        dir: PathBuf,
    },
    /// An image without its `.pts`.
    #[error("{image}: no landmarks file {pts}")]
    MissingLandmarks {
        /// The image.
        image: PathBuf,
        /// The `.pts` looked for.
        pts: PathBuf,
    },
    /// A `.pts` without its image.
    #[error("{pts}: landmarks file has no image of the same name")]
    OrphanLandmarks {
        /// The `.pts`.
        pts: PathBuf,
    },
    /// Training examples with different landmark counts.
    #[error("{path}: {found} landmarks, but {first} has {expected}")]
    LandmarkCount {
        /// The odd file.
        path: PathBuf,
        /// The first file's count.
        expected: usize,
        /// This file's count.
        found: usize,
        /// The first file.
        first: PathBuf,
    },
    /// Landmarks far outside their image: probably of another frame.
    #[error(
        "{pts}: landmark {index} at ({:.1}, {:.1}) lies outside its image {image} ({width}×{height}); are they from different frames?",
        point[0], point[1]
    )]
    LandmarksOutsideImage {
        /// The `.pts`.
        pts: PathBuf,
        /// The image.
        image: PathBuf,
        /// The landmark.
        index: usize,
        /// Its position.
        point: shape::Point,
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
    /// Fewer than two training examples.
    #[error("need at least 2 training examples, got {0}")]
    TooFewExamples(usize),
    /// The model folder's manifest or arrays are damaged or of another version.
    #[error(transparent)]
    Manifest(#[from] ManifestError),
    /// An array could not be written.
    #[error(transparent)]
    Npy(#[from] crate::npy::NpyError),
    /// The folder's parts do not fit together.
    #[error("{path}: {reason}")]
    Inconsistent {
        /// The manifest.
        path: PathBuf,
        /// What does not fit.
        reason: String,
    },
    /// A face-space point that does not fit the model.
    #[error(transparent)]
    Facespace(#[from] FacespaceError),
    /// Bad landmarks or shape model.
    #[error(transparent)]
    Shape(#[from] ShapeError),
    /// Bad triangulation or reference frame.
    #[error("mesh: {0}")]
    Mesh(#[from] MeshError),
    /// The appearance PCA failed.
    #[error("appearance PCA: {0}")]
    Pca(#[from] PcaError),
    /// A warp failed.
    #[error("warp: {0}")]
    Warp(#[from] WarpError),
    /// An option out of range.
    #[error(transparent)]
    Option(#[from] InvalidOption),
}

/// Reference frames may cover at most this many pixels (a model of a face 1000 px across).
pub const MAX_PIXELS: usize = 1_000_000;

/// Default rim left out of the appearance model, reference-frame pixels.
pub const DEFAULT_MARGIN: f64 = 4.0;

/// Options for [`FaceModel::build`].
#[derive(Clone, Debug, PartialEq)]
pub struct BuildOptions {
    /// Approximate pixel count of the reference frame's mesh (default 40 000).
    pub pixels: usize,
    /// Shape components to keep (default: 95% of the variance).
    pub shape: Components,
    /// Appearance components to keep (default: 98% of the variance, at most 80).
    pub appearance: Components,
    /// A fixed triangle list; `None` triangulates the mean shape (Delaunay).
    pub triangles: Option<Vec<Triangle>>,
    /// A face region: the appearance model covers only the triangulation of its landmarks
    /// (the shape model keeps every landmark).
    pub region: Option<Region>,
    /// Reference-frame pixels next to the mesh boundary left out of the appearance model
    /// (default 4: enough to keep the background that hand-marked outlines let in off the
    /// face; see [`crate::mesh::Placement::margin`]).
    pub margin: f64,
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
            region: None,
            margin: DEFAULT_MARGIN,
        }
    }
}

/// A frame rebuilt from face-space: its landmarks and its shape-normalised texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Reconstruction {
    /// Landmarks `pose(x̄ + P_s b_s)`.
    pub landmarks: Landmarks,
    /// Texture `ā + P_a b_a`, mask pixels × RGB.
    pub texture: Vec<f32>,
}

/// Independent shape and appearance models over one reference frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceModel {
    /// The point distribution model, pose kept apart.
    pub shape: ShapeModel,
    /// The texture model over the reference frame's mask.
    pub appearance: AppearanceModel,
    /// The shape-normalised image domain.
    pub frame: ReferenceFrame,
    /// How the mean shape sits in the reference frame.
    pub placement: Placement,
    /// The training examples' names.
    pub source: Vec<String>,
    /// The face region the appearance model covers (`None`: the whole face).
    pub region: Option<Region>,
    /// For a region model, the whole-face model built from the same frames, which tracks: a
    /// region's appearance alone does not hold a face in place (saved as `tracker/` inside
    /// the model folder).
    pub tracker: Option<Box<FaceModel>>,
}

impl FaceModel {
    /// The model that tracks faces for this one: its whole-face tracker, or itself.
    pub fn tracker(&self) -> &FaceModel {
        self.tracker.as_deref().unwrap_or(self)
    }

    /// Builds both models: Procrustes + shape PCA, the reference frame, every example warped
    /// to it (in parallel), appearance PCA; for a region, also the whole-face model that
    /// tracks for it ([`FaceModel::tracker`]).
    pub fn build(
        examples: &[TrainingExample],
        options: &BuildOptions,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Self, ModelError> {
        options::count_in("reference-frame pixels", options.pixels, 100, MAX_PIXELS)?;
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
        let triangles = match (&options.triangles, &options.region) {
            (Some(t), _) => t.clone(),
            (None, Some(region)) => region.triangulate(&mean)?,
            (None, None) => mesh::delaunay(&mean)?,
        };
        options::in_range("margin", options.margin, 0.0, 100.0)?;
        let (frame, placement) =
            ReferenceFrame::fit_mean(&mean, triangles, options.pixels, options.margin)?;
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
        drop(textures);
        let tracker = match &options.region {
            Some(_) => {
                progress(Progress {
                    stage: "whole-face tracker",
                    done: steps - 1,
                    total: steps,
                });
                let whole = BuildOptions {
                    region: None,
                    triangles: None,
                    ..options.clone()
                };
                Some(Box::new(FaceModel::build(examples, &whole, &mut |_| {})?))
            }
            None => None,
        };
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
            region: options.region.clone(),
            tracker,
        })
    }

    /// The landmarks synthesis moves, the others staying where a background's face has them
    /// ([`crate::synth::backdrop::anchor`]): a region's articulators, or for a whole iBUG
    /// 68-point face the lower face's — lips and chin — so eyes, brows, nose and the upper jaw
    /// line, which carry head pose more than speech, come from the background's own face.
    pub fn articulators(&self) -> Option<Vec<u32>> {
        match &self.region {
            Some(region) => region.articulators(),
            None if self.shape.n_landmarks() == 68 => Region::LowerFace.articulators(),
            None => None,
        }
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
        // Models without a rim keep the hashes they were saved with.
        if self.placement.margin != 0.0 {
            eat(&self.placement.margin.to_le_bytes());
        }
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

    /// The layout of this model's face-space vectors.
    pub fn layout(&self) -> Layout {
        Layout::new(self.shape.n_params(), self.appearance.n_params())
    }

    /// Projects a frame to face-space, written into `out` (the layout's length): pose and
    /// `b_s` from the landmarks, `b_a` from the image warped to the reference frame.
    pub fn project_into(
        &self,
        image: &RgbImage,
        landmarks: &Landmarks,
        out: &mut [f32],
    ) -> Result<(), ModelError> {
        let layout = self.layout();
        if out.len() != layout.dims() {
            return Err(FacespaceError::Width {
                layout,
                found: out.len(),
            }
            .into());
        }
        let (pose, shape) = self.shape.project(landmarks)?;
        let texture = warp::to_reference(&self.frame, image, &landmarks.points)?;
        let appearance = self.appearance.project(&texture);
        FaceParams {
            pose,
            shape: &shape,
            appearance: &appearance,
        }
        .write_into(out)?;
        Ok(())
    }

    /// [`FaceModel::project_into`] a new vector.
    pub fn project(&self, image: &RgbImage, landmarks: &Landmarks) -> Result<Vec<f32>, ModelError> {
        let mut out = vec![0.0; self.layout().dims()];
        self.project_into(image, landmarks, &mut out)?;
        Ok(out)
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

    /// Landmarks `pose(x̄ + P_s b_s)` of a face-space point.
    pub fn landmarks(&self, params: FaceParams<'_>) -> Result<Landmarks, ModelError> {
        self.layout().expect(params.layout())?;
        Ok(self.shape.instance(&params.pose, params.shape))
    }

    /// Landmarks `pose(x̄ + P_s b_s)` and texture `ā + P_a b_a`.
    pub fn reconstruct(&self, params: FaceParams<'_>) -> Result<Reconstruction, ModelError> {
        Ok(Reconstruction {
            landmarks: self.landmarks(params)?,
            texture: self.appearance.instance(params.appearance),
        })
    }

    /// Projects `image` with its `landmarks` and reconstructs it: original | reconstruction
    /// side by side, cropped to the face with a quarter of its size around it, and the
    /// texture PSNR (dB) in the reference frame.
    pub fn reconstruction_pair(
        &self,
        image: &RgbImage,
        landmarks: &Landmarks,
    ) -> Result<(RgbImage, f64), ModelError> {
        let row = self.project(image, landmarks)?;
        let r = self.reconstruct(self.layout().split(&row)?)?;
        let mut canvas = image.clone();
        warp::from_reference_into(&self.frame, &r.texture, &r.landmarks.points, &mut canvas)?;
        let original = warp::to_reference(&self.frame, image, &landmarks.points)?;
        let mse = original
            .iter()
            .zip(&r.texture)
            .map(|(a, b)| f64::from(a - b).powi(2))
            .sum::<f64>()
            / original.len() as f64;
        let psnr = 10.0 * (255.0f64 * 255.0 / mse.max(1e-12)).log10();
        let (lo, hi) = landmarks.bounds();
        let margin = 0.25 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let clamp = |v: f64, max: u32| v.clamp(0.0, max as f64) as u32;
        let (x0, y0) = (
            clamp(lo[0] - margin, image.width()),
            clamp(lo[1] - margin, image.height()),
        );
        let (x1, y1) = (
            clamp(hi[0] + margin, image.width()),
            clamp(hi[1] + margin, image.height()),
        );
        let (w, h) = ((x1 - x0).max(1), (y1 - y0).max(1));
        let crop = |img: &RgbImage| image::imageops::crop_imm(img, x0, y0, w, h).to_image();
        let mut out = RgbImage::new(2 * w, h);
        image::imageops::replace(&mut out, &crop(image), 0, 0);
        image::imageops::replace(&mut out, &crop(&canvas), i64::from(w), 0);
        Ok((out, psnr))
    }
}
