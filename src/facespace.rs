//! The face-space vector, the currency every stage passes (DESIGN §1).
//!
//! One frame's point is `[pose (4) | b_s | b_a]`: a similarity pose kept apart from the shape
//! parameters, so that synthesis can hold the head still or replay a recorded motion, then
//! the shape and appearance parameters of the two independent models. A [`Layout`] (from
//! [`crate::model::FaceModel::layout`]) says where each block lies; [`FaceParams`] is one
//! frame's point split into its blocks; [`Frames`] is a sequence of points at a frame rate
//! (`frames × dims`, `f32`, the precision of every file that stores them).

use std::ops::Range;

use ndarray::{Array2, ArrayView1, ArrayView2, ArrayViewMut2, Axis};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::options::{self, InvalidOption};
use crate::shape::Similarity;

/// Values of the pose block: `[a, b, tx, ty]` of the similarity `p ↦ [a −b; b a] p + t`.
pub const POSE_DIMS: usize = 4;

/// Largest parameter count of one block a file may declare: far above any model's, far below
/// what would make a reader allocate unreasonably.
pub const MAX_BLOCK: usize = 100_000;

/// What is wrong with a face-space vector or sequence.
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum FacespaceError {
    /// A row's length differs from the layout's.
    #[error("{found} values per frame, but the layout {layout} has {}", layout.dims())]
    Width {
        /// The layout expected.
        layout: Layout,
        /// Values found.
        found: usize,
    },
    /// Two layouts that must agree differ.
    #[error("face-space layout {found} where {expected} was expected")]
    LayoutMismatch {
        /// The layout expected.
        expected: Layout,
        /// The layout found.
        found: Layout,
    },
    /// A value is NaN or infinite.
    #[error("frame {frame}, value {index} is not finite")]
    NotFinite {
        /// Frame (row).
        frame: usize,
        /// Column.
        index: usize,
    },
    /// An out-of-range frame rate or size.
    #[error(transparent)]
    Option(#[from] InvalidOption),
}

/// Where the blocks of a face-space vector lie: `[pose (POSE_DIMS) | shape | appearance]`.
///
/// Stored in JSON as `{"pose": 4, "shape": k_s, "appearance": k_a}`; reading checks the pose
/// width and caps the block sizes, so a damaged file cannot ask for absurd allocations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "LayoutFile", into = "LayoutFile")]
pub struct Layout {
    /// Shape parameters `b_s`.
    pub shape: usize,
    /// Appearance parameters `b_a`.
    pub appearance: usize,
}

impl Layout {
    /// A layout of `shape` shape and `appearance` appearance parameters.
    pub fn new(shape: usize, appearance: usize) -> Self {
        Layout { shape, appearance }
    }

    /// Values per frame: pose + shape + appearance.
    pub fn dims(&self) -> usize {
        POSE_DIMS + self.shape + self.appearance
    }

    /// Columns of the pose.
    pub fn pose_range(&self) -> Range<usize> {
        0..POSE_DIMS
    }

    /// Columns of `b_s`.
    pub fn shape_range(&self) -> Range<usize> {
        POSE_DIMS..POSE_DIMS + self.shape
    }

    /// Columns of `b_a`.
    pub fn appearance_range(&self) -> Range<usize> {
        POSE_DIMS + self.shape..self.dims()
    }

    /// Columns of shape and appearance together: what synthesis drives (the pose never is).
    pub fn params_range(&self) -> Range<usize> {
        POSE_DIMS..self.dims()
    }

    /// Splits a row into its blocks, checking its length.
    pub fn split<'a>(&self, row: &'a [f32]) -> Result<FaceParams<'a>, FacespaceError> {
        if row.len() != self.dims() {
            return Err(FacespaceError::Width {
                layout: *self,
                found: row.len(),
            });
        }
        Ok(FaceParams {
            pose: pose_of(row),
            shape: &row[self.shape_range()],
            appearance: &row[self.appearance_range()],
        })
    }

    /// Checks that `other` is this layout.
    pub fn expect(&self, other: Layout) -> Result<(), FacespaceError> {
        if *self == other {
            Ok(())
        } else {
            Err(FacespaceError::LayoutMismatch {
                expected: *self,
                found: other,
            })
        }
    }
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "[pose {POSE_DIMS} | shape {} | appearance {}]",
            self.shape, self.appearance
        )
    }
}

/// The JSON form of a [`Layout`].
#[derive(Serialize, Deserialize)]
struct LayoutFile {
    pose: usize,
    shape: usize,
    appearance: usize,
}

impl TryFrom<LayoutFile> for Layout {
    type Error = String;

    fn try_from(f: LayoutFile) -> Result<Self, String> {
        if f.pose != POSE_DIMS {
            return Err(format!(
                "layout has {} pose values; face-space poses have {POSE_DIMS}",
                f.pose
            ));
        }
        if f.shape > MAX_BLOCK || f.appearance > MAX_BLOCK {
            return Err(format!(
                "layout of {} shape and {} appearance parameters exceeds {MAX_BLOCK} per block",
                f.shape, f.appearance
            ));
        }
        Ok(Layout::new(f.shape, f.appearance))
    }
}

impl From<Layout> for LayoutFile {
    fn from(l: Layout) -> Self {
        LayoutFile {
            pose: POSE_DIMS,
            shape: l.shape,
            appearance: l.appearance,
        }
    }
}

/// The similarity of a row's pose block.
fn pose_of(row: &[f32]) -> Similarity {
    Similarity::from_array([row[0], row[1], row[2], row[3]].map(f64::from))
}

/// One frame's face-space point, split into its blocks (borrowed from a row or from the
/// caller's vectors).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceParams<'a> {
    /// The pose: maps the mean-shape frame onto the image.
    pub pose: Similarity,
    /// Shape parameters `b_s`.
    pub shape: &'a [f32],
    /// Appearance parameters `b_a`.
    pub appearance: &'a [f32],
}

impl FaceParams<'_> {
    /// The layout these blocks fill.
    pub fn layout(&self) -> Layout {
        Layout::new(self.shape.len(), self.appearance.len())
    }

    /// Writes `[a, b, tx, ty | b_s | b_a]` into `out` (of the layout's length).
    pub fn write_into(&self, out: &mut [f32]) -> Result<(), FacespaceError> {
        let layout = self.layout();
        if out.len() != layout.dims() {
            return Err(FacespaceError::Width {
                layout,
                found: out.len(),
            });
        }
        let pose = self.pose.to_array().map(|v| v as f32);
        out[layout.pose_range()].copy_from_slice(&pose);
        out[layout.shape_range()].copy_from_slice(self.shape);
        out[layout.appearance_range()].copy_from_slice(self.appearance);
        Ok(())
    }

    /// `[a, b, tx, ty | b_s | b_a]`.
    pub fn to_vector(&self) -> Vec<f32> {
        let mut v = vec![0.0; self.layout().dims()];
        self.write_into(&mut v).expect("sized for the layout");
        v
    }
}

/// Lowest frame rate any sequence or video may declare (one frame per 100 s); below it a
/// damaged manifest or a typo, and MP4 timescales stop being representable.
pub const MIN_FPS: f64 = 0.01;
/// Frame rates are at most this many per second.
pub const MAX_FPS: f64 = 1000.0;

/// Longest sequence (seconds) synthesised, rendered or heard beside one: an hour; a damaged
/// label file cannot ask for years of frames.
pub const MAX_DURATION: f64 = 3600.0;

/// Checks a frame rate: finite, in [[`MIN_FPS`], [`MAX_FPS`]].
pub fn check_fps(fps: f64) -> Result<f64, InvalidOption> {
    options::in_range("frame rate", fps, MIN_FPS, MAX_FPS)
}

/// A face-space sequence: `frames × dims` values at `fps`, every value finite.
///
/// The array is private so that its width always matches the layout; read it through
/// [`Frames::values`], rows through [`Frames::row`] and [`Frames::params`].
#[derive(Clone, Debug, PartialEq)]
pub struct Frames {
    layout: Layout,
    fps: f64,
    values: Array2<f32>,
}

impl Frames {
    /// Wraps `values` (`frames × layout.dims()`), checking its width, the frame rate and that
    /// every value is finite.
    pub fn new(layout: Layout, fps: f64, values: Array2<f32>) -> Result<Self, FacespaceError> {
        check_fps(fps)?;
        if values.ncols() != layout.dims() {
            return Err(FacespaceError::Width {
                layout,
                found: values.ncols(),
            });
        }
        if let Some((at, _)) = values.indexed_iter().find(|(_, v)| !v.is_finite()) {
            return Err(FacespaceError::NotFinite {
                frame: at.0,
                index: at.1,
            });
        }
        Ok(Frames {
            layout,
            fps,
            values: values.as_standard_layout().into_owned(),
        })
    }

    /// From row-major values (`frames × layout.dims()` of them).
    pub fn from_rows(layout: Layout, fps: f64, rows: Vec<f32>) -> Result<Self, FacespaceError> {
        let dims = layout.dims();
        if !rows.len().is_multiple_of(dims) {
            return Err(FacespaceError::Width {
                layout,
                found: rows.len() % dims,
            });
        }
        let values =
            Array2::from_shape_vec((rows.len() / dims, dims), rows).expect("length checked");
        Self::new(layout, fps, values)
    }

    /// The layout of every row.
    pub fn layout(&self) -> Layout {
        self.layout
    }

    /// Frames per second.
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.values.nrows()
    }

    /// Whether there are no frames.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Seconds covered: frames / fps.
    pub fn duration(&self) -> f64 {
        self.len() as f64 / self.fps
    }

    /// The time of each frame, `i / fps`.
    pub fn times(&self) -> Vec<f64> {
        (0..self.len()).map(|i| i as f64 / self.fps).collect()
    }

    /// All values, `frames × dims`.
    pub fn values(&self) -> ArrayView2<'_, f32> {
        self.values.view()
    }

    /// All values, writable in place (the shape stays fixed, so the layout still holds).
    pub fn values_mut(&mut self) -> ArrayViewMut2<'_, f32> {
        self.values.view_mut()
    }

    /// The values as one row-major slice.
    pub fn as_slice(&self) -> &[f32] {
        self.values.as_slice().expect("standard layout")
    }

    /// Row `i`, `[pose | b_s | b_a]`.
    pub fn row(&self, i: usize) -> &[f32] {
        let dims = self.layout.dims();
        &self.as_slice()[i * dims..(i + 1) * dims]
    }

    /// Row `i` split into its blocks.
    pub fn params(&self, i: usize) -> FaceParams<'_> {
        self.layout
            .split(self.row(i))
            .expect("rows have the layout")
    }

    /// Every row, split.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = FaceParams<'_>> {
        (0..self.len()).map(|i| self.params(i))
    }

    /// Column `k` over time.
    pub fn column(&self, k: usize) -> ArrayView1<'_, f32> {
        self.values.column(k)
    }

    /// Sets frame `i`'s pose.
    pub fn set_pose(&mut self, i: usize, pose: Similarity) {
        let v = pose.to_array().map(|v| v as f32);
        self.values
            .row_mut(i)
            .as_slice_mut()
            .expect("standard layout")[..POSE_DIMS]
            .copy_from_slice(&v);
    }

    /// Frames `range`, a copy at the same rate.
    pub fn slice(&self, range: Range<usize>) -> Frames {
        Frames {
            layout: self.layout,
            fps: self.fps,
            values: self.values.slice_axis(Axis(0), range.into()).to_owned(),
        }
    }

    /// The array of values.
    pub fn into_values(self) -> Array2<f32> {
        self.values
    }
}
