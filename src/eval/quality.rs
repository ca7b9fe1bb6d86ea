//! Quality of video through face-space: PSNR and SSIM inside the face mask.

use image::RgbImage;

use crate::model::FaceModel;
use crate::shape::Point;

/// PSNR (dB, peak 255) over the RGB values of the pixels where `mask` is set (DESIGN §9:
/// video through face-space). Identical pixels give +∞.
pub fn psnr_masked(a: &RgbImage, b: &RgbImage, mask: &[bool]) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((pa, pb), &m) in a.pixels().zip(b.pixels()).zip(mask) {
        if m {
            for c in 0..3 {
                let d = f64::from(pa.0[c]) - f64::from(pb.0[c]);
                sum += d * d;
            }
            n += 3;
        }
    }
    if n == 0 {
        return f64::NAN;
    }
    10.0 * (255.0f64 * 255.0 / (sum / n as f64)).log10()
}

/// Mean SSIM over the pixels where `mask` is set: Wang et al. 2004 with scikit-image's
/// defaults (7×7 uniform window, sample covariance, K1 = 0.01, K2 = 0.03, data range 255,
/// reflected borders), computed per RGB channel and averaged like `channel_axis=-1`.
pub fn ssim_masked(a: &RgbImage, b: &RgbImage, mask: &[bool]) -> f64 {
    let (w, h) = (a.width() as usize, a.height() as usize);
    const WIN: usize = 7;
    let np = (WIN * WIN) as f64;
    let cov_norm = np / (np - 1.0);
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let count = mask.iter().filter(|&&m| m).count();
    if count == 0 {
        return f64::NAN;
    }
    // Only the mask's bounding box, grown by the window's reach, is filtered: inside it
    // every mask pixel's window is the same as in the whole frame (and where the box meets
    // the frame's edge, so do the reflections).
    let r = WIN / 2;
    let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
    for i in (0..w * h).filter(|&i| mask[i]) {
        let (x, y) = (i % w, i / w);
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    let (x0, y0) = (x0.saturating_sub(r), y0.saturating_sub(r));
    let (x1, y1) = ((x1 + r).min(w - 1), (y1 + r).min(h - 1));
    let (cw, ch) = (x1 - x0 + 1, y1 - y0 + 1);
    let (w, mask) = (cw, {
        let mut m = Vec::with_capacity(cw * ch);
        for y in y0..=y1 {
            m.extend_from_slice(&mask[y * w + x0..=y * w + x1]);
        }
        m
    });
    let h = ch;
    let crop = |img: &RgbImage, c: usize| -> Vec<f64> {
        let mut v = Vec::with_capacity(cw * ch);
        for y in y0..=y1 {
            for x in x0..=x1 {
                v.push(f64::from(img.get_pixel(x as u32, y as u32).0[c]));
            }
        }
        v
    };
    let mut total = 0.0;
    for c in 0..3 {
        let x: Vec<f64> = crop(a, c);
        let y: Vec<f64> = crop(b, c);
        let prod =
            |p: &[f64], q: &[f64]| -> Vec<f64> { p.iter().zip(q).map(|(u, v)| u * v).collect() };
        let (ux, uy) = (uniform_filter(&x, w, h, WIN), uniform_filter(&y, w, h, WIN));
        let uxx = uniform_filter(&prod(&x, &x), w, h, WIN);
        let uyy = uniform_filter(&prod(&y, &y), w, h, WIN);
        let uxy = uniform_filter(&prod(&x, &y), w, h, WIN);
        let mut sum = 0.0;
        for i in (0..w * h).filter(|&i| mask[i]) {
            let vx = cov_norm * (uxx[i] - ux[i] * ux[i]);
            let vy = cov_norm * (uyy[i] - uy[i] * uy[i]);
            let vxy = cov_norm * (uxy[i] - ux[i] * uy[i]);
            let (a1, a2) = (2.0 * ux[i] * uy[i] + c1, 2.0 * vxy + c2);
            let (b1, b2) = (ux[i] * ux[i] + uy[i] * uy[i] + c1, vx + vy + c2);
            sum += a1 * a2 / (b1 * b2);
        }
        total += sum / count as f64;
    }
    total / 3.0
}

/// Separable `size`-wide mean filter with scipy.ndimage's default `reflect` borders
/// (d c b a | a b c d | d c b a).
fn uniform_filter(data: &[f64], w: usize, h: usize, size: usize) -> Vec<f64> {
    let r = (size / 2) as isize;
    let reflect = |i: isize, n: usize| -> usize {
        let n = n as isize;
        let mut i = i;
        loop {
            if i < 0 {
                i = -i - 1;
            } else if i >= n {
                i = 2 * n - i - 1;
            } else {
                return i as usize;
            }
        }
    };
    let mut rows = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            rows[y * w + x] = (-r..=r)
                .map(|d| data[y * w + reflect(x as isize + d, w)])
                .sum::<f64>()
                / size as f64;
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] = (-r..=r)
                .map(|d| rows[reflect(y as isize + d, h) * w + x])
                .sum::<f64>()
                / size as f64;
        }
    }
    out
}

/// Pixels covered by the mesh at `landmarks` on a `width × height` frame (the face mask).
pub fn face_mask(model: &FaceModel, landmarks: &[Point], width: u32, height: u32) -> Vec<bool> {
    let (owner, _) = crate::mesh::cover(
        landmarks,
        &model.frame.triangles,
        width as usize,
        height as usize,
    );
    owner.into_iter().map(|o| o != u32::MAX).collect()
}
