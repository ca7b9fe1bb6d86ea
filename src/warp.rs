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

use crate::mesh::{BarycentricMap, ReferenceFrame};
use crate::shape::Point;

#[derive(Debug, Error)]
pub enum WarpError {
    #[error("{found} landmarks given, the mesh has {expected}")]
    LandmarkCount { expected: usize, found: usize },
    #[error("landmark {index} is not finite")]
    NotFinite { index: usize },
    #[error("texture has {found} values, the reference frame needs {expected} (pixels × 3)")]
    TextureLength { expected: usize, found: usize },
    #[error("image is empty ({width}×{height})")]
    EmptyImage { width: u32, height: u32 },
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
    let (x0, y0) = (xc as usize, yc as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = ((xc - x0 as f64) as f32, (yc - y0 as f64) as f32);
    let (i00, i01, i10, i11) = (
        (y0 * w + x0) * C,
        (y0 * w + x1) * C,
        (y1 * w + x0) * C,
        (y1 * w + x1) * C,
    );
    let mut out = [0f32; C];
    for (c, o) in out.iter_mut().enumerate() {
        let top = to_f32(data[i00 + c]) * (1.0 - fx) + to_f32(data[i01 + c]) * fx;
        let bottom = to_f32(data[i10 + c]) * (1.0 - fx) + to_f32(data[i11 + c]) * fx;
        *o = top * (1.0 - fy) + bottom * fy;
    }
    out
}

/// A single-channel f32 image (grey levels), for fitting on luminance.
#[derive(Clone, Debug, PartialEq)]
pub struct GreyImage {
    pub width: usize,
    pub height: usize,
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
    out.par_chunks_mut(CHUNK * C)
        .zip(frame.pixels.par_chunks(CHUNK))
        .for_each(|(out, pixels)| {
            for (o, p) in out.chunks_exact_mut(C).zip(pixels) {
                let [a, b, c] = frame.triangles[p.triangle as usize].map(|v| landmarks[v as usize]);
                let l = p.bary.map(|v| v as f64);
                let x = l[0] * a[0] + l[1] * b[0] + l[2] * c[0];
                let y = l[0] * a[1] + l[1] * b[1] + l[2] * c[1];
                o.copy_from_slice(&sample::<T, C>(data, w, h, x, y, &to_f32));
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

fn check_landmarks(frame: &ReferenceFrame, landmarks: &[Point]) -> Result<(), WarpError> {
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

/// A full `width × height × 3` reference image from a texture: mask pixels plus the padding
/// rings, so bilinear samples at the mesh edge read defined values.
pub fn texture_to_image(frame: &ReferenceFrame, texture: &[f32]) -> Result<Vec<f32>, WarpError> {
    texture_to_image_with(frame, texture, None)
}

/// [`texture_to_image`] with an optional fourth channel (alpha, one value per mask pixel).
fn texture_to_image_with(
    frame: &ReferenceFrame,
    texture: &[f32],
    alpha: Option<&[f32]>,
) -> Result<Vec<f32>, WarpError> {
    if texture.len() != frame.n_pixels() * 3 {
        return Err(WarpError::TextureLength {
            expected: frame.n_pixels() * 3,
            found: texture.len(),
        });
    }
    if let Some(a) = alpha
        && a.len() != frame.n_pixels()
    {
        return Err(WarpError::TextureLength {
            expected: frame.n_pixels(),
            found: a.len(),
        });
    }
    let c = if alpha.is_some() { 4 } else { 3 };
    let put = |img: &mut [f32], dst: usize, src: usize| {
        img[dst * c..dst * c + 3].copy_from_slice(&texture[src * 3..src * 3 + 3]);
        if let Some(a) = alpha {
            img[dst * c + 3] = a[src];
        }
    };
    let mut img = vec![0f32; frame.width * frame.height * c];
    for (i, p) in frame.pixels.iter().enumerate() {
        put(&mut img, p.y as usize * frame.width + p.x as usize, i);
    }
    for &(dst, src) in &frame.padding {
        put(&mut img, dst as usize, src as usize);
    }
    Ok(img)
}

/// The texture as an 8-bit image of the reference frame (outside the mask: black).
pub fn texture_to_rgb(frame: &ReferenceFrame, texture: &[f32]) -> Result<RgbImage, WarpError> {
    if texture.len() != frame.n_pixels() * 3 {
        return Err(WarpError::TextureLength {
            expected: frame.n_pixels() * 3,
            found: texture.len(),
        });
    }
    let mut img = RgbImage::new(frame.width as u32, frame.height as u32);
    for (p, t) in frame.pixels.iter().zip(texture.chunks_exact(3)) {
        img.put_pixel(
            p.x,
            p.y,
            image::Rgb([to_u8(t[0]), to_u8(t[1]), to_u8(t[2])]),
        );
    }
    Ok(img)
}

/// Rounds a grey level to the nearest 8-bit value.
#[inline]
pub fn to_u8(v: f32) -> u8 {
    (v + 0.5).clamp(0.0, 255.0) as u8
}

/// How far (pixels) rendering extends the face beyond the mesh boundary, extrapolating the
/// edge triangles' maps over the padded texture: a later warp back samples bilinearly at the
/// boundary and must find face there, not background.
pub const RENDER_DILATION: f64 = 1.0;

/// Draws a texture onto `canvas` with the mesh at `landmarks`. Pixels outside the mesh (and
/// its one-pixel dilation) are left as they were, so the face can be drawn over a background.
pub fn from_reference_into(
    frame: &ReferenceFrame,
    texture: &[f32],
    landmarks: &[Point],
    canvas: &mut RgbImage,
) -> Result<(), WarpError> {
    check_landmarks(frame, landmarks)?;
    let source = texture_to_image(frame, texture)?;
    draw::<3>(frame, &source, landmarks, canvas);
    Ok(())
}

/// [`from_reference_into`] blended by `alpha` (one value in [0, 1] per mask pixel, warped
/// with the texture): `out = α·face + (1 − α)·canvas`, for a feathered edge over a background.
pub fn from_reference_blend_into(
    frame: &ReferenceFrame,
    texture: &[f32],
    alpha: &[f32],
    landmarks: &[Point],
    canvas: &mut RgbImage,
) -> Result<(), WarpError> {
    check_landmarks(frame, landmarks)?;
    let source = texture_to_image_with(frame, texture, Some(alpha))?;
    draw::<4>(frame, &source, landmarks, canvas);
    Ok(())
}

/// The span-walking rasteriser behind both: `C` = 3 copies RGB, `C` = 4 blends by alpha.
fn draw<const C: usize>(
    frame: &ReferenceFrame,
    source: &[f32],
    landmarks: &[Point],
    canvas: &mut RgbImage,
) {
    let (w, h) = (canvas.width() as usize, canvas.height() as usize);
    if w == 0 || h == 0 {
        return;
    }
    /// A destination triangle: barycentric coordinates and source position are affine in
    /// the pixel position, `v(x, y) = v0 + vx·x + vy·y`, so each row is a span walked by
    /// constant increments.
    struct Tri {
        /// `λ_i = l0[i] + lx[i]·x + ly[i]·y`.
        l0: [f64; 3],
        lx: [f64; 3],
        ly: [f64; 3],
        /// Lowest barycentric value still drawn, per vertex: 0 inside, negative across a
        /// hull edge (−dilation / height of the triangle over that edge).
        floor: [f64; 3],
        /// Source (reference-frame) position: `s = s0 + sx·x + sy·y`.
        s0: Point,
        /// The triangle's vertices in the reference frame.
        src: [Point; 3],
        sx: Point,
        sy: Point,
        /// The bounding box grown by the dilation: a sliver's shifted half-plane would
        /// otherwise reach far beyond the triangle.
        x_lo: f64,
        x_hi: f64,
        y0: usize,
        y1: usize,
    }
    let tris: Vec<Tri> = frame
        .triangles
        .iter()
        .zip(&frame.hull_edges)
        .filter_map(|(t, hull)| {
            let verts = t.map(|v| landmarks[v as usize]);
            let [a, b, c] = verts;
            let to_bary = BarycentricMap::new(a, b, c)?;
            let twice_area = crate::mesh::signed_area(a, b, c).abs();
            let floor = std::array::from_fn(|i| {
                let (p, q) = (verts[(i + 1) % 3], verts[(i + 2) % 3]);
                if hull[i] {
                    -RENDER_DILATION * (p[0] - q[0]).hypot(p[1] - q[1]) / twice_area
                } else {
                    -1e-9
                }
            });
            let d = RENDER_DILATION;
            let (lo_y, hi_y) = (a[1].min(b[1]).min(c[1]) - d, a[1].max(b[1]).max(c[1]) + d);
            let (lo_x, hi_x) = (a[0].min(b[0]).min(c[0]) - d, a[0].max(b[0]).max(c[0]) + d);
            if hi_x < 0.0 || hi_y < 0.0 || lo_x > (w - 1) as f64 || lo_y > (h - 1) as f64 {
                return None;
            }
            let (l00, l10, l01) = (
                to_bary.at([0.0, 0.0]),
                to_bary.at([1.0, 0.0]),
                to_bary.at([0.0, 1.0]),
            );
            let lx = std::array::from_fn(|i| l10[i] - l00[i]);
            let ly = std::array::from_fn(|i| l01[i] - l00[i]);
            let src = t.map(|v| frame.landmarks[v as usize]);
            let at = |l: [f64; 3], k: usize| l[0] * src[0][k] + l[1] * src[1][k] + l[2] * src[2][k];
            let s0 = [at(l00, 0), at(l00, 1)];
            Some(Tri {
                l0: l00,
                lx,
                ly,
                floor,
                s0,
                src,
                sx: [at(l10, 0) - s0[0], at(l10, 1) - s0[1]],
                sy: [at(l01, 0) - s0[0], at(l01, 1) - s0[1]],
                x_lo: lo_x.max(0.0),
                x_hi: hi_x.min((w - 1) as f64),
                y0: lo_y.ceil().max(0.0) as usize,
                y1: (hi_y.floor() as usize).min(h - 1),
            })
        })
        .collect();
    const BAND: usize = 16;
    let (fw, fh) = (frame.width, frame.height);
    canvas
        .par_chunks_mut(BAND * w * 3)
        .enumerate()
        .for_each(|(band, rows)| {
            let (r0, r1) = (band * BAND, (band * BAND + BAND).min(h) - 1);
            for t in tris.iter().filter(|t| t.y1 >= r0 && t.y0 <= r1) {
                for y in t.y0.max(r0)..=t.y1.min(r1) {
                    // The row's span: every λ_i(x) = c_i + lx_i·x ≥ floor_i.
                    let (mut lo, mut hi) = (t.x_lo, t.x_hi);
                    for i in 0..3 {
                        let c = t.l0[i] + t.ly[i] * y as f64 - t.floor[i];
                        if t.lx[i] > 0.0 {
                            lo = lo.max(-c / t.lx[i]);
                        } else if t.lx[i] < 0.0 {
                            hi = hi.min(-c / t.lx[i]);
                        } else if c < 0.0 {
                            hi = -1.0;
                        }
                    }
                    if hi < lo {
                        continue;
                    }
                    let (x0, x1) = (lo.ceil() as usize, hi as usize);
                    let row = &mut rows[(y - r0) * w * 3..(y - r0 + 1) * w * 3];
                    let mut sx = t.s0[0] + t.sx[0] * x0 as f64 + t.sy[0] * y as f64;
                    let mut sy = t.s0[1] + t.sx[1] * x0 as f64 + t.sy[1] * y as f64;
                    let mut l: [f64; 3] =
                        std::array::from_fn(|i| t.l0[i] + t.lx[i] * x0 as f64 + t.ly[i] * y as f64);
                    for px in row[x0 * 3..(x1 + 1) * 3].chunks_exact_mut(3) {
                        let v = if l.iter().all(|&v| v >= 0.0) {
                            sample::<f32, C>(source, fw, fh, sx, sy, |v: f32| v)
                        } else {
                            // Dilated pixel beyond a hull edge: sample the nearest point of the
                            // triangle rather than extrapolate its map, which a sliver would
                            // stretch far outside the texture.
                            let c = l.map(|v| v.max(0.0));
                            let sum = c[0] + c[1] + c[2];
                            let at = |k: usize| {
                                (c[0] * t.src[0][k] + c[1] * t.src[1][k] + c[2] * t.src[2][k]) / sum
                            };
                            sample::<f32, C>(source, fw, fh, at(0), at(1), |v: f32| v)
                        };
                        if C == 4 {
                            let a = v[3].clamp(0.0, 1.0);
                            for (p, f) in px.iter_mut().zip(v) {
                                *p = to_u8(a * f + (1.0 - a) * f32::from(*p));
                            }
                        } else {
                            px.copy_from_slice(&[v[0], v[1], v[2]].map(to_u8));
                        }
                        sx += t.sx[0];
                        sy += t.sx[1];
                        l.iter_mut().zip(&t.lx).for_each(|(v, d)| *v += d);
                    }
                }
            }
        });
}
