//! Objective measures of synthesised trajectories against real ones (DESIGN §9,
//! [unitsel] §6–7): Pearson r of the first appearance parameter (r_pca) and of the mouth
//! height (r_h), landmark RMSE in pixels, and the dynamic-time-warping cost; and of video
//! through face-space: PSNR and SSIM inside the face mask.

use image::RgbImage;
use serde::Serialize;

use crate::codebook::Layout;
use crate::model::FaceModel;
use crate::shape::{Point, Similarity};

/// Pearson correlation of two equally long series (0 when either is constant).
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n < 2 {
        return 0.0;
    }
    let (ma, mb) = (
        a[..n].iter().sum::<f64>() / n as f64,
        b[..n].iter().sum::<f64>() / n as f64,
    );
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (x, y) = (a[i] - ma, b[i] - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    if saa == 0.0 || sbb == 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// Dynamic time warping between two `frames × dims` series with Euclidean frame distance;
/// the total cost of the best path divided by its length.
pub fn dtw(a: &[f64], b: &[f64], dims: usize) -> f64 {
    let (n, m) = (a.len() / dims, b.len() / dims);
    if n == 0 || m == 0 {
        return f64::INFINITY;
    }
    let d = |i: usize, j: usize| -> f64 {
        a[i * dims..(i + 1) * dims]
            .iter()
            .zip(&b[j * dims..(j + 1) * dims])
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    // (cost, path length) per cell, one row at a time.
    let mut prev = vec![(f64::INFINITY, 0usize); m];
    let mut cur = vec![(0.0, 0usize); m];
    for i in 0..n {
        for j in 0..m {
            let best = if i == 0 && j == 0 {
                (0.0, 0)
            } else {
                let mut c = (f64::INFINITY, 0);
                for cand in [
                    (i > 0).then(|| prev[j]),
                    (j > 0).then(|| cur[j - 1]),
                    (i > 0 && j > 0).then(|| prev[j - 1]),
                ]
                .into_iter()
                .flatten()
                {
                    if cand.0 < c.0 {
                        c = cand;
                    }
                }
                c
            };
            cur[j] = (best.0 + d(i, j), best.1 + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[m - 1].0 / prev[m - 1].1 as f64
}

/// Mouth height: the largest vertical extent of the outer lip contour (iBUG points 48–59).
pub fn mouth_height(points: &[Point]) -> f64 {
    let lips = &points[48..60];
    let (lo, hi) = lips
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[1]), hi.max(p[1]))
        });
    hi - lo
}

/// Landmarks of every frame of a `frames × dims` face-space series.
pub fn landmarks(model: &FaceModel, frames: &[f64], layout: &Layout) -> Vec<Vec<Point>> {
    frames
        .chunks_exact(layout.dims())
        .map(|row| {
            let pose = Similarity::from_array([row[0], row[1], row[2], row[3]]);
            let b: Vec<f32> = row[layout.pose..layout.pose + layout.shape]
                .iter()
                .map(|&v| v as f32)
                .collect();
            model.shape.instance(&pose, &b).points
        })
        .collect()
}

/// The measures of one synthesised sentence against the real one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Scores {
    pub r_pca: f64,
    pub r_h: f64,
    pub rmse_px: f64,
    pub dtw: f64,
    /// Standard deviation of the mouth height over the sentence (articulation amplitude).
    pub mouth_sd_px: f64,
}

/// Scores `synth` against `real` (both `frames × dims`, same frame rate; the shorter length
/// is compared). DTW runs over the shape and appearance parameters.
pub fn score(model: &FaceModel, layout: &Layout, synth: &[f64], real: &[f64]) -> Scores {
    let dims = layout.dims();
    let n = (synth.len() / dims).min(real.len() / dims);
    let (s, r) = (&synth[..n * dims], &real[..n * dims]);
    let first = layout.pose + layout.shape;
    let col = |m: &[f64], k: usize| m.chunks_exact(dims).map(|row| row[k]).collect::<Vec<_>>();
    let (ls, lr) = (landmarks(model, s, layout), landmarks(model, r, layout));
    let (hs, hr): (Vec<f64>, Vec<f64>) = (
        ls.iter().map(|p| mouth_height(p)).collect(),
        lr.iter().map(|p| mouth_height(p)).collect(),
    );
    let sq: f64 = ls
        .iter()
        .zip(&lr)
        .flat_map(|(a, b)| {
            a.iter()
                .zip(b)
                .map(|(p, q)| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2))
        })
        .sum();
    let count = (n * ls.first().map_or(1, |p| p.len())).max(1);
    let params = |m: &[f64]| {
        m.chunks_exact(dims)
            .flat_map(|row| row[layout.params()].to_vec())
            .collect::<Vec<_>>()
    };
    let mean = hs.iter().sum::<f64>() / n.max(1) as f64;
    Scores {
        r_pca: if layout.appearance > 0 {
            pearson(&col(s, first), &col(r, first))
        } else {
            0.0
        },
        r_h: pearson(&hs, &hr),
        rmse_px: (sq / count as f64).sqrt(),
        dtw: dtw(&params(s), &params(r), layout.params().len()),
        mouth_sd_px: (hs.iter().map(|h| (h - mean).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt(),
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pearson_known_values() {
        assert!((pearson(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]) - 1.0).abs() < 1e-12);
        assert!((pearson(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]) + 1.0).abs() < 1e-12);
        // Hand-computed: x = (1,2,3,4), y = (1,3,2,4): r = 0.8.
        assert!((pearson(&[1.0, 2.0, 3.0, 4.0], &[1.0, 3.0, 2.0, 4.0]) - 0.8).abs() < 1e-12);
        assert_eq!(pearson(&[1.0, 1.0], &[1.0, 2.0]), 0.0);
    }

    #[test]
    fn dtw_aligns_a_stretched_copy_at_zero_cost() {
        let a = [0.0, 1.0, 2.0, 3.0];
        let b = [0.0, 0.0, 1.0, 1.0, 2.0, 3.0, 3.0];
        assert_eq!(dtw(&a, &b, 1), 0.0);
        // Shifted by one: the best path pairs a[i+1] with c[i], paying 1 only at both ends:
        // (0,0) 1, (1,0) 0, (2,1) 0, (3,2) 0, (3,3) 1 → 2 over 5 steps.
        let c: Vec<f64> = a.iter().map(|v| v + 1.0).collect();
        assert!((dtw(&a, &c, 1) - 0.4).abs() < 1e-12, "{}", dtw(&a, &c, 1));
    }
}
