//! Texture → image: each destination triangle rasterised by exact row spans with incremental
//! source coordinates, dilated one pixel across hull edges.

use image::RgbImage;
use rayon::prelude::*;

use super::{WarpError, all_inside, check_landmarks, sample, sample_inside};
use crate::mesh::{BarycentricMap, ReferenceFrame};
use crate::shape::Point;

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
    let at = |p: &crate::mesh::MaskPixel| p.y as usize * frame.width + p.x as usize;
    if alpha.is_none() {
        // Mask pixels are row-major: copy each run of adjacent pixels as one slice.
        let mut start = 0;
        while start < frame.pixels.len() {
            let dst = at(&frame.pixels[start]);
            let run = frame.pixels[start..]
                .iter()
                .enumerate()
                .take_while(|(k, p)| at(p) == dst + k)
                .count();
            img[dst * 3..(dst + run) * 3].copy_from_slice(&texture[start * 3..(start + run) * 3]);
            start += run;
        }
    } else {
        for (i, p) in frame.pixels.iter().enumerate() {
            put(&mut img, at(p), i);
        }
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
    // Through i32: the value is already in range, and f32 → i32 is one instruction where the
    // saturating f32 → u8 is several.
    (v + 0.5).clamp(0.0, 255.0) as i32 as u8
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

/// A destination triangle: barycentric coordinates and source position are affine in the
/// pixel position, `v(x, y) = v0 + vx·x + vy·y`, so each row is a span walked by constant
/// increments. Shared with the GPU renderer, which draws the same quads.
pub(crate) struct Tri {
    /// `λ_i = l0[i] + lx[i]·x + ly[i]·y`.
    pub l0: [f64; 3],
    pub lx: [f64; 3],
    /// `1 / lx[i]` (0 where `lx[i]` is 0): row spans without divisions.
    pub inv_lx: [f64; 3],
    pub ly: [f64; 3],
    /// Lowest barycentric value still drawn, per vertex: 0 inside, negative across a hull
    /// edge (−dilation / height of the triangle over that edge).
    pub floor: [f64; 3],
    /// The first vertex in the image (an origin near the triangle, for precision in f32 on
    /// the GPU).
    #[cfg_attr(not(feature = "gpu"), allow(dead_code))]
    pub origin: Point,
    /// Source (reference-frame) position: `s = s0 + sx·x + sy·y`.
    pub s0: Point,
    /// The triangle's vertices in the reference frame.
    pub src: [Point; 3],
    pub sx: Point,
    pub sy: Point,
    /// The bounding box grown by the dilation: a sliver's shifted half-plane would otherwise
    /// reach far beyond the triangle.
    pub x_lo: f64,
    pub x_hi: f64,
    pub y0: usize,
    pub y1: usize,
}

/// The drawable triangles of the mesh at `landmarks` on a `w × h` canvas (degenerate and
/// off-canvas ones dropped), in mesh order.
pub(crate) fn triangles(
    frame: &ReferenceFrame,
    landmarks: &[Point],
    w: usize,
    h: usize,
) -> Vec<Tri> {
    frame
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
                origin: a,
                inv_lx: lx.map(|v: f64| if v != 0.0 { 1.0 / v } else { 0.0 }),
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
        .collect()
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
    let tris = triangles(frame, landmarks, w, h);
    const BAND: usize = 16;
    let (fw, fh) = (frame.width, frame.height);
    canvas
        .par_chunks_mut(BAND * w * 3)
        .enumerate()
        .for_each(|(band, rows)| {
            let (r0, r1) = (band * BAND, (band * BAND + BAND).min(h) - 1);
            for t in tris.iter().filter(|t| t.y1 >= r0 && t.y0 <= r1) {
                for y in t.y0.max(r0)..=t.y1.min(r1) {
                    // The row's span: every λ_i(x) = c_i + lx_i·x ≥ floor_i; and within it the
                    // pixels inside the triangle proper (every λ_i ≥ 0), the rest dilated.
                    let span = |floor: [f64; 3]| {
                        let (mut lo, mut hi) = (t.x_lo, t.x_hi);
                        for (i, floor) in floor.iter().enumerate() {
                            let c = t.l0[i] + t.ly[i] * y as f64 - floor;
                            if t.lx[i] > 0.0 {
                                lo = lo.max(-c * t.inv_lx[i]);
                            } else if t.lx[i] < 0.0 {
                                hi = hi.min(-c * t.inv_lx[i]);
                            } else if c < 0.0 {
                                hi = -1.0;
                            }
                        }
                        (lo, hi)
                    };
                    let (lo, hi) = span(t.floor);
                    if hi < lo {
                        continue;
                    }
                    let (x0, x1) = (lo.ceil() as usize, hi as usize);
                    let (in_lo, in_hi) = span([0.0; 3]);
                    // The inside run [i0, i1) within [x0, x1].
                    let (i0, i1) = if in_hi < in_lo {
                        (x0, x0)
                    } else {
                        let i0 = (in_lo.ceil().max(x0 as f64) as usize).min(x1 + 1);
                        let i1 = ((in_hi.floor() + 1.0).max(i0 as f64) as usize).min(x1 + 1);
                        (i0, i1)
                    };
                    let row = &mut rows[(y - r0) * w * 3..(y - r0 + 1) * w * 3];
                    let put = |px: &mut [u8], v: [f32; C]| {
                        if C == 4 {
                            let a = v[3].clamp(0.0, 1.0);
                            for (p, f) in px.iter_mut().zip(v) {
                                *p = to_u8(a * f.clamp(0.0, 255.0) + (1.0 - a) * f32::from(*p));
                            }
                        } else {
                            px.copy_from_slice(&[v[0], v[1], v[2]].map(to_u8));
                        }
                    };
                    // Dilated pixels beyond a hull edge: sample the nearest point of the
                    // triangle rather than extrapolate its map, which a sliver would stretch
                    // far outside the texture.
                    let dilated = |x: usize| {
                        let l: [f64; 3] = std::array::from_fn(|i| {
                            (t.l0[i] + t.lx[i] * x as f64 + t.ly[i] * y as f64).max(0.0)
                        });
                        let sum = l[0] + l[1] + l[2];
                        let at = |k: usize| {
                            (l[0] * t.src[0][k] + l[1] * t.src[1][k] + l[2] * t.src[2][k]) / sum
                        };
                        sample::<f32, C>(source, fw, fh, at(0), at(1), |v: f32| v)
                    };
                    for x in (x0..i0).chain(i1..=x1) {
                        put(&mut row[x * 3..x * 3 + 3], dilated(x));
                    }
                    let mut sx = t.s0[0] + t.sx[0] * i0 as f64 + t.sy[0] * y as f64;
                    let mut sy = t.s0[1] + t.sx[1] * i0 as f64 + t.sy[1] * y as f64;
                    // Inside pixels are convex combinations of the source vertices.
                    let inside = all_inside(&t.src, fw, fh, 1.0);
                    for px in row[i0 * 3..i1 * 3].chunks_exact_mut(3) {
                        put(
                            px,
                            if inside {
                                sample_inside::<f32, C>(source, fw, sx, sy, |v: f32| v)
                            } else {
                                sample::<f32, C>(source, fw, fh, sx, sy, |v: f32| v)
                            },
                        );
                        sx += t.sx[0];
                        sy += t.sx[1];
                    }
                }
            }
        });
}
