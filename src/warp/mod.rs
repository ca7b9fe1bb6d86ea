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

/// Catmull–Rom (bicubic, a = −½) sample of an RGB image at `(x, y)` (pixel centres at
/// integers), clamped to the border: it keeps more of the finest detail than
/// [`sample_bilinear`], whose fractional offsets act as a low-pass filter.
pub fn sample_cubic(image: &RgbImage, x: f64, y: f64) -> [f32; 3] {
    let (w, h) = (image.width() as i64, image.height() as i64);
    let data = image.as_raw();
    let (xf, yf) = (x.floor(), y.floor());
    let weights = |t: f64| {
        let (t2, t3) = (t * t, t * t * t);
        [
            0.5 * (-t3 + 2.0 * t2 - t),
            0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2),
        ]
    };
    let (wx, wy) = (weights(x - xf), weights(y - yf));
    let mut out = [0f64; 3];
    for (j, wyj) in wy.iter().enumerate() {
        let row = (yf as i64 - 1 + j as i64).clamp(0, h - 1);
        for (i, wxi) in wx.iter().enumerate() {
            let col = (xf as i64 - 1 + i as i64).clamp(0, w - 1);
            let o = ((row * w + col) * 3) as usize;
            for (c, v) in out.iter_mut().enumerate() {
                *v += wyj * wxi * f64::from(data[o + c]);
            }
        }
    }
    out.map(|v| v as f32)
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
            // The sum in integers is exact, as in f32 (at most 765), and vectorises.
            .map(|c| (u16::from(c[0]) + u16::from(c[1]) + u16::from(c[2])) as f32 / 3.0)
            .collect();
        GreyImage {
            width: image.width() as usize,
            height: image.height() as usize,
            data,
        }
    }

    /// Half size by 2×2 averaging (an odd last row or column is dropped; a one-pixel-wide or
    /// -high image repeats its only row or column). Row by row, in the order
    /// `((a + b) + c) + d`, so every value is the same to the bit as a per-pixel sum.
    pub fn half(&self) -> Self {
        let (w, h) = ((self.width / 2).max(1), (self.height / 2).max(1));
        let row = |r: usize| {
            let r = r.min(self.height - 1) * self.width;
            &self.data[r..r + self.width]
        };
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            let (top, bottom) = (row(2 * y), row(2 * y + 1));
            if self.width >= 2 {
                data.extend(
                    top.chunks_exact(2)
                        .zip(bottom.chunks_exact(2))
                        .map(|(t, b)| (t[0] + t[1] + b[0] + b[1]) / 4.0),
                );
            } else {
                data.push((top[0] + top[0] + bottom[0] + bottom[0]) / 4.0);
            }
        }
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

/// Gathers `C`-channel samples at each mask pixel's source point in an image of `w × h`:
/// `sample(x, y, inside)`, `inside` when the pixel's triangle lies wholly in the image (no
/// clamping needed).
fn gather<const C: usize>(
    frame: &ReferenceFrame,
    (w, h): (usize, usize),
    landmarks: &[Point],
    out: &mut [f32],
    sample: impl Fn(f64, f64, bool) -> [f32; C] + Sync,
) {
    const CHUNK: usize = 2048;
    // A triangle whose image vertices all lie inside needs no clamping at any of its pixels
    // (they are convex combinations of the vertices; a margin of one pixel absorbs rounding).
    let maps = inside_maps(frame, landmarks, w, h);
    out.par_chunks_mut(CHUNK * C)
        .zip(frame.pixels.par_chunks(CHUNK))
        .for_each(|(out, pixels)| {
            for (o, p) in out.chunks_exact_mut(C).zip(pixels) {
                let (m, inside) = &maps[p.triangle as usize];
                let (px, py) = (f64::from(p.x), f64::from(p.y));
                let x = m[0] + m[1] * px + m[2] * py;
                let y = m[3] + m[4] * px + m[5] * py;
                o.copy_from_slice(&sample(x, y, *inside));
            }
        });
}

/// A reference frame's mask as runs of pixels on one row in one triangle, grouped into
/// stretches of about [`Runs::GROUP`] pixels for threads: the fit warps its frame a few
/// hundred times a second, and a run needs its triangle's map looked up once, not per pixel.
#[derive(Clone, Debug)]
pub struct Runs {
    /// (first mask pixel, length, row, first column, triangle).
    runs: Vec<(u32, u32, u32, u32, u32)>,
    /// Each group's first run and first mask pixel; a last entry closes the last group.
    groups: Vec<(usize, usize)>,
}

impl Runs {
    /// Pixels a group holds, about.
    pub const GROUP: usize = 2048;

    /// The runs of `frame`'s mask (its pixels are row-major).
    pub fn new(frame: &ReferenceFrame) -> Self {
        let mut runs: Vec<(u32, u32, u32, u32, u32)> = Vec::new();
        for (i, p) in frame.pixels.iter().enumerate() {
            match runs.last_mut() {
                Some(r) if r.2 == p.y && r.4 == p.triangle && r.3 + r.1 == p.x => r.1 += 1,
                _ => runs.push((i as u32, 1, p.y, p.x, p.triangle)),
            }
        }
        let mut groups = vec![(0, 0)];
        for (k, r) in runs.iter().enumerate() {
            if r.0 as usize >= groups.last().expect("non-empty").1 + Self::GROUP {
                groups.push((k, r.0 as usize));
            }
        }
        groups.push((runs.len(), frame.pixels.len()));
        Runs { runs, groups }
    }
}

/// [`to_reference_into`] for a grey image: one value per mask pixel, by `runs` (of `frame`).
pub fn to_reference_grey_into(
    frame: &ReferenceFrame,
    runs: &Runs,
    image: &GreyImage,
    landmarks: &[Point],
    out: &mut [f32],
) -> Result<(), WarpError> {
    check_landmarks(frame, landmarks)?;
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return Err(WarpError::EmptyImage {
            width: w as u32,
            height: h as u32,
        });
    }
    if out.len() != frame.n_pixels() {
        return Err(WarpError::TextureLength {
            expected: frame.n_pixels(),
            found: out.len(),
        });
    }
    let maps: Vec<([f64; 6], bool)> = source_maps(frame, landmarks)
        .into_iter()
        .zip(&frame.triangles)
        .map(|(m, t)| (m, all_inside(&t.map(|v| landmarks[v as usize]), w, h, 1.0)))
        .collect();
    // Each group's stretch of the output.
    let mut pieces = Vec::with_capacity(runs.groups.len());
    let mut rest = out;
    for g in runs.groups.windows(2) {
        let (piece, tail) = rest.split_at_mut(g[1].1 - g[0].1);
        pieces.push((g[0].0..g[1].0, piece));
        rest = tail;
    }
    pieces.into_par_iter().for_each(|(group, piece)| {
        let runs = &runs.runs[group];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: this CPU has AVX2 (checked just above).
            unsafe { grey_runs_avx2(runs, &maps, image, piece) };
            return;
        }
        grey_runs(runs, &maps, image, piece);
    });
    Ok(())
}

/// Each triangle's map from reference pixels to image points ([`source_maps`]), with whether
/// the triangle lies inside a `w × h` image (so its pixels need no clamping).
fn inside_maps(
    frame: &ReferenceFrame,
    landmarks: &[Point],
    w: usize,
    h: usize,
) -> Vec<([f64; 6], bool)> {
    source_maps(frame, landmarks)
        .into_iter()
        .zip(&frame.triangles)
        .map(|(m, t)| (m, all_inside(&t.map(|v| landmarks[v as usize]), w, h, 1.0)))
        .collect()
}

/// [`grey_runs`] compiled for AVX2: twice the lanes a step, the same operations in the same
/// order (no fused multiply-add), so the same values to the bit.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn grey_runs_avx2(
    runs: &[(u32, u32, u32, u32, u32)],
    maps: &[([f64; 6], bool)],
    image: &GreyImage,
    piece: &mut [f32],
) {
    grey_runs(runs, maps, image, piece);
}

/// The grey warp of consecutive `runs` into `piece` (which starts at the first run's first
/// pixel), by the triangle maps `maps` (each with whether its triangle lies inside the image).
#[inline(always)]
fn grey_runs(
    runs: &[(u32, u32, u32, u32, u32)],
    maps: &[([f64; 6], bool)],
    image: &GreyImage,
    piece: &mut [f32],
) {
    let (data, w, h) = (&image.data, image.width, image.height);
    let Some(&(base, ..)) = runs.first() else {
        return;
    };
    let mut block = GreyBlock::default();
    for &(first, len, y, x0, t) in runs {
        let (m, inside) = &maps[t as usize];
        let py = f64::from(y);
        let at = (first - base) as usize;
        let out = &mut piece[at..at + len as usize];
        if *inside {
            for (b, out) in out.chunks_mut(GreyBlock::LEN).enumerate() {
                let x0 = x0 + (b * GreyBlock::LEN) as u32;
                block.sample_inside(data, w, m, x0, py, out);
            }
            continue;
        }
        for (k, o) in out.iter_mut().enumerate() {
            // The per-pixel expression of `gather`, for the same values to the bit.
            let px = f64::from(x0 + k as u32);
            let x = m[0] + m[1] * px + m[2] * py;
            let y = m[3] + m[4] * px + m[5] * py;
            *o = sample::<f32, 1>(data, w, h, x, y, |v| v)[0];
        }
    }
}

/// Scratch for [`sample_inside`] over a stretch of a run, one step at a time over every
/// pixel (source point, texel and fractions, the four texels, the blend), so the compiler
/// vectorises all but the texel reads: the grey warp is most of a fit's time. Each pixel
/// goes through the same operations as [`gather`]'s, for the same values to the bit.
struct GreyBlock {
    x: [f64; Self::LEN],
    y: [f64; Self::LEN],
    texel: [usize; Self::LEN],
    fx: [f32; Self::LEN],
    fy: [f32; Self::LEN],
    corners: [[f32; Self::LEN]; 4],
}

impl Default for GreyBlock {
    fn default() -> Self {
        GreyBlock {
            x: [0.0; Self::LEN],
            y: [0.0; Self::LEN],
            texel: [0; Self::LEN],
            fx: [0.0; Self::LEN],
            fy: [0.0; Self::LEN],
            corners: [[0.0; Self::LEN]; 4],
        }
    }
}

impl GreyBlock {
    /// Pixels a block holds.
    const LEN: usize = 32;

    /// `out[k]` = the grey image `data` (`w` wide) sampled bilinearly at the source point of
    /// pixel `(x0 + k, py)` under the triangle map `m`, all of whose points lie inside.
    #[inline(always)]
    fn sample_inside(
        &mut self,
        data: &[f32],
        w: usize,
        m: &[f64; 6],
        x0: u32,
        py: f64,
        out: &mut [f32],
    ) {
        let n = out.len();
        let (xs, ys) = (&mut self.x[..n], &mut self.y[..n]);
        for (k, (x, y)) in xs.iter_mut().zip(ys.iter_mut()).enumerate() {
            let px = f64::from(x0 + k as u32);
            *x = m[0] + m[1] * px + m[2] * py;
            *y = m[3] + m[4] * px + m[5] * py;
        }
        let (fxs, fys, texels) = (&mut self.fx[..n], &mut self.fy[..n], &mut self.texel[..n]);
        let points = xs.iter().zip(ys.iter());
        let samples = fxs.iter_mut().zip(fys.iter_mut()).zip(texels.iter_mut());
        for ((x, y), ((fx, fy), texel)) in points.zip(samples) {
            // SAFETY: the triangle's corners lie inside the image (`all_inside`, finite), so
            // its points are finite and within a pixel of it, far inside i32 (the saturating
            // `as` costs more here than the rest of the step and keeps it from vectorising).
            let (x0, y0): (i32, i32) = unsafe { (x.to_int_unchecked(), y.to_int_unchecked()) };
            *fx = (x - f64::from(x0)) as f32;
            *fy = (y - f64::from(y0)) as f32;
            *texel = y0 as usize * w + x0 as usize;
        }
        let [c00, c10, c01, c11] = &mut self.corners;
        let (c00, c10, c01, c11) = (&mut c00[..n], &mut c10[..n], &mut c01[..n], &mut c11[..n]);
        let corners = c00.iter_mut().zip(c10.iter_mut()).zip(c01.iter_mut()).zip(c11.iter_mut());
        for ((((c00, c10), c01), c11), &i) in corners.zip(texels.iter()) {
            let (top, bottom) = (&data[i..i + 2], &data[i + w..i + w + 2]);
            (*c00, *c10, *c01, *c11) = (top[0], top[1], bottom[0], bottom[1]);
        }
        let corners = c00.iter().zip(c10.iter()).zip(c01.iter()).zip(c11.iter());
        let weights = fxs.iter().zip(fys.iter());
        for ((o, (((c00, c10), c01), c11)), (&fx, &fy)) in out.iter_mut().zip(corners).zip(weights) {
            let t = c00 * (1.0 - fx) + c10 * fx;
            let b = c01 * (1.0 - fx) + c11 * fx;
            *o = t * (1.0 - fy) + b * fy;
        }
    }
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
    to_reference_with(frame, image, landmarks, out, Sampling::Bilinear)
}

/// How a warp samples its source image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    /// [`sample_bilinear`]: what tracking, model building and rendering use.
    Bilinear,
    /// [`sample_cubic`]: for textures that are resampled again and should keep their finest
    /// detail (a talker's recorded mouths).
    Cubic,
}

/// [`to_reference_into`] with the sampling given.
pub fn to_reference_with(
    frame: &ReferenceFrame,
    image: &RgbImage,
    landmarks: &[Point],
    out: &mut [f32],
    sampling: Sampling,
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
    let (w, h) = (image.width() as usize, image.height() as usize);
    let (data, to_f32) = (image.as_raw(), |v: u8| v as f32);
    match sampling {
        Sampling::Bilinear => gather(frame, (w, h), landmarks, out, |x, y, inside| {
            if inside {
                sample_inside::<u8, 3>(data, w, x, y, to_f32)
            } else {
                sample::<u8, 3>(data, w, h, x, y, to_f32)
            }
        }),
        Sampling::Cubic => gather(frame, (w, h), landmarks, out, |x, y, _| sample_cubic(image, x, y)),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grey is the mean of R, G and B as f32 sums give it, to the bit.
    #[test]
    fn grey_is_the_mean_of_the_channels() {
        let rgb = RgbImage::from_fn(64, 48, |x, y| {
            image::Rgb([(x * 4) as u8, (y * 5 + x) as u8, 255 - (x * y % 256) as u8])
        });
        let grey = GreyImage::from_rgb(&rgb);
        for (g, p) in grey.data.iter().zip(rgb.pixels()) {
            let mean = (p[0] as f32 + p[1] as f32 + p[2] as f32) / 3.0;
            assert_eq!(g.to_bits(), mean.to_bits(), "{p:?}");
        }
    }

    /// The half-size image is the mean of each 2×2 block, as a per-pixel sum with clamped
    /// reads gives it, to the bit, at even, odd and one-pixel sizes.
    #[test]
    fn half_is_the_mean_of_each_two_by_two_block() {
        for (width, height) in [(8, 6), (7, 5), (1, 4), (5, 1), (1, 1)] {
            let data = (0..width * height)
                .map(|i| ((i * 37) % 251) as f32 / 7.0)
                .collect();
            let image = GreyImage { width, height, data };
            let at = |x: usize, y: usize| image.data[y.min(height - 1) * width + x.min(width - 1)];
            let half = image.half();
            assert_eq!((half.width, half.height), ((width / 2).max(1), (height / 2).max(1)));
            for y in 0..half.height {
                for x in 0..half.width {
                    let mean = (at(2 * x, 2 * y)
                        + at(2 * x + 1, 2 * y)
                        + at(2 * x, 2 * y + 1)
                        + at(2 * x + 1, 2 * y + 1))
                        / 4.0;
                    assert_eq!(half.data[y * half.width + x].to_bits(), mean.to_bits(), "{width}×{height} at ({x}, {y})");
                }
            }
        }
    }

    /// Catmull–Rom interpolates (pixel centres come back exactly) and reproduces quadratics
    /// exactly away from the border (Keys 1981: third-order accurate for a = −½), where
    /// bilinear sampling is off by t(1 − t) at each fraction t.
    #[test]
    fn cubic_sampling_reproduces_a_quadratic() {
        let f = |x: f64, y: f64| x * x + 3.0 * y + y * y;
        let image = RgbImage::from_fn(12, 10, |x, y| {
            let v = f(f64::from(x), f64::from(y)) as u8;
            image::Rgb([v, v / 2, 255 - v])
        });
        for (x, y) in [(3.0, 4.0), (5.3, 2.0), (7.75, 6.4), (1.5, 1.25), (8.9, 7.6)] {
            let v = f(x, y);
            let s = sample_cubic(&image, x, y);
            assert!((f64::from(s[0]) - v).abs() < 1e-4, "({x}, {y}): {} against {v}", s[0]);
            assert!((f64::from(s[2]) - (255.0 - v)).abs() < 1e-4);
        }
        // Integer positions are the pixels themselves, even at the border (clamped).
        for (x, y) in [(0u32, 0u32), (11, 9), (4, 7)] {
            let p = image.get_pixel(x, y).0.map(f32::from);
            assert_eq!(sample_cubic(&image, f64::from(x), f64::from(y)), p);
        }
    }

    /// The grey warp by runs gives, to the bit, what the per-pixel RGB warp gives on the same
    /// image with R = G = B: inside the image, and with the face half off its edge (the
    /// clamped sampler).
    #[test]
    fn grey_runs_match_the_per_pixel_warp() {
        // A face's frame as a model builds it (its marked points' Delaunay mesh, ~20 000
        // pixels), from one of the test clip's hand-marked frames, lips parted.
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut face = crate::shape::read_pts(&root.join("tests/data/clip/01000.pts")).unwrap();
        for lower_inner_lip in &mut face.points[65..68] {
            lower_inner_lip[1] += 3.0; // parted: the closed lips' points coincide
        }
        let triangles = crate::mesh::delaunay(&face.points).unwrap();
        let (frame, _) = ReferenceFrame::fit_mean(&face.points, triangles, 20_000, 1.0).unwrap();
        let frame = &frame;
        let runs = Runs::new(frame);
        let rgb = RgbImage::from_fn(300, 240, |x, y| {
            let v = ((x * 7 + y * 13 + x * y) % 256) as u8;
            image::Rgb([v, v, v])
        });
        let grey = GreyImage::from_rgb(&rgb);
        for (scale, dx, dy) in [(1.2, 20.0, 15.0), (1.5, -60.0, 100.0), (0.6, 250.0, -10.0)] {
            let points: Vec<Point> = frame
                .landmarks
                .iter()
                .map(|p| [p[0] * scale + dx, p[1] * scale + dy])
                .collect();
            let mut by_runs = vec![0f32; frame.n_pixels()];
            to_reference_grey_into(frame, &runs, &grey, &points, &mut by_runs).unwrap();
            let per_pixel = to_reference(frame, &rgb, &points).unwrap();
            for (i, (g, c)) in by_runs.iter().zip(per_pixel.chunks_exact(3)).enumerate() {
                assert_eq!(g.to_bits(), c[0].to_bits(), "pixel {i} at scale {scale}");
            }
            // The portable code gives the same as what ran (AVX2's where the CPU has it).
            let mut portable = vec![0f32; frame.n_pixels()];
            let maps = inside_maps(frame, &points, grey.width, grey.height);
            grey_runs(&runs.runs, &maps, &grey, &mut portable);
            assert!(portable.iter().zip(&by_runs).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        // Every mask pixel lies in exactly one run, and some runs span more than one block.
        let covered: usize = runs.runs.iter().map(|r| r.1 as usize).sum();
        assert_eq!(covered, frame.n_pixels());
        let longest = runs.runs.iter().map(|r| r.1 as usize).max().unwrap();
        assert!(longest > GreyBlock::LEN, "the longest run has {longest} pixels");
    }

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
