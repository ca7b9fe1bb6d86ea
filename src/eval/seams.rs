//! What a viewer sees at full size in a face drawn over its background: the brightness step
//! across the region's border, and shimmer — frame-to-frame change where nothing moves (the
//! cheeks beside the nose, lips left out). Both are compared with the same pixels of the real
//! video under the face.

use image::RgbImage;
use serde::Serialize;

use crate::facespace::Frames;
use crate::model::FaceModel;
use crate::shape::Point;

/// Pixels either side of the band where the face fades in counted as its border.
pub const BORDER_REACH: usize = 1;

/// The compositing alpha of the face drawn at `points` on a `width × height` canvas (0 where
/// no face is drawn): `alpha` (one value per mask pixel, [`crate::render::feather_alpha`])
/// warped as the renderer warps the texture.
pub fn alpha_on_canvas(
    model: &FaceModel,
    alpha: &[f32],
    points: &[Point],
    width: u32,
    height: u32,
) -> Result<Vec<f32>, crate::warp::WarpError> {
    let white = vec![255f32; 3 * alpha.len()];
    let mut canvas = RgbImage::new(width, height);
    crate::warp::from_reference_blend_into(&model.frame, &white, alpha, points, &mut canvas)?;
    Ok(canvas.pixels().map(|p| f32::from(p.0[0]) / 255.0).collect())
}

/// The border of a feathered face: the pixels where its canvas alpha is strictly between 0
/// and 1 (to within a grey level), grown by [`BORDER_REACH`] — where a seam would show.
pub fn fade_band(alpha: &[f32], width: u32, height: u32) -> Vec<bool> {
    let partial: Vec<bool> = alpha.iter().map(|&a| a > 0.004 && a < 0.996).collect();
    let ring = border_ring(&partial, width, height, BORDER_REACH);
    partial.iter().zip(ring).map(|(&p, r)| p || r).collect()
}

/// Full-size defects of one rendered sequence, each beside the real video's value on the same
/// pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Defects {
    /// Mean |∇| over the border ring of the face drawn, rendered.
    pub border: f64,
    /// The same ring in the real frames.
    pub border_real: f64,
    /// Mean absolute frame-to-frame change on the cheek patches, rendered.
    pub shimmer: f64,
    /// The same in the real frames.
    pub shimmer_real: f64,
}

/// [`Defects`] of `rendered` (the face of `frames` drawn by `model` over `real`, frame by
/// frame, composited by `alpha` per mask pixel): the border is the [`fade_band`] of the face
/// drawn, the cheek patches follow its landmarks.
pub fn measure(
    model: &FaceModel,
    alpha: &[f32],
    frames: &Frames,
    rendered: &[RgbImage],
    real: &[RgbImage],
) -> Result<Defects, crate::render::RenderError> {
    let n = rendered.len().min(real.len()).min(frames.len());
    let mut d = Defects::default();
    let (mut rings, mut pairs) = (0usize, 0usize);
    let mut previous: Option<Vec<bool>> = None;
    for t in 0..n {
        let (w, h) = rendered[t].dimensions();
        let points = model.landmarks(frames.params(t))?.points;
        let ring = fade_band(&alpha_on_canvas(model, alpha, &points, w, h)?, w, h);
        let (b, r) = (
            mean_gradient(&rendered[t], &ring),
            mean_gradient(&real[t], &ring),
        );
        if b.is_finite() && r.is_finite() {
            d.border += b;
            d.border_real += r;
            rings += 1;
        }
        let cheeks = cheek_patches(&points, w, h);
        if let Some(before) = &previous {
            // Pixels in the patches of both frames.
            let both: Vec<bool> = cheeks.iter().zip(before).map(|(a, b)| *a && *b).collect();
            let (s, r) = (
                frame_change(&rendered[t - 1], &rendered[t], &both),
                frame_change(&real[t - 1], &real[t], &both),
            );
            if s.is_finite() && r.is_finite() {
                d.shimmer += s;
                d.shimmer_real += r;
                pairs += 1;
            }
        }
        previous = Some(cheeks);
    }
    let (rings, pairs) = (rings.max(1) as f64, pairs.max(1) as f64);
    d.border /= rings;
    d.border_real /= rings;
    d.shimmer /= pairs;
    d.shimmer_real /= pairs;
    Ok(d)
}

/// Rec. 601 luma of every pixel, row-major.
pub fn grey(image: &RgbImage) -> Vec<f64> {
    image
        .pixels()
        .map(|p| crate::video::luma(p.0.map(f64::from)))
        .collect()
}

/// The pixels within `reach` (Chebyshev distance) of `mask`'s boundary, on either side: where
/// a (2·reach + 1)² window, clipped to the frame, holds both mask and other pixels.
pub fn border_ring(mask: &[bool], width: u32, height: u32, reach: usize) -> Vec<bool> {
    let (w, h) = (width as usize, height as usize);
    // Summed-area table of the mask, one row and column of zeros in front.
    let mut table = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0;
        for x in 0..w {
            row += u32::from(mask[y * w + x]);
            table[(y + 1) * (w + 1) + x + 1] = table[y * (w + 1) + x + 1] + row;
        }
    }
    let mut ring = vec![false; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(reach), (y + reach + 1).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(reach), (x + reach + 1).min(w));
            let inside = table[y1 * (w + 1) + x1] + table[y0 * (w + 1) + x0]
                - table[y0 * (w + 1) + x1]
                - table[y1 * (w + 1) + x0];
            let all = ((y1 - y0) * (x1 - x0)) as u32;
            ring[y * w + x] = inside > 0 && inside < all;
        }
    }
    ring
}

/// Mean gradient magnitude |∇| of the luma over the pixels where `mask` is set: central
/// differences inside the frame, one-sided at its edges (numpy's `gradient`).
pub fn mean_gradient(image: &RgbImage, mask: &[bool]) -> f64 {
    let (w, h) = (image.width() as usize, image.height() as usize);
    let g = grey(image);
    let diff = |a: usize, b: usize, span: usize| (g[b] - g[a]) / span as f64;
    let (mut sum, mut n) = (0.0, 0usize);
    for y in 0..h {
        for x in 0..w {
            if !mask[y * w + x] {
                continue;
            }
            let (xa, xb) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (ya, yb) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let gx = if xb > xa {
                diff(y * w + xa, y * w + xb, xb - xa)
            } else {
                0.0
            };
            let gy = if yb > ya {
                diff(ya * w + x, yb * w + x, yb - ya)
            } else {
                0.0
            };
            sum += gx.hypot(gy);
            n += 1;
        }
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

/// Two cheek patches beside the nose of a 68-point iBUG face: squares centred 40 % of the way
/// from each nostril wing (points 31, 35) to the jaw beside it (points 2, 14), each side a
/// quarter of that distance, cut off above the top of the lips (points 48–59, less 2 px) so
/// that articulation does not count. Empty for another landmark scheme.
pub fn cheek_patches(points: &[Point], width: u32, height: u32) -> Vec<bool> {
    let (w, h) = (width as usize, height as usize);
    let mut mask = vec![false; w * h];
    if points.len() != 68 {
        return mask;
    }
    let lips_top = points[48..60]
        .iter()
        .map(|p| p[1])
        .fold(f64::INFINITY, f64::min)
        - 2.0;
    for (wing, jaw) in [(31, 2), (35, 14)] {
        let (a, b) = (points[wing], points[jaw]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let centre = [a[0] + 0.4 * dx, a[1] + 0.4 * dy];
        let half = 0.125 * dx.hypot(dy);
        let clip = |v: f64, hi: usize| v.clamp(0.0, hi as f64) as usize;
        let (x0, x1) = (clip(centre[0] - half, w), clip(centre[0] + half, w));
        let (y0, y1) = (
            clip(centre[1] - half, h),
            clip((centre[1] + half).min(lips_top), h),
        );
        for y in y0..y1 {
            mask[y * w + x0..y * w + x1].fill(true);
        }
    }
    mask
}

/// Mean absolute luma change between two frames over the pixels where `mask` is set.
pub fn frame_change(a: &RgbImage, b: &RgbImage, mask: &[bool]) -> f64 {
    let (ga, gb) = (grey(a), grey(b));
    let (mut sum, mut n) = (0.0, 0usize);
    for ((x, y), &m) in ga.iter().zip(&gb).zip(mask) {
        if m {
            sum += (x - y).abs();
            n += 1;
        }
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32, f: impl Fn(u32, u32) -> u8) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            let v = f(x, y);
            image::Rgb([v, v, v])
        })
    }

    #[test]
    fn gradient_of_a_plane_is_its_slope() {
        // luma = 2x + y: |∇| = √5 everywhere (one-sided differences are exact on a plane).
        let img = ramp(20, 10, |x, y| (2 * x + y) as u8);
        let mask = vec![true; 200];
        assert!((mean_gradient(&img, &mask) - 5f64.sqrt()).abs() < 1e-9);
        // A step of 100 between columns 9 and 10: central differences give 50 on both.
        let step = ramp(20, 10, |x, _| if x < 10 { 0 } else { 100 });
        let mut cols = vec![false; 200];
        for y in 0..10 {
            cols[y * 20 + 9] = true;
            cols[y * 20 + 10] = true;
        }
        assert!((mean_gradient(&step, &cols) - 50.0).abs() < 1e-9);
    }

    #[test]
    fn ring_is_the_band_about_the_edge() {
        // A 10×10 square at (10..20)²: the ring of reach 2 is the square's outline grown 2 px
        // either side, 14² − 6² pixels.
        let (w, h) = (30u32, 30u32);
        let mask: Vec<bool> = (0..900)
            .map(|i| (10..20).contains(&(i % 30)) && (10..20).contains(&(i / 30)))
            .collect();
        let ring = border_ring(&mask, w, h, 2);
        assert_eq!(ring.iter().filter(|&&r| r).count(), 14 * 14 - 6 * 6);
        assert!(ring[12 * 30 + 8] && ring[11 * 30 + 11] && !ring[15 * 30 + 15] && !ring[0]);
        // Nothing masked, or everything: no border.
        assert!(!border_ring(&vec![false; 900], w, h, 2).contains(&true));
        assert!(!border_ring(&vec![true; 900], w, h, 2).contains(&true));
    }

    #[test]
    fn fade_band_holds_the_partial_alpha_and_its_edge() {
        // Alpha ramps over columns 5..=9 of a 20-wide strip: the band is columns 4..=10.
        let alpha: Vec<f32> = (0..200)
            .map(|i| ((i % 20) as f32 - 4.0).clamp(0.0, 6.0) / 6.0)
            .collect();
        let band = fade_band(&alpha, 20, 10);
        let cols: Vec<usize> = (0..20).filter(|&x| band[3 * 20 + x]).collect();
        assert_eq!(cols, (4..=10).collect::<Vec<_>>());
    }

    #[test]
    fn frame_change_is_the_mean_absolute_difference() {
        let a = ramp(4, 4, |x, _| (10 * x) as u8);
        let b = ramp(4, 4, |x, _| (10 * x + 3) as u8);
        let mask = vec![true; 16];
        assert!((frame_change(&a, &b, &mask) - 3.0).abs() < 1e-9);
        assert!(frame_change(&a, &b, &[false; 16]).is_nan());
    }

    #[test]
    fn cheek_patches_sit_beside_the_nose_above_the_lips() {
        let mut p = vec![[50.0, 50.0]; 68];
        p[31] = [40.0, 60.0];
        p[35] = [60.0, 60.0];
        p[2] = [10.0, 60.0];
        p[14] = [90.0, 60.0];
        for q in &mut p[48..60] {
            *q = [50.0, 80.0];
        }
        let m = cheek_patches(&p, 100, 100);
        // Centres at x = 28 and 72, y = 60; half side 3.75.
        assert!(m[60 * 100 + 28] && m[60 * 100 + 72] && !m[60 * 100 + 50]);
        let count = m.iter().filter(|&&v| v).count();
        assert_eq!(count, 2 * 7 * 7);
        // Lips raised to y = 60: only rows above 58 remain.
        for q in &mut p[48..60] {
            *q = [50.0, 60.0];
        }
        let m = cheek_patches(&p, 100, 100);
        assert!(!m[59 * 100 + 28] && m[57 * 100 + 28]);
        assert!(!cheek_patches(&p[..60], 100, 100).contains(&true));
    }
}
