//! Piecewise affine warps between an image and the reference frame, bilinear sampling,
//! parallel with rayon (DESIGN §2, §10).
//!
//! * [`to_reference`]: image at its landmarks → shape-normalised texture. Each mask pixel's
//!   precomputed triangle and barycentric coordinates give its source point directly.
//! * [`from_reference_into`]: texture → image at new landmarks. Each destination triangle is
//!   rasterised and every covered pixel samples the reference frame through the triangle's
//!   affine map.
//!
//! Textures are `n_pixels × 3` interleaved RGB `f32` in grey levels (0–255), in mask order.

use image::RgbImage;
use rayon::prelude::*;
use thiserror::Error;

mod draw;

pub use draw::{
    RENDER_DILATION, from_reference_blend_into, from_reference_into, texture_to_image,
    texture_to_rgb, to_u8,
};
#[cfg(feature = "gpu")]
pub(crate) use draw::{Tri, triangles};

use crate::mesh::ReferenceFrame;
use crate::shape::Point;

/// What can be wrong with a warp's inputs.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum WarpError {
    /// Another number of landmarks than the mesh has.
    #[error("{found} landmarks given, the mesh has {expected}")]
    LandmarkCount {
        /// The mesh's count.
        expected: usize,
        /// Given.
        found: usize,
    },
    /// A NaN or infinite landmark.
    #[error("landmark {index} is not finite")]
    NotFinite {
        /// The landmark.
        index: usize,
    },
    /// A texture of another length than the reference frame needs.
    #[error("texture has {found} values, the reference frame needs {expected} (pixels × 3)")]
    TextureLength {
        /// Values needed.
        expected: usize,
        /// Values given.
        found: usize,
    },
    /// An image without pixels.
    #[error("image is empty ({width}×{height})")]
    EmptyImage {
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
    },
}

/// Bilinear sample of an RGB image at `(x, y)` (pixel centres at integers), clamped to
/// the border.
#[inline]
pub fn sample_bilinear(image: &RgbImage, x: f64, y: f64) -> [f32; 3] {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let data = image.as_raw();
    sample::<u8, 3>(data, w, h, x, y, |v: u8| v as f32)
}

#[inline(always)]
fn sample<T: Copy, const C: usize>(
    data: &[T],
    w: usize,
    h: usize,
    x: f64,
    y: f64,
    to_f32: impl Fn(T) -> f32,
) -> [f32; C] {
    let xc = x.clamp(0.0, (w - 1) as f64);
    let yc = y.clamp(0.0, (h - 1) as f64);
    // Truncation is floor here (both are ≥ 0) and, unlike f64::floor on baseline x86-64,
    // needs no libm call.
    // Through i32 for the same reason (both are in 0..=w − 1 after the clamp).
    let (x0, y0) = (xc as i32 as usize, yc as i32 as usize);
    let (fx, fy) = ((xc - x0 as f64) as f32, (yc - y0 as f64) as f32);
    // The two texels of each row as one slice (one bounds check per row); at the last
    // column or row the neighbour is the texel itself.
    let dx = if x0 + 1 < w { C } else { 0 };
    let dy = if y0 + 1 < h { w * C } else { 0 };
    let i00 = (y0 * w + x0) * C;
    let top = &data[i00..i00 + dx + C];
    let bottom = &data[i00 + dy..i00 + dy + dx + C];
    let mut out = [0f32; C];
    for (c, o) in out.iter_mut().enumerate() {
        let t = to_f32(top[c]) * (1.0 - fx) + to_f32(top[dx + c]) * fx;
        let b = to_f32(bottom[c]) * (1.0 - fx) + to_f32(bottom[dx + c]) * fx;
        *o = t * (1.0 - fy) + b * fy;
    }
    out
}

/// [`sample`] for a point known to lie in `[0, w − 2] × [0, h − 2]` (every texel neighbour
/// exists): no clamping or edge tests, for the bulk of pixels whose triangle lies inside.
#[inline(always)]
fn sample_inside<T: Copy, const C: usize>(
    data: &[T],
    w: usize,
    x: f64,
    y: f64,
    to_f32: impl Fn(T) -> f32,
) -> [f32; C] {
    let (x0, y0) = (x as i32 as usize, y as i32 as usize);
    let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
    let i00 = (y0 * w + x0) * C;
    let top = &data[i00..i00 + 2 * C];
    let bottom = &data[i00 + w * C..i00 + w * C + 2 * C];
    let mut out = [0f32; C];
    for (c, o) in out.iter_mut().enumerate() {
        let t = to_f32(top[c]) * (1.0 - fx) + to_f32(top[C + c]) * fx;
        let b = to_f32(bottom[c]) * (1.0 - fx) + to_f32(bottom[C + c]) * fx;
        *o = t * (1.0 - fy) + b * fy;
    }
    out
}

/// Whether every point lies at least `margin` pixels inside where [`sample_inside`] may
/// sample a `w × h` image.
fn all_inside(points: &[[f64; 2]], w: usize, h: usize, margin: f64) -> bool {
    let (xs, ys) = (
        margin..=w as f64 - 2.0 - margin,
        margin..=h as f64 - 2.0 - margin,
    );
    points
        .iter()
        .all(|p| xs.contains(&p[0]) && ys.contains(&p[1]))
}

/// A single-channel f32 image (grey levels), for fitting on luminance.
#[derive(Clone, Debug, PartialEq)]
pub struct GreyImage {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Row-major grey levels.
    pub data: Vec<f32>,
}

impl GreyImage {
    /// The mean of R, G and B: the grey of a texture warped in RGB is the warp of this.
    pub fn from_rgb(image: &RgbImage) -> Self {
        let data = image
            .as_raw()
            .chunks_exact(3)
            .map(|c| (c[0] as f32 + c[1] as f32 + c[2] as f32) / 3.0)
            .collect();
        GreyImage {
            width: image.width() as usize,
            height: image.height() as usize,
            data,
        }
    }

    /// Half size by 2×2 averaging (an odd last row or column is dropped).
    pub fn half(&self) -> Self {
        let (w, h) = ((self.width / 2).max(1), (self.height / 2).max(1));
        let at = |x: usize, y: usize| {
            self.data[y.min(self.height - 1) * self.width + x.min(self.width - 1)]
        };
        let data = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| {
                (at(2 * x, 2 * y)
                    + at(2 * x + 1, 2 * y)
                    + at(2 * x, 2 * y + 1)
                    + at(2 * x + 1, 2 * y + 1))
                    / 4.0
            })
            .collect();
        GreyImage {
            width: w,
            height: h,
            data,
        }
    }
}

/// Per triangle, the affine map from a reference-frame pixel to its source point in the image,
/// `(x, y) = (m[0] + m[1]·px + m[2]·py, m[3] + m[4]·px + m[5]·py)`: the barycentric
/// combination of the triangle's image vertices, folded once per call so each pixel costs two
/// multiply-adds per coordinate.
fn source_maps(frame: &ReferenceFrame, landmarks: &[Point]) -> Vec<[f64; 6]> {
    frame
        .triangles
        .iter()
        .map(|t| {
            let [r0, r1, r2] = t.map(|v| frame.landmarks[v as usize]);
            let [a, b, c] = t.map(|v| landmarks[v as usize]);
            match crate::mesh::BarycentricMap::new(r0, r1, r2) {
                Some(to_bary) => {
                    let (l00, l10, l01) = (
                        to_bary.at([0.0, 0.0]),
                        to_bary.at([1.0, 0.0]),
                        to_bary.at([0.0, 1.0]),
                    );
                    let at = |l: [f64; 3], k: usize| l[0] * a[k] + l[1] * b[k] + l[2] * c[k];
                    let (x0, y0) = (at(l00, 0), at(l00, 1));
                    [
                        x0,
                        at(l10, 0) - x0,
                        at(l01, 0) - x0,
                        y0,
                        at(l10, 1) - y0,
                        at(l01, 1) - y0,
                    ]
                }
                // A degenerate reference triangle covers no mask pixel.
                None => [a[0], 0.0, 0.0, a[1], 0.0, 0.0],
            }
        })
        .collect()
}

/// Gathers `C`-channel samples of `data` (`w × h`) at each mask pixel's source point.
fn gather<T: Copy + Send + Sync, const C: usize>(
    frame: &ReferenceFrame,
    data: &[T],
    (w, h): (usize, usize),
    landmarks: &[Point],
    out: &mut [f32],
    to_f32: impl Fn(T) -> f32 + Sync,
) {
    const CHUNK: usize = 2048;
    // A triangle whose image vertices all lie inside needs no clamping at any of its pixels
    // (they are convex combinations of the vertices; a margin of one pixel absorbs rounding).
    let maps: Vec<([f64; 6], bool)> = source_maps(frame, landmarks)
        .into_iter()
        .zip(&frame.triangles)
        .map(|(m, t)| (m, all_inside(&t.map(|v| landmarks[v as usize]), w, h, 1.0)))
        .collect();
    out.par_chunks_mut(CHUNK * C)
        .zip(frame.pixels.par_chunks(CHUNK))
        .for_each(|(out, pixels)| {
            for (o, p) in out.chunks_exact_mut(C).zip(pixels) {
                let (m, inside) = &maps[p.triangle as usize];
                let (px, py) = (f64::from(p.x), f64::from(p.y));
                let x = m[0] + m[1] * px + m[2] * py;
                let y = m[3] + m[4] * px + m[5] * py;
                o.copy_from_slice(&if *inside {
                    sample_inside::<T, C>(data, w, x, y, &to_f32)
                } else {
                    sample::<T, C>(data, w, h, x, y, &to_f32)
                });
            }
        });
}

/// [`to_reference_into`] for a grey image: one value per mask pixel.
pub fn to_reference_grey_into(
    frame: &ReferenceFrame,
    image: &GreyImage,
    landmarks: &[Point],
    out: &mut [f32],
) -> Result<(), WarpError> {
    check_landmarks(frame, landmarks)?;
    if image.width == 0 || image.height == 0 {
        return Err(WarpError::EmptyImage {
            width: image.width as u32,
            height: image.height as u32,
        });
    }
    if out.len() != frame.n_pixels() {
        return Err(WarpError::TextureLength {
            expected: frame.n_pixels(),
            found: out.len(),
        });
    }
    gather::<f32, 1>(
        frame,
        &image.data,
        (image.width, image.height),
        landmarks,
        out,
        |v| v,
    );
    Ok(())
}

pub(crate) fn check_landmarks(
    frame: &ReferenceFrame,
    landmarks: &[Point],
) -> Result<(), WarpError> {
    if landmarks.len() != frame.landmarks.len() {
        return Err(WarpError::LandmarkCount {
            expected: frame.landmarks.len(),
            found: landmarks.len(),
        });
    }
    match landmarks
        .iter()
        .position(|p| !(p[0].is_finite() && p[1].is_finite()))
    {
        Some(index) => Err(WarpError::NotFinite { index }),
        None => Ok(()),
    }
}

/// Warps `image`, whose face has `landmarks`, into the reference frame.
pub fn to_reference(
    frame: &ReferenceFrame,
    image: &RgbImage,
    landmarks: &[Point],
) -> Result<Vec<f32>, WarpError> {
    let mut out = vec![0f32; frame.n_pixels() * 3];
    to_reference_into(frame, image, landmarks, &mut out)?;
    Ok(out)
}

/// [`to_reference`] into a caller's buffer of `n_pixels × 3` values.
pub fn to_reference_into(
    frame: &ReferenceFrame,
    image: &RgbImage,
    landmarks: &[Point],
    out: &mut [f32],
) -> Result<(), WarpError> {
    check_landmarks(frame, landmarks)?;
    if image.width() == 0 || image.height() == 0 {
        return Err(WarpError::EmptyImage {
            width: image.width(),
            height: image.height(),
        });
    }
    if out.len() != frame.n_pixels() * 3 {
        return Err(WarpError::TextureLength {
            expected: frame.n_pixels() * 3,
            found: out.len(),
        });
    }
    gather::<u8, 3>(
        frame,
        image.as_raw(),
        (image.width() as usize, image.height() as usize),
        landmarks,
        out,
        |v| v as f32,
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unclamped sampler agrees with the clamped one wherever it may be used, on a
    /// 3-channel image with distinct texels, up to the image's last inner texel.
    #[test]
    fn sample_inside_matches_sample() {
        let (w, h) = (7, 5);
        let data: Vec<u8> = (0..w * h * 3).map(|i| (i * 37 % 251) as u8).collect();
        let to_f32 = |v: u8| f32::from(v);
        let mut checked = 0;
        for i in 0..=40 {
            for j in 0..=40 {
                let (x, y) = (i as f64 * 0.125, j as f64 * 0.075);
                if !all_inside(&[[x, y]], w, h, 0.0) {
                    continue;
                }
                let a = sample::<u8, 3>(&data, w, h, x, y, to_f32);
                let b = sample_inside::<u8, 3>(&data, w, x, y, to_f32);
                assert_eq!(a, b, "at ({x}, {y})");
                checked += 1;
            }
        }
        // Points up to x = 5, y = 3 (the last inner texel) were all compared.
        assert_eq!(checked, 41 * 41);
        assert!(!all_inside(&[[5.01, 0.0]], w, h, 0.0));
        assert!(!all_inside(&[[1.0, 1.0]], w, h, 1.5));
    }
}
