//! Triangulation of the mean shape and the reference frame the appearance model lives in:
//! a mask of the pixels inside the mesh, each with its triangle and barycentric coordinates,
//! computed once so a warp is a gather with no per-pixel search (DESIGN §2, §10).

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::shape::Point;

/// Triangle vertex indices into a landmark list.
pub type Triangle = [u32; 3];

/// What can be wrong with a mesh or reference frame.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum MeshError {
    /// Points that cannot be triangulated (too few, coincident, collinear).
    #[error("cannot triangulate: {0}")]
    Degenerate(String),
    /// A triangle naming a landmark that does not exist.
    #[error("triangle {index} refers to landmark {vertex}, but there are only {count} landmarks")]
    IndexOutOfRange {
        /// The triangle.
        index: usize,
        /// The vertex it names.
        vertex: u32,
        /// Landmarks there are.
        count: usize,
    },
    /// A triangle without area.
    #[error("triangle {index} {triangle:?} has (near) zero area {area:.3e}")]
    ZeroArea {
        /// The triangle.
        index: usize,
        /// Its vertices.
        triangle: Triangle,
        /// Its area.
        area: f64,
    },
    /// A reference frame too small to hold a face.
    #[error("reference frame of {0} pixels is too small (need at least 100)")]
    TooFewPixels(usize),
    /// A reference frame too large to allocate sensibly.
    #[error("a {width}×{height} reference frame exceeds {MAX_FRAME_PIXELS} pixels")]
    TooLarge {
        /// Its width.
        width: f64,
        /// Its height.
        height: f64,
    },
}

/// Largest reference frame (bounding box, pixels) placed: a damaged placement cannot ask for
/// gigabytes.
pub const MAX_FRAME_PIXELS: usize = 16_000_000;

/// Delaunay triangulation of the points (counter-clockwise in x-right/y-down pixel axes
/// is not guaranteed; use [`signed_area`] where orientation matters).
pub fn delaunay(points: &[Point]) -> Result<Vec<Triangle>, MeshError> {
    if points.len() < 3 {
        return Err(MeshError::Degenerate(format!(
            "{} points (need at least 3)",
            points.len()
        )));
    }
    for (i, p) in points.iter().enumerate() {
        if let Some(j) = points[..i].iter().position(|q| q == p) {
            return Err(MeshError::Degenerate(format!(
                "landmarks {j} and {i} coincide at {p:?}"
            )));
        }
    }
    let pts: Vec<delaunator::Point> = points
        .iter()
        .map(|p| delaunator::Point { x: p[0], y: p[1] })
        .collect();
    let t = delaunator::triangulate(&pts);
    if t.triangles.is_empty() {
        return Err(MeshError::Degenerate("all landmarks are collinear".into()));
    }
    let triangles: Vec<Triangle> = t
        .triangles
        .chunks_exact(3)
        .map(|c| [c[0] as u32, c[1] as u32, c[2] as u32])
        .collect();
    validate(points, &triangles)?;
    Ok(triangles)
}

/// A face region (\[blend\] §3: separate models per region): the landmarks whose mesh the
/// region's appearance model covers. Synthesis drives the region and the rest of the face
/// comes from the background.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Region {
    /// iBUG-68's lower face: the jaw line (0–16), the base of the nose (31–35) and the lips
    /// (48–67) — the articulators and the cheeks between them, not the eyes or brows.
    LowerFace,
    /// These landmarks (indices into the landmark list).
    Landmarks(Vec<u32>),
}

impl Region {
    /// The region's landmark indices, checked against a landmark count.
    pub fn landmarks(&self, count: usize) -> Result<Vec<u32>, MeshError> {
        let list: Vec<u32> = match self {
            Region::LowerFace => {
                if count != 68 {
                    return Err(MeshError::Degenerate(format!(
                        "the lower-face region is defined on iBUG's 68 landmarks, the model has {count}"
                    )));
                }
                (0..17).chain(31..36).chain(48..68).collect()
            }
            Region::Landmarks(l) => l.clone(),
        };
        if let Some(&vertex) = list.iter().find(|&&v| v as usize >= count) {
            return Err(MeshError::IndexOutOfRange {
                index: 0,
                vertex,
                count,
            });
        }
        Ok(list)
    }

    /// The landmarks synthesis moves within the region — for the lower face the lips and the
    /// chin (jaw 5–11) — while the others stay where the background's face has them
    /// (`None`: no such split is known for a custom region).
    pub fn articulators(&self) -> Option<Vec<u32>> {
        match self {
            Region::LowerFace => Some((5..12).chain(48..68).collect()),
            Region::Landmarks(_) => None,
        }
    }

    /// The Delaunay triangulation of the region's landmarks of `points`, as triangles over the
    /// whole landmark list.
    pub fn triangulate(&self, points: &[Point]) -> Result<Vec<Triangle>, MeshError> {
        let list = self.landmarks(points.len())?;
        let sub: Vec<Point> = list.iter().map(|&v| points[v as usize]).collect();
        Ok(delaunay(&sub)?
            .into_iter()
            .map(|t| t.map(|v| list[v as usize]))
            .collect())
    }
}

/// Twice the signed area of a triangle.
pub fn signed_area(a: Point, b: Point, c: Point) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
}

/// Checks indices and that no triangle is degenerate relative to the whole mesh.
pub fn validate(points: &[Point], triangles: &[Triangle]) -> Result<(), MeshError> {
    if triangles.is_empty() {
        return Err(MeshError::Degenerate("no triangles".into()));
    }
    for (index, t) in triangles.iter().enumerate() {
        if let Some(&vertex) = t.iter().find(|&&v| v as usize >= points.len()) {
            return Err(MeshError::IndexOutOfRange {
                index,
                vertex,
                count: points.len(),
            });
        }
    }
    let area = |t: &Triangle| {
        0.5 * signed_area(
            points[t[0] as usize],
            points[t[1] as usize],
            points[t[2] as usize],
        )
        .abs()
    };
    let total: f64 = triangles.iter().map(area).sum();
    let floor = 1e-9 * total.max(f64::MIN_POSITIVE);
    for (index, t) in triangles.iter().enumerate() {
        let a = area(t);
        if a <= floor {
            return Err(MeshError::ZeroArea {
                index,
                triangle: *t,
                area: a,
            });
        }
    }
    Ok(())
}

/// One pixel of the reference-frame mask.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskPixel {
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
    /// The triangle covering it.
    pub triangle: u32,
    /// Barycentric coordinates of the pixel centre in its triangle (sum to 1).
    pub bary: [f32; 3],
}

/// How a reference frame was placed: `pixel = scale · x̄ + offset` for the mean shape `x̄`,
/// and how wide a rim inside the mesh boundary the mask leaves out.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Pixels per unit of the (unit-norm) mean shape.
    pub scale: f64,
    /// Where the mean shape's origin lies, pixels.
    pub offset: Point,
    /// Reference-frame pixels next to the mesh boundary left out of the mask (the appearance
    /// model): hand-marked outlines let background in there, and a model that learned it
    /// would draw a streak of it on the face. Rendering fills the rim from the background.
    #[serde(default)]
    pub margin: f64,
}

/// The shape-normalised image domain: the mesh at the mean shape, its mask and the
/// precomputed per-pixel triangle and barycentric map.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceFrame {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// The mesh vertices in reference-frame pixels.
    pub landmarks: Vec<Point>,
    /// The mesh's triangles.
    pub triangles: Vec<Triangle>,
    /// Mask pixels, in row-major order; appearance vectors follow this order.
    pub pixels: Vec<MaskPixel>,
    /// Pixels just outside the mask and the mask pixel that fills them, nearest rings
    /// first, so bilinear sampling at the mesh edge never reads undefined texture.
    pub padding: Vec<(u32, u32)>,
    /// Per triangle, whether the edge opposite each vertex lies on the mesh boundary
    /// (belongs to no other triangle). Rendering dilates across these edges only.
    pub hull_edges: Vec<[bool; 3]>,
    /// The rim left out of the mask ([`Placement::margin`]), pixels.
    pub margin: f64,
}

/// Margin in pixels kept around the mesh inside the reference frame.
const MARGIN: f64 = 2.0;

impl ReferenceFrame {
    /// Scales the (normalised) mean shape so the mesh covers about `target_pixels` pixels,
    /// leaving a rim of `margin` pixels inside the boundary out of the mask.
    pub fn fit_mean(
        mean: &[Point],
        triangles: Vec<Triangle>,
        target_pixels: usize,
        margin: f64,
    ) -> Result<(Self, Placement), MeshError> {
        if target_pixels < 100 {
            return Err(MeshError::TooFewPixels(target_pixels));
        }
        validate(mean, &triangles)?;
        let area: f64 = triangles
            .iter()
            .map(|t| {
                0.5 * signed_area(
                    mean[t[0] as usize],
                    mean[t[1] as usize],
                    mean[t[2] as usize],
                )
                .abs()
            })
            .sum();
        let scale = (target_pixels as f64 / area).sqrt();
        let min = mean
            .iter()
            .fold([f64::INFINITY; 2], |m, p| [m[0].min(p[0]), m[1].min(p[1])]);
        let placement = Placement {
            scale,
            offset: [MARGIN - scale * min[0], MARGIN - scale * min[1]],
            margin,
        };
        Ok((Self::place(mean, triangles, placement)?, placement))
    }

    /// Rebuilds a frame from a stored placement (bit-identical to the one it was saved from).
    pub fn place(
        mean: &[Point],
        triangles: Vec<Triangle>,
        placement: Placement,
    ) -> Result<Self, MeshError> {
        let landmarks: Vec<Point> = mean
            .iter()
            .map(|p| {
                [
                    placement.scale * p[0] + placement.offset[0],
                    placement.scale * p[1] + placement.offset[1],
                ]
            })
            .collect();
        let max = landmarks
            .iter()
            .fold([0f64; 2], |m, p| [m[0].max(p[0]), m[1].max(p[1])]);
        let (w, h) = (
            (max[0] + MARGIN).ceil() + 1.0,
            (max[1] + MARGIN).ceil() + 1.0,
        );
        if w * h > MAX_FRAME_PIXELS as f64 || !(w * h).is_finite() {
            return Err(MeshError::TooLarge {
                width: w,
                height: h,
            });
        }
        Self::with_margin(
            landmarks,
            triangles,
            w as usize,
            h as usize,
            placement.margin,
        )
    }

    /// A frame from explicit vertex positions and size (for warps onto any target shape).
    pub fn from_landmarks(
        landmarks: Vec<Point>,
        triangles: Vec<Triangle>,
        width: usize,
        height: usize,
    ) -> Result<Self, MeshError> {
        Self::with_margin(landmarks, triangles, width, height, 0.0)
    }

    fn with_margin(
        landmarks: Vec<Point>,
        triangles: Vec<Triangle>,
        width: usize,
        height: usize,
        margin: f64,
    ) -> Result<Self, MeshError> {
        validate(&landmarks, &triangles)?;
        if !(margin.is_finite() && margin >= 0.0) {
            return Err(MeshError::Degenerate(format!(
                "a rim margin of {margin} pixels"
            )));
        }
        let (owner, bary) = cover(&landmarks, &triangles, width, height);
        let hull_edges = hull_edges(&triangles);
        let rim = rim_segments(&landmarks, &triangles, &hull_edges);
        let pixels: Vec<MaskPixel> = (0..width * height)
            .filter(|&i| owner[i] != u32::MAX)
            .map(|i| MaskPixel {
                x: (i % width) as u32,
                y: (i / width) as u32,
                triangle: owner[i],
                bary: bary[i],
            })
            .filter(|p| margin == 0.0 || rim_distance(&rim, [p.x as f64, p.y as f64]) >= margin)
            .collect();
        let padding = padding_rings(width, height, &pixels, 2 + margin.ceil() as usize);
        Ok(ReferenceFrame {
            width,
            height,
            landmarks,
            triangles,
            pixels,
            padding,
            hull_edges,
            margin,
        })
    }

    /// Each mask pixel's distance (pixels) to the mesh boundary.
    pub fn rim_distances(&self) -> Vec<f64> {
        let rim = rim_segments(&self.landmarks, &self.triangles, &self.hull_edges);
        self.pixels
            .iter()
            .map(|p| rim_distance(&rim, [p.x as f64, p.y as f64]))
            .collect()
    }

    /// Each mask pixel's distance (pixels) to the part of the mesh made of the triangles whose
    /// every corner is in `vertices`: 0 inside it, +∞ everywhere when no triangle is.
    pub fn part_distances(&self, vertices: &[u32]) -> Vec<f64> {
        let part: Vec<bool> = self
            .triangles
            .iter()
            .map(|t| t.iter().all(|v| vertices.contains(v)))
            .collect();
        let inner: Vec<Triangle> = self
            .triangles
            .iter()
            .zip(&part)
            .filter(|(_, in_part)| **in_part)
            .map(|(t, _)| *t)
            .collect();
        let outline = rim_segments(&self.landmarks, &inner, &hull_edges(&inner));
        self.pixels
            .iter()
            .map(|p| {
                if part[p.triangle as usize] {
                    0.0
                } else {
                    rim_distance(&outline, [p.x as f64, p.y as f64])
                }
            })
            .collect()
    }

    /// Number of mask pixels.
    pub fn n_pixels(&self) -> usize {
        self.pixels.len()
    }

    /// The mask as a `height × width` image: 255 inside the mesh, 0 outside.
    pub fn mask_image(&self) -> Vec<u8> {
        let mut m = vec![0u8; self.width * self.height];
        for p in &self.pixels {
            m[p.y as usize * self.width + p.x as usize] = 255;
        }
        m
    }
}

/// Rasterises a mesh onto a `width × height` grid: per pixel, the first triangle that covers
/// it (`u32::MAX` for none) and the pixel's barycentric coordinates in it.
pub fn cover(
    landmarks: &[Point],
    triangles: &[Triangle],
    width: usize,
    height: usize,
) -> (Vec<u32>, Vec<[f32; 3]>) {
    let mut owner = vec![u32::MAX; width * height];
    let mut bary = vec![[0f32; 3]; width * height];
    if width == 0 || height == 0 {
        return (owner, bary);
    }
    for (ti, t) in triangles.iter().enumerate() {
        let [a, b, c] = t.map(|v| landmarks[v as usize]);
        let Some(to_bary) = BarycentricMap::new(a, b, c) else {
            continue;
        };
        let (lo_x, hi_x) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
        let (lo_y, hi_y) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
        if !(hi_x >= 0.0 && hi_y >= 0.0 && lo_x < width as f64 && lo_y < height as f64) {
            continue;
        }
        let x0 = lo_x.floor().max(0.0) as usize;
        let x1 = (hi_x.ceil() as usize).min(width - 1);
        let y0 = lo_y.floor().max(0.0) as usize;
        let y1 = (hi_y.ceil() as usize).min(height - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let i = y * width + x;
                if owner[i] != u32::MAX {
                    continue;
                }
                let l = to_bary.at([x as f64, y as f64]);
                if l.iter().all(|&v| v >= -1e-9) {
                    owner[i] = ti as u32;
                    bary[i] = l.map(|v| v as f32);
                }
            }
        }
    }
    (owner, bary)
}

/// Maps a point to barycentric coordinates of a fixed triangle.
#[derive(Clone, Copy, Debug)]
pub struct BarycentricMap {
    origin: Point,
    inv: [[f64; 2]; 2],
}

impl BarycentricMap {
    /// `None` for a degenerate triangle.
    pub fn new(a: Point, b: Point, c: Point) -> Option<Self> {
        let (e1, e2) = ([b[0] - a[0], b[1] - a[1]], [c[0] - a[0], c[1] - a[1]]);
        let det = e1[0] * e2[1] - e2[0] * e1[1];
        if det.abs()
            <= f64::EPSILON * (e1[0].abs() + e1[1].abs() + e2[0].abs() + e2[1].abs()).powi(2)
        {
            return None;
        }
        Some(BarycentricMap {
            origin: a,
            inv: [[e2[1] / det, -e2[0] / det], [-e1[1] / det, e1[0] / det]],
        })
    }

    /// Barycentric coordinates of `p` (they sum to 1; all ≥ 0 inside the triangle).
    pub fn at(&self, p: Point) -> [f64; 3] {
        let (dx, dy) = (p[0] - self.origin[0], p[1] - self.origin[1]);
        let l1 = self.inv[0][0] * dx + self.inv[0][1] * dy;
        let l2 = self.inv[1][0] * dx + self.inv[1][1] * dy;
        [1.0 - l1 - l2, l1, l2]
    }
}

/// The mesh boundary as segments (the hull edges of every triangle).
fn rim_segments(
    landmarks: &[Point],
    triangles: &[Triangle],
    hull_edges: &[[bool; 3]],
) -> Vec<(Point, Point)> {
    let mut edges = Vec::new();
    for (t, hull) in triangles.iter().zip(hull_edges) {
        for i in 0..3 {
            if hull[i] {
                let (p, q) = (t[(i + 1) % 3] as usize, t[(i + 2) % 3] as usize);
                edges.push((landmarks[p], landmarks[q]));
            }
        }
    }
    edges
}

/// Distance from `c` to the nearest boundary segment: the least `hypot` over the segments, to
/// the bit. `hypot` is slow (every mask pixel against every rim segment, at each model load),
/// so the segments are ranked by the squared distance first, and `hypot` is taken only of
/// those within rounding of the least (a relative 1e-9, where the two differ by ~1e-15).
fn rim_distance(rim: &[(Point, Point)], c: Point) -> f64 {
    let squared = |&(p, q): &(Point, Point)| {
        let [x, y] = point_segment_offset(c, p, q);
        x * x + y * y
    };
    let least = rim.iter().map(squared).fold(f64::INFINITY, f64::min);
    rim.iter()
        .filter(|s| squared(s) <= least * (1.0 + 1e-9))
        .map(|&(p, q)| point_segment_distance(c, p, q))
        .fold(f64::INFINITY, f64::min)
}

/// The offset from the nearest point of segment `p`–`q` to `c`.
fn point_segment_offset(c: Point, p: Point, q: Point) -> [f64; 2] {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((c[0] - p[0]) * dx + (c[1] - p[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    [c[0] - p[0] - t * dx, c[1] - p[1] - t * dy]
}

fn point_segment_distance(c: Point, p: Point, q: Point) -> f64 {
    let [x, y] = point_segment_offset(c, p, q);
    x.hypot(y)
}

/// For each triangle, which of its edges (opposite vertex 0, 1, 2) no other triangle shares.
fn hull_edges(triangles: &[Triangle]) -> Vec<[bool; 3]> {
    let key = |a: u32, b: u32| (a.min(b), a.max(b));
    let mut count = std::collections::BTreeMap::new();
    for t in triangles {
        for i in 0..3 {
            *count
                .entry(key(t[(i + 1) % 3], t[(i + 2) % 3]))
                .or_insert(0) += 1;
        }
    }
    triangles
        .iter()
        .map(|t| std::array::from_fn(|i| count[&key(t[(i + 1) % 3], t[(i + 2) % 3])] == 1))
        .collect()
}

/// Rings of pixels around the mask, each filled from an already-defined 8-neighbour.
fn padding_rings(
    width: usize,
    height: usize,
    pixels: &[MaskPixel],
    rings: usize,
) -> Vec<(u32, u32)> {
    // source[i] = mask index whose value pixel i takes, for mask and padded pixels.
    let mut source = vec![u32::MAX; width * height];
    for (k, p) in pixels.iter().enumerate() {
        source[p.y as usize * width + p.x as usize] = k as u32;
    }
    let mut padding = Vec::new();
    for _ in 0..rings {
        let mut ring = Vec::new();
        for y in 0..height {
            for x in 0..width {
                if source[y * width + x] != u32::MAX {
                    continue;
                }
                let neighbours = [
                    (0i64, -1i64),
                    (-1, 0),
                    (1, 0),
                    (0, 1),
                    (-1, -1),
                    (1, -1),
                    (-1, 1),
                    (1, 1),
                ];
                let found = neighbours.iter().find_map(|&(dx, dy)| {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    (nx >= 0 && ny >= 0 && (nx as usize) < width && (ny as usize) < height)
                        .then(|| source[ny as usize * width + nx as usize])
                        .filter(|&s| s != u32::MAX)
                });
                if let Some(s) = found {
                    ring.push(((y * width + x) as u32, s));
                }
            }
        }
        for &(i, s) in &ring {
            source[i as usize] = s;
        }
        padding.extend(ring);
    }
    padding
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rim_distance_is_the_least_hypot_to_the_bit() {
        let mut rng = crate::rng::Rng::new(11);
        let mut point = || [rng.range(-50.0, 50.0), rng.range(-50.0, 50.0)];
        for n in [1, 2, 7, 30] {
            let rim: Vec<(Point, Point)> = (0..n).map(|_| (point(), point())).collect();
            for _ in 0..2_000 {
                let c = point();
                let reference = rim
                    .iter()
                    .map(|&(p, q)| point_segment_distance(c, p, q))
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(rim_distance(&rim, c).to_bits(), reference.to_bits());
            }
        }
        // Ties: a point equidistant from two segments, and one on a segment.
        let rim = [([0.0, 0.0], [0.0, 10.0]), ([2.0, 0.0], [2.0, 10.0])];
        assert_eq!(rim_distance(&rim, [1.0, 5.0]), 1.0);
        assert_eq!(rim_distance(&rim, [2.0, 3.0]), 0.0);
        assert_eq!(rim_distance(&[], [0.0, 0.0]), f64::INFINITY);
        // The segment's own hypot, not the square root of its square: a distance whose square
        // underflows.
        let tiny = [([0.0, 0.0], [0.0, 1.0])];
        assert_eq!(rim_distance(&tiny, [1e-200, 0.5]), 1e-200);
    }
}
