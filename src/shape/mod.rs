//! Landmark sets, iBUG `.pts` files, similarity transforms, generalised Procrustes analysis
//! and the shape model (a point distribution model, \[blend\] §3) with the pose kept apart.
//!
//! Coordinates are image pixels with the centre of the top-left pixel at (0, 0), x to the
//! right, y down. iBUG `.pts` files count from 1 (their Matlab origin; menpo does the same
//! conversion), so reading subtracts 1 and writing adds 1.

mod ljson;
mod procrustes;
mod pts;
mod similarity;

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use ljson::{parse_ljson, read_landmarks, read_ljson};
pub use procrustes::{Procrustes, generalised_procrustes};
pub use pts::{format_pts, parse_pts, read_pts, write_pts, write_sequence};
pub use similarity::{Similarity, align, centroid};

use crate::pca::{Components, PcaError, PcaModel};

/// A 2-D point `[x, y]` in pixels.
pub type Point = [f64; 2];

/// The iBUG 68-point scheme's contours, as index ranges `(first, last, closed)`: jaw, brows,
/// nose bridge and base, eyes, outer and inner lips (the 300-W annotation guide's figure).
pub const IBUG_CONTOURS: [(usize, usize, bool); 9] = [
    (0, 16, false),
    (17, 21, false),
    (22, 26, false),
    (27, 30, false),
    (31, 35, false),
    (36, 41, true),
    (42, 47, true),
    (48, 59, true),
    (60, 67, true),
];

/// The iBUG scheme's point count.
pub const IBUG_POINTS: usize = 68;

/// The iBUG scheme's eyes (the subject's right, on the image's left, first) and mouth (outer
/// and inner lips): the groups whose centres place a face.
pub const IBUG_EYES_AND_MOUTH: [std::ops::Range<usize>; 3] = [36..42, 42..48, 48..68];

/// One face's landmarks, in a fixed order (68 for the iBUG scheme, any count allowed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Landmarks {
    /// The points, in the scheme's order.
    pub points: Vec<Point>,
}

/// What can be wrong with landmarks, `.pts` files or the shape model.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ShapeError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A `.pts` file is malformed.
    #[error("{path}:{line}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The line (1-based).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A menpo `.ljson` file is malformed.
    #[error("{path}: {reason}")]
    Ljson {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Another number of landmarks than expected.
    #[error("{what}: {found} landmarks where {expected} were expected")]
    Count {
        /// Whose landmarks.
        what: String,
        /// The count expected.
        expected: usize,
        /// The count found.
        found: usize,
    },
    /// A NaN or infinite coordinate.
    #[error("{what}: landmark {index} is not finite")]
    NotFinite {
        /// Whose landmarks.
        what: String,
        /// The landmark.
        index: usize,
    },
    /// Every landmark at one point.
    #[error("{what}: all landmarks coincide, the shape has no size")]
    Degenerate {
        /// Whose landmarks.
        what: String,
    },
    /// Too few shapes to align.
    #[error("Procrustes analysis needs at least 2 shapes, got {0}")]
    TooFewShapes(usize),
    /// The shape PCA failed.
    #[error("shape PCA: {0}")]
    Pca(#[from] PcaError),
    /// A landmark array could not be written.
    #[error(transparent)]
    Npy(#[from] crate::npy::NpyError),
}

impl Landmarks {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Checks the point count and that every point is finite; `what` names the source.
    pub fn validate(&self, expected: Option<usize>, what: &str) -> Result<(), ShapeError> {
        if let Some(expected) = expected
            && self.len() != expected
        {
            return Err(ShapeError::Count {
                what: what.into(),
                expected,
                found: self.len(),
            });
        }
        match self
            .points
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            Some(index) => Err(ShapeError::NotFinite {
                what: what.into(),
                index,
            }),
            None => Ok(()),
        }
    }

    /// Coordinates as `[x0, y0, x1, y1, …]`.
    pub fn to_flat(&self) -> Vec<f32> {
        self.points
            .iter()
            .flat_map(|p| [p[0] as f32, p[1] as f32])
            .collect()
    }

    /// Points from `[x0, y0, x1, y1, …]`.
    pub fn from_flat(flat: &[f32]) -> Self {
        Landmarks {
            points: flat
                .chunks_exact(2)
                .map(|c| [c[0] as f64, c[1] as f64])
                .collect(),
        }
    }

    /// Axis-aligned bounds `(min, max)`.
    pub fn bounds(&self) -> (Point, Point) {
        self.points.iter().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            },
        )
    }
}

/// Point distribution model: `x ≈ pose(x̄ + P_s b_s)` (\[blend\] §3). The mean `x̄` is centred
/// with unit norm; the components are orthogonal to its similarity directions, so the pose
/// and `b_s` separate exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeModel {
    /// PCA of the aligned coordinates `[x0, y0, …]` about the Procrustes mean.
    pub pca: PcaModel,
}

impl ShapeModel {
    /// Procrustes-aligns the shapes and keeps the components that `keep` asks for.
    pub fn build(shapes: &[Landmarks], keep: Components) -> Result<Self, ShapeError> {
        let gpa = generalised_procrustes(shapes)?;
        let mean: Vec<f32> = gpa
            .mean
            .iter()
            .flat_map(|p| [p[0] as f32, p[1] as f32])
            .collect();
        let rows: Vec<Vec<f32>> = gpa
            .aligned
            .iter()
            .map(|s| s.iter().flat_map(|p| [p[0] as f32, p[1] as f32]).collect())
            .collect();
        let refs: Vec<&[f32]> = rows.iter().map(|r| r.as_slice()).collect();
        Ok(ShapeModel {
            pca: PcaModel::fit_about(&refs, &mean, keep)?,
        })
    }

    /// Landmarks per shape.
    pub fn n_landmarks(&self) -> usize {
        self.pca.dim() / 2
    }

    /// Shape parameters `b_s`.
    pub fn n_params(&self) -> usize {
        self.pca.n_components()
    }

    /// The mean shape `x̄` (centred, unit norm).
    pub fn mean(&self) -> Vec<Point> {
        Landmarks::from_flat(&self.pca.mean).points
    }

    /// Pose and shape parameters of landmarks: the pose fits `x̄` onto them by least squares,
    /// `b_s = P_sᵀ (pose⁻¹(x) − x̄)`.
    pub fn project(&self, landmarks: &Landmarks) -> Result<(Similarity, Vec<f32>), ShapeError> {
        landmarks.validate(Some(self.n_landmarks()), "landmarks")?;
        let pose = align(&self.mean(), &landmarks.points)
            .filter(|t| t.scale() > 0.0)
            .ok_or(ShapeError::Degenerate {
                what: "landmarks".into(),
            })?;
        Ok((pose, self.project_at(&pose, landmarks)?))
    }

    /// The shape parameters of landmarks at a given pose (not their own least-squares pose):
    /// `b_s = P_sᵀ (pose⁻¹(x) − x̄)`.
    pub fn project_at(
        &self,
        pose: &Similarity,
        landmarks: &Landmarks,
    ) -> Result<Vec<f32>, ShapeError> {
        Ok(self.pca.project(&self.unposed(pose, landmarks)?))
    }

    /// [`Self::project_at`] by a weighted least-squares projection (made with
    /// [`crate::pca::PcaModel::weighted`] from this model's PCA), which favours some landmarks.
    pub fn project_at_weighted(
        &self,
        pose: &Similarity,
        landmarks: &Landmarks,
        projection: &crate::pca::WeightedProjection,
    ) -> Result<Vec<f32>, ShapeError> {
        Ok(projection.project(&self.pca, &self.unposed(pose, landmarks)?))
    }

    /// `pose⁻¹(x)`, flat, after checking the landmark count.
    fn unposed(&self, pose: &Similarity, landmarks: &Landmarks) -> Result<Vec<f32>, ShapeError> {
        landmarks.validate(Some(self.n_landmarks()), "landmarks")?;
        let aligned = Landmarks {
            points: pose.invert().apply_all(&landmarks.points),
        };
        Ok(aligned.to_flat())
    }

    /// Landmarks of `pose(x̄ + P_s b_s)`.
    pub fn instance(&self, pose: &Similarity, b: &[f32]) -> Landmarks {
        let flat = self.pca.reconstruct(b);
        Landmarks {
            points: Landmarks::from_flat(&flat)
                .points
                .iter()
                .map(|&p| pose.apply(p))
                .collect(),
        }
    }
}
