//! Mouth measures of \[unitsel\] §7 on recorded talkers: eq. 16's r_pca — the correlation of
//! the first principal component of the mouth region's appearance, photometrically
//! normalised — the inner-mouth height, and flicker (within-sentence spread of each
//! appearance parameter against the real sentence's).

use crate::facespace::Frames;
use crate::model::FaceModel;
use crate::shape::{Point, Similarity};

/// iBUG-68 lip landmarks (outer 48–59, inner 60–67): triangles with all three corners among
/// them make the mouth region.
const LIPS: std::ops::RangeInclusive<u32> = 48..=67;

/// The mouth region of a model's appearance: its grey texture as a linear function of `b_a`.
pub struct MouthAppearance {
    /// Grey mean per mouth pixel.
    mean: Vec<f64>,
    /// Per component, the grey value per mouth pixel.
    components: Vec<Vec<f64>>,
}

impl MouthAppearance {
    /// The mouth pixels of `model`'s reference frame (`None` when its mesh has no triangle
    /// inside the lips, e.g. a model without the 68 iBUG points).
    pub fn new(model: &FaceModel) -> Option<Self> {
        let frame = &model.frame;
        let pca = &model.appearance.pca;
        if pca.dim() != 3 * frame.pixels.len() {
            return None;
        }
        let mouth: Vec<usize> = frame
            .pixels
            .iter()
            .enumerate()
            .filter(|(_, p)| {
                frame
                    .triangles
                    .get(p.triangle as usize)
                    .is_some_and(|t| t.iter().all(|v| LIPS.contains(v)))
            })
            .map(|(i, _)| i)
            .collect();
        if mouth.len() < 10 {
            return None;
        }
        let grey = |values: &[f32]| -> Vec<f64> {
            mouth
                .iter()
                .map(|&i| {
                    values[3 * i..3 * i + 3]
                        .iter()
                        .map(|&v| v as f64)
                        .sum::<f64>()
                        / 3.0
                })
                .collect()
        };
        let dim = pca.dim();
        Some(MouthAppearance {
            mean: grey(&pca.mean),
            components: (0..pca.n_components())
                .map(|c| grey(&pca.components[c * dim..(c + 1) * dim]))
                .collect(),
        })
    }

    /// The frame's mouth texture `ā + P b_a` in grey, photometrically normalised: zero mean
    /// and unit s.d. over the region (the gain and offset of lighting removed).
    pub fn normalised(&self, b_a: &[f32]) -> Vec<f64> {
        let mut t = self.mean.clone();
        for (c, &b) in self.components.iter().zip(b_a) {
            let b = b as f64;
            t.iter_mut().zip(c).for_each(|(v, &p)| *v += b * p);
        }
        let n = t.len() as f64;
        let mean = t.iter().sum::<f64>() / n;
        let sd = (t.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n)
            .sqrt()
            .max(1e-9);
        t.iter_mut().for_each(|v| *v = (*v - mean) / sd);
        t
    }
}

/// The first principal component of normalised mouth textures.
pub struct MouthPc {
    mouth: MouthAppearance,
    centre: Vec<f64>,
    axis: Vec<f64>,
}

impl MouthPc {
    /// Fitted on the mouth textures of every frame of `sentences` (the real test sentences:
    /// eq. 16's PCA of the mouth images), by power iteration on their covariance.
    pub fn fit(model: &FaceModel, sentences: &[&Frames]) -> Option<Self> {
        let mouth = MouthAppearance::new(model)?;
        let textures: Vec<Vec<f64>> = sentences
            .iter()
            .flat_map(|f| {
                f.iter()
                    .map(|p| mouth.normalised(p.appearance))
                    .collect::<Vec<_>>()
            })
            .collect();
        if textures.len() < 2 {
            return None;
        }
        let d = textures[0].len();
        let mut centre = vec![0f64; d];
        for t in &textures {
            centre.iter_mut().zip(t).for_each(|(c, v)| *c += v);
        }
        centre.iter_mut().for_each(|c| *c /= textures.len() as f64);
        // Power iteration from a fixed start (the first frame's deviation, plus a constant so
        // that it is never orthogonal to everything).
        let mut axis: Vec<f64> = textures[0]
            .iter()
            .zip(&centre)
            .map(|(v, c)| v - c + 1e-3)
            .collect();
        for _ in 0..100 {
            let mut next = vec![0f64; d];
            for t in &textures {
                let proj: f64 = t
                    .iter()
                    .zip(&centre)
                    .zip(&axis)
                    .map(|((v, c), a)| (v - c) * a)
                    .sum();
                next.iter_mut()
                    .zip(t)
                    .zip(&centre)
                    .for_each(|((n, v), c)| *n += proj * (v - c));
            }
            let norm = next.iter().map(|v| v * v).sum::<f64>().sqrt();
            if norm == 0.0 {
                return None;
            }
            next.iter_mut().for_each(|v| *v /= norm);
            axis = next;
        }
        Some(MouthPc {
            mouth,
            centre,
            axis,
        })
    }

    /// Each frame's coordinate on the component.
    pub fn series(&self, frames: &Frames) -> Vec<f64> {
        frames
            .iter()
            .map(|p| {
                let t = self.mouth.normalised(p.appearance);
                t.iter()
                    .zip(&self.centre)
                    .zip(&self.axis)
                    .map(|((v, c), a)| (v - c) * a)
                    .sum()
            })
            .collect()
    }

    /// The unit axis (for tests).
    pub fn axis(&self) -> &[f64] {
        &self.axis
    }
}

/// Inner-mouth height: the mean vertical gap between the inner lips (iBUG 61–63 over 67–65).
pub fn inner_mouth_height(points: &[Point]) -> f64 {
    [(61, 67), (62, 66), (63, 65)]
        .iter()
        .map(|&(top, bottom)| points[bottom][1] - points[top][1])
        .sum::<f64>()
        / 3.0
}

/// Lip motion: the mean frame-to-frame displacement of the lip landmarks (iBUG 48–67) of the
/// shape alone, without the pose — how fast the mouth moves, which smoothing and averaging
/// take first and correlation does not see. Zero for fewer than two frames.
pub fn lip_motion(model: &FaceModel, frames: &Frames) -> f64 {
    let lips: Vec<Vec<Point>> = frames
        .iter()
        .map(|p| {
            let points = model.shape.instance(&Similarity::IDENTITY, p.shape).points;
            points[*LIPS.start() as usize..=*LIPS.end() as usize].to_vec()
        })
        .collect();
    let steps: Vec<f64> = lips
        .windows(2)
        .map(|w| {
            let d: f64 = w[0].iter().zip(&w[1]).map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1])).sum();
            d / w[0].len() as f64
        })
        .collect();
    steps.iter().sum::<f64>() / steps.len().max(1) as f64
}

/// Mouth sharpness: the mean grey (BT.601 luma) gradient magnitude, by central differences,
/// inside the lips' bounding box (iBUG 48–67, a 3-pixel margin) of each image, averaged over
/// the images — a soft mouth (a blurred appearance model, a reference frame too small for
/// the face) scores below the recorded one. Images under 3×3 pixels score 0.
pub fn mouth_sharpness(images: &[image::RgbImage], landmarks: &[Vec<Point>]) -> f64 {
    let grey = |im: &image::RgbImage, x: u32, y: u32| {
        crate::video::luma(im.get_pixel(x, y).0.map(f64::from))
    };
    let mut total = 0.0;
    for (im, l) in images.iter().zip(landmarks) {
        if im.width() < 3 || im.height() < 3 {
            continue;
        }
        let lips = &l[*LIPS.start() as usize..=*LIPS.end() as usize];
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in lips {
            (x0, x1, y0, y1) = (x0.min(p[0]), x1.max(p[0]), y0.min(p[1]), y1.max(p[1]));
        }
        let clamp = |v: f64, hi: u32| (v.max(1.0) as u32).min(hi);
        let (x0, x1) = (clamp(x0 - 3.0, im.width() - 2), clamp(x1 + 3.0, im.width() - 2));
        let (y0, y1) = (clamp(y0 - 3.0, im.height() - 2), clamp(y1 + 3.0, im.height() - 2));
        total += mean_gradient(|x, y| grey(im, x, y), x0..=x1, y0..=y1);
    }
    total / images.len().max(1) as f64
}

/// The mean gradient magnitude (central differences) of `grey` over the pixels `xs × ys`,
/// each of which has its four neighbours in the image.
pub(crate) fn mean_gradient(
    grey: impl Fn(u32, u32) -> f64,
    xs: std::ops::RangeInclusive<u32>,
    ys: std::ops::RangeInclusive<u32>,
) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0.0f64);
    for y in ys {
        for x in xs.clone() {
            let gx = grey(x + 1, y) - grey(x - 1, y);
            let gy = grey(x, y + 1) - grey(x, y - 1);
            sum += 0.5 * gx.hypot(gy);
            n += 1.0;
        }
    }
    sum / n.max(1.0)
}

/// Per appearance parameter, the synthesised within-sentence s.d. over the real one's.
pub fn flicker(synth: &Frames, real: &Frames) -> Vec<f64> {
    let range = synth.layout().appearance_range();
    let sd = |f: &Frames, k: usize| {
        super::standard_deviation(&f.column(k).iter().map(|&v| v as f64).collect::<Vec<_>>())
    };
    range
        .map(|k| sd(synth, k) / sd(real, k).max(1e-9))
        .collect()
}
