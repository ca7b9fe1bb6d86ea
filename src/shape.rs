//! Landmark sets, iBUG `.pts` files, similarity transforms, generalised Procrustes analysis
//! and the shape model (a point distribution model, [blend] §3) with the pose kept apart.
//!
//! Coordinates are image pixels with the centre of the top-left pixel at (0, 0), x to the
//! right, y down. iBUG `.pts` files count from 1 (their Matlab origin; menpo does the same
//! conversion), so reading subtracts 1 and writing adds 1.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::atomic;
use crate::pca::{Components, PcaError, PcaModel};

/// A 2-D point `[x, y]` in pixels.
pub type Point = [f64; 2];

/// One face's landmarks, in a fixed order (68 for the iBUG scheme, any count allowed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Landmarks {
    pub points: Vec<Point>,
}

#[derive(Debug, Error)]
pub enum ShapeError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}:{line}: {reason}")]
    Parse {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    #[error("{what}: {found} landmarks where {expected} were expected")]
    Count {
        what: String,
        expected: usize,
        found: usize,
    },
    #[error("{what}: landmark {index} is not finite")]
    NotFinite { what: String, index: usize },
    #[error("{what}: all landmarks coincide, the shape has no size")]
    Degenerate { what: String },
    #[error("Procrustes analysis needs at least 2 shapes, got {0}")]
    TooFewShapes(usize),
    #[error("shape PCA: {0}")]
    Pca(#[from] PcaError),
    #[error(transparent)]
    Npy(#[from] crate::npy::NpyError),
}

impl Landmarks {
    pub fn len(&self) -> usize {
        self.points.len()
    }

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

/// Reads an iBUG `.pts` file (`version: 1`, `n_points: N`, `{`, N lines `x y`, `}`).
pub fn read_pts(path: &Path) -> Result<Landmarks, ShapeError> {
    let text = std::fs::read_to_string(path).map_err(|source| ShapeError::Io {
        path: path.into(),
        source,
    })?;
    parse_pts(&text, path)
}

/// Parses `.pts` text; `path` names the source in errors.
pub fn parse_pts(text: &str, path: &Path) -> Result<Landmarks, ShapeError> {
    let err = |line: usize, reason: String| ShapeError::Parse {
        path: path.into(),
        line,
        reason,
    };
    let mut declared = None;
    let mut points = Vec::new();
    let mut state = 0; // 0: header, 1: inside braces, 2: after the closing brace
    let mut last_line = 0;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        last_line = line_no;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        match state {
            0 => {
                if line == "{" {
                    state = 1;
                } else if let Some((key, value)) = line.split_once(':') {
                    match key.trim() {
                        "version" if value.trim() != "1" => {
                            return Err(err(
                                line_no,
                                format!("unsupported version {:?}", value.trim()),
                            ));
                        }
                        "n_points" => {
                            let n = value.trim().parse::<usize>();
                            declared = Some(n.map_err(|_| {
                                err(line_no, format!("bad n_points {:?}", value.trim()))
                            })?);
                        }
                        _ => {} // other header keys are allowed and ignored
                    }
                } else {
                    return Err(err(
                        line_no,
                        format!("expected a header line or '{{', found {line:?}"),
                    ));
                }
            }
            1 if line == "}" => state = 2,
            1 => {
                let mut it = line.split_whitespace();
                let mut coord = |name| -> Result<f64, ShapeError> {
                    let s = it
                        .next()
                        .ok_or_else(|| err(line_no, format!("missing {name} coordinate")))?;
                    let v = s
                        .parse::<f64>()
                        .map_err(|_| err(line_no, format!("bad {name} coordinate {s:?}")))?;
                    if v.is_finite() {
                        Ok(v)
                    } else {
                        Err(err(line_no, format!("{name} coordinate is {v}")))
                    }
                };
                let (x, y) = (coord("x")?, coord("y")?);
                if it.next().is_some() {
                    return Err(err(
                        line_no,
                        format!("expected two coordinates, found {line:?}"),
                    ));
                }
                points.push([x - 1.0, y - 1.0]);
            }
            _ => {
                return Err(err(
                    line_no,
                    format!("text after the closing '}}': {line:?}"),
                ));
            }
        }
    }
    let declared = declared.ok_or_else(|| err(1, "no n_points header".into()))?;
    if state != 2 {
        return Err(err(
            last_line,
            "missing closing '}' (file truncated?)".into(),
        ));
    }
    if points.len() != declared {
        return Err(err(
            last_line,
            format!(
                "n_points says {declared} but {} points follow",
                points.len()
            ),
        ));
    }
    Ok(Landmarks { points })
}

/// Formats landmarks as iBUG `.pts` text (1-based coordinates).
pub fn format_pts(landmarks: &Landmarks) -> String {
    let mut s = format!("version: 1\nn_points: {}\n{{\n", landmarks.len());
    for p in &landmarks.points {
        s.push_str(&format!("{:.6} {:.6}\n", p[0] + 1.0, p[1] + 1.0));
    }
    s.push_str("}\n");
    s
}

/// Writes a `.pts` file atomically.
pub fn write_pts(path: &Path, landmarks: &Landmarks) -> Result<(), ShapeError> {
    atomic::write_file(path, format_pts(landmarks).as_bytes()).map_err(|source| ShapeError::Io {
        path: path.into(),
        source,
    })
}

/// Writes a sequence of landmark sets: a `.npy` (frames × landmarks × 2, pixel centres
/// 0-based) when `path` ends in `.npy`, else a folder of `.pts` files named `names[i].pts`
/// (default `000000.pts`, …).
pub fn write_sequence(
    path: &Path,
    landmarks: &[Landmarks],
    names: Option<&[String]>,
) -> Result<(), ShapeError> {
    if path.extension().is_some_and(|e| e == "npy") {
        let n = landmarks.first().map_or(0, Landmarks::len);
        for (i, l) in landmarks.iter().enumerate() {
            l.validate(Some(n), &format!("{}: frame {i}", path.display()))?;
        }
        let flat: Vec<f32> = landmarks.iter().flat_map(Landmarks::to_flat).collect();
        let array = ndarray::Array3::from_shape_vec((landmarks.len(), n, 2), flat)
            .expect("every set has n points");
        crate::npy::write(path, array.view())?;
        return Ok(());
    }
    for (i, lm) in landmarks.iter().enumerate() {
        let name = names
            .and_then(|n| n.get(i).cloned())
            .unwrap_or_else(|| format!("{i:06}"));
        write_pts(&path.join(format!("{name}.pts")), lm)?;
    }
    Ok(())
}

/// A similarity transform `p ↦ [a −b; b a] p + t`, with `a = s cos θ`, `b = s sin θ`.
/// This is the pose of a face-space point (DESIGN §1): `[a, b, tx, ty]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Similarity {
    pub a: f64,
    pub b: f64,
    pub tx: f64,
    pub ty: f64,
}

impl Similarity {
    pub const IDENTITY: Similarity = Similarity {
        a: 1.0,
        b: 0.0,
        tx: 0.0,
        ty: 0.0,
    };

    pub fn new(scale: f64, angle: f64, tx: f64, ty: f64) -> Self {
        Similarity {
            a: scale * angle.cos(),
            b: scale * angle.sin(),
            tx,
            ty,
        }
    }

    pub fn scale(&self) -> f64 {
        self.a.hypot(self.b)
    }

    pub fn angle(&self) -> f64 {
        self.b.atan2(self.a)
    }

    pub fn apply(&self, p: Point) -> Point {
        [
            self.a * p[0] - self.b * p[1] + self.tx,
            self.b * p[0] + self.a * p[1] + self.ty,
        ]
    }

    pub fn apply_all(&self, points: &[Point]) -> Vec<Point> {
        points.iter().map(|&p| self.apply(p)).collect()
    }

    /// The inverse transform (the scale must be non-zero).
    pub fn invert(&self) -> Self {
        let d = self.a * self.a + self.b * self.b;
        let (a, b) = (self.a / d, -self.b / d);
        Similarity {
            a,
            b,
            tx: -(a * self.tx - b * self.ty),
            ty: -(b * self.tx + a * self.ty),
        }
    }

    /// `self ∘ other`: apply `other` first, then `self`.
    pub fn compose(&self, other: &Similarity) -> Self {
        let t = self.apply([other.tx, other.ty]);
        Similarity {
            a: self.a * other.a - self.b * other.b,
            b: self.a * other.b + self.b * other.a,
            tx: t[0],
            ty: t[1],
        }
    }

    pub fn to_array(&self) -> [f64; 4] {
        [self.a, self.b, self.tx, self.ty]
    }

    pub fn from_array(v: [f64; 4]) -> Self {
        Similarity {
            a: v[0],
            b: v[1],
            tx: v[2],
            ty: v[3],
        }
    }
}

/// The least-squares similarity `T` minimising `Σ |T(from_i) − to_i|²` (Umeyama / ordinary
/// Procrustes). `None` when `from` has no extent.
pub fn align(from: &[Point], to: &[Point]) -> Option<Similarity> {
    assert_eq!(from.len(), to.len(), "align: point counts differ");
    let cf = centroid(from);
    let ct = centroid(to);
    let (mut denom, mut num_a, mut num_b) = (0.0, 0.0, 0.0);
    for (f, t) in from.iter().zip(to) {
        let (fx, fy, tx, ty) = (f[0] - cf[0], f[1] - cf[1], t[0] - ct[0], t[1] - ct[1]);
        denom += fx * fx + fy * fy;
        num_a += fx * tx + fy * ty;
        num_b += fx * ty - fy * tx;
    }
    if denom <= f64::MIN_POSITIVE {
        return None;
    }
    let (a, b) = (num_a / denom, num_b / denom);
    Some(Similarity {
        a,
        b,
        tx: ct[0] - (a * cf[0] - b * cf[1]),
        ty: ct[1] - (b * cf[0] + a * cf[1]),
    })
}

pub fn centroid(points: &[Point]) -> Point {
    let n = points.len() as f64;
    let s = points
        .iter()
        .fold([0.0, 0.0], |s, p| [s[0] + p[0], s[1] + p[1]]);
    [s[0] / n, s[1] / n]
}

/// Centres the points and scales them to unit Frobenius norm.
fn normalise(points: &[Point]) -> Option<Vec<Point>> {
    let c = centroid(points);
    let centred: Vec<Point> = points.iter().map(|p| [p[0] - c[0], p[1] - c[1]]).collect();
    let norm = centred
        .iter()
        .map(|p| p[0] * p[0] + p[1] * p[1])
        .sum::<f64>()
        .sqrt();
    (norm > f64::MIN_POSITIVE).then(|| centred.iter().map(|p| [p[0] / norm, p[1] / norm]).collect())
}

/// Result of generalised Procrustes analysis.
#[derive(Clone, Debug)]
pub struct Procrustes {
    /// The mean shape: centred, unit norm, in the orientation of the first shape.
    pub mean: Vec<Point>,
    /// Each shape mapped into the mean's frame: `poses[i].invert()` applied to shape `i`.
    /// These lie in the tangent plane of the mean (`x · mean = 1`, no rotation or
    /// translation component) because each pose is fitted from the mean onto the shape.
    pub aligned: Vec<Vec<Point>>,
    /// `poses[i]` maps the mean frame onto shape `i` in its image.
    pub poses: Vec<Similarity>,
    pub iterations: usize,
}

/// Generalised Procrustes analysis: align every shape to the mean, re-estimate the mean,
/// normalise it (centre, unit norm, orientation held to the previous estimate), repeat until
/// the mean moves less than 1e-12.
pub fn generalised_procrustes(shapes: &[Landmarks]) -> Result<Procrustes, ShapeError> {
    if shapes.len() < 2 {
        return Err(ShapeError::TooFewShapes(shapes.len()));
    }
    let n = shapes[0].len();
    for (i, s) in shapes.iter().enumerate() {
        s.validate(Some(n), &format!("shape {i}"))?;
    }
    let degenerate = |i: usize| ShapeError::Degenerate {
        what: format!("shape {i}"),
    };
    let mut mean = normalise(&shapes[0].points).ok_or_else(|| degenerate(0))?;
    let mut iterations = 0;
    loop {
        iterations += 1;
        let poses = shapes
            .iter()
            .enumerate()
            .map(|(i, s)| {
                align(&mean, &s.points)
                    .filter(|t| t.scale() > 0.0)
                    .ok_or_else(|| degenerate(i))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let aligned: Vec<Vec<Point>> = shapes
            .iter()
            .zip(&poses)
            .map(|(s, t)| t.invert().apply_all(&s.points))
            .collect();
        let mut next = vec![[0.0, 0.0]; n];
        for shape in &aligned {
            for (m, p) in next.iter_mut().zip(shape) {
                m[0] += p[0] / shapes.len() as f64;
                m[1] += p[1] / shapes.len() as f64;
            }
        }
        let next = normalise(&next).ok_or(ShapeError::Degenerate {
            what: "mean shape".into(),
        })?;
        // Hold the orientation: rotate the new mean onto the old one (rotation only).
        let t = align(&next, &mean).expect("normalised mean has extent");
        let rotation = Similarity {
            a: t.a / t.scale(),
            b: t.b / t.scale(),
            tx: 0.0,
            ty: 0.0,
        };
        let next = rotation.apply_all(&next);
        let change: f64 = next
            .iter()
            .zip(&mean)
            .map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2))
            .sum();
        mean = next;
        if change.sqrt() < 1e-12 || iterations >= 100 {
            // Re-derive poses and aligned shapes against the final mean.
            let poses: Vec<Similarity> = shapes
                .iter()
                .enumerate()
                .map(|(i, s)| align(&mean, &s.points).ok_or_else(|| degenerate(i)))
                .collect::<Result<_, _>>()?;
            let aligned = shapes
                .iter()
                .zip(&poses)
                .map(|(s, t)| t.invert().apply_all(&s.points))
                .collect();
            return Ok(Procrustes {
                mean,
                aligned,
                poses,
                iterations,
            });
        }
    }
}

/// Point distribution model: `x ≈ pose(x̄ + P_s b_s)` ([blend] §3). The mean `x̄` is centred
/// with unit norm; the components are orthogonal to its similarity directions, so the pose
/// and `b_s` separate exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeModel {
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

    pub fn n_landmarks(&self) -> usize {
        self.pca.dim() / 2
    }

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
        let aligned = Landmarks {
            points: pose.invert().apply_all(&landmarks.points),
        };
        Ok((pose, self.pca.project(&aligned.to_flat())))
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
