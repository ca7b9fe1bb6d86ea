//! Objective measures (DESIGN §9, \[unitsel\] §6–7): of synthesised trajectories against real
//! ones — Pearson r of the first appearance parameter (r_pca) and of the mouth height (r_h),
//! landmark RMSE in pixels, the dynamic-time-warping cost (the systems and baselines they
//! compare are [`crate::synth::systems`], above this module); and of video through
//! face-space, PSNR and SSIM inside the face mask ([`quality`]).

pub mod mouth;
pub mod quality;
pub mod realism;
pub mod seams;

use serde::Serialize;

pub use quality::{face_mask, psnr_masked, ssim_masked};

use crate::facespace::Frames;
use crate::model::FaceModel;
use crate::shape::Point;

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

/// Population standard deviation (0 for fewer than one value).
pub fn standard_deviation(v: &[f64]) -> f64 {
    mean_and_sd(v).1
}

/// Mean and population standard deviation (0 and 0 for an empty slice).
pub fn mean_and_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len().max(1) as f64;
    let m = v.iter().sum::<f64>() / n;
    (m, (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt())
}

/// Mean absolute change from one value to the next (0 for fewer than two values): how much a
/// series moves a frame, where a jump between a live session's batches shows.
pub fn mean_step(v: &[f64]) -> f64 {
    v.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / (v.len().max(2) - 1) as f64
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

/// Edit (Levenshtein) distance between two sequences: insertions, deletions and
/// substitutions cost 1 — the numerator of a phone error rate.
pub fn edit_distance<T: PartialEq>(a: &[T], b: &[T]) -> usize {
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, x) in a.iter().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, y) in b.iter().enumerate() {
            let up = row[j + 1];
            row[j + 1] = (diag + usize::from(x != y)).min(row[j] + 1).min(up + 1);
            diag = up;
        }
    }
    row[b.len()]
}

/// Landmarks of every frame of a face-space sequence.
pub fn landmarks(model: &FaceModel, frames: &Frames) -> Vec<Vec<Point>> {
    frames
        .iter()
        .map(|p| model.shape.instance(&p.pose, p.shape).points)
        .collect()
}

/// The measures of one synthesised sentence against the real one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Scores {
    /// Pearson r of the first appearance parameter.
    pub r_pca: f64,
    /// Pearson r of the mouth height.
    pub r_h: f64,
    /// Landmark RMSE, pixels.
    pub rmse_px: f64,
    /// DTW cost per path step over shape and appearance parameters.
    pub dtw: f64,
    /// Standard deviation of the mouth height over the sentence (articulation amplitude).
    pub mouth_sd_px: f64,
}

/// Scores `synth` against `real` (same layout and frame rate; the shorter length is
/// compared). DTW runs over the shape and appearance parameters.
pub fn score(model: &FaceModel, synth: &Frames, real: &Frames) -> Scores {
    let n = synth.len().min(real.len());
    let (s, r) = (synth.slice(0..n), real.slice(0..n));
    let layout = s.layout();
    let first = layout.appearance_range().start;
    let col = |m: &Frames, k: usize| {
        m.column(k)
            .iter()
            .map(|&v| f64::from(v))
            .collect::<Vec<_>>()
    };
    let (ls, lr) = (landmarks(model, &s), landmarks(model, &r));
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
    let params = |m: &Frames| {
        m.values()
            .rows()
            .into_iter()
            .flat_map(|row| {
                row.iter()
                    .skip(layout.params_range().start)
                    .map(|&v| f64::from(v))
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
    };
    Scores {
        r_pca: if layout.appearance > 0 {
            pearson(&col(&s, first), &col(&r, first))
        } else {
            0.0
        },
        r_h: pearson(&hs, &hr),
        rmse_px: (sq / count as f64).sqrt(),
        dtw: dtw(&params(&s), &params(&r), layout.params_range().len()),
        mouth_sd_px: standard_deviation(&hs),
    }
}

/// The mean of each measure over several sentences.
pub fn mean_scores(scores: &[Scores]) -> Scores {
    let n = scores.len().max(1) as f64;
    let avg = |f: fn(&Scores) -> f64| scores.iter().map(f).sum::<f64>() / n;
    Scores {
        r_pca: avg(|s| s.r_pca),
        r_h: avg(|s| s.r_h),
        rmse_px: avg(|s| s.rmse_px),
        dtw: avg(|s| s.dtw),
        mouth_sd_px: avg(|s| s.mouth_sd_px),
    }
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

    /// By hand: 1 → 3 → 2 → 2 moves 2, 1 and 0: a mean step of 1.
    #[test]
    fn mean_step_known_values() {
        assert_eq!(mean_step(&[1.0, 3.0, 2.0, 2.0]), 1.0);
        assert_eq!(mean_step(&[5.0]), 0.0);
        assert_eq!(mean_step(&[]), 0.0);
    }

    /// Levenshtein's textbook cases: kitten → sitting 3, flaw → lawn 2, to or from nothing
    /// the other's length, a copy 0.
    #[test]
    fn edit_distance_known_values() {
        let d = |a: &str, b: &str| {
            edit_distance(&a.chars().collect::<Vec<_>>(), &b.chars().collect::<Vec<_>>())
        };
        assert_eq!(d("kitten", "sitting"), 3);
        assert_eq!(d("flaw", "lawn"), 2);
        assert_eq!(d("", "abc"), 3);
        assert_eq!(d("abc", ""), 3);
        assert_eq!(d("same", "same"), 0);
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
