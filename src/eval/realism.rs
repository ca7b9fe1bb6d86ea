//! Can a plain classifier tell synthesis from the recording? (issue 38)
//!
//! Each frame's mouth is cut out head-stabilised — a similarity fitted to the eye corners and
//! nose (points that do not move with speech) maps a fixed window around the model's mean lips
//! into the image, sampled in grey — and every second of crops ([`WINDOW`] frames, half
//! overlapping) becomes a few statistics ([`features`]): sharpness, high-frequency energy,
//! temporal change, brightness steadiness, and how the crops move in and out of a 5-component
//! PCA fitted on the training folds' crops. A logistic regression on them, cross-validated by
//! sentence (a sentence's real and synthesised windows always in the same fold), gives the
//! accuracy: 0.5 when the two cannot be told apart, 1 when they always can.

use image::RgbImage;

use crate::model::FaceModel;
use crate::pca::{Components, PcaModel};
use crate::shape::{Point, Similarity, align};

/// Crop width and height, pixels: about the lips' own size in a 360×288 GRID frame, with a
/// margin.
pub const CROP: (usize, usize) = (64, 40);

/// Frames per window: one second at 25 fps.
pub const WINDOW: usize = 25;

/// Folds of the cross-validation.
pub const FOLDS: usize = 5;

/// PCA components of the crops whose motion the features measure.
const PCS: usize = 5;

/// L2 penalty of the logistic regression (on standardised features).
pub const RIDGE: f64 = 1e-2;

/// iBUG-68 points that do not move with speech: eye corners, nose bridge and tip.
const STEADY: [usize; 9] = [36, 39, 42, 45, 27, 28, 29, 30, 33];

/// Frames the steady points are averaged over ([`Cropper::crops`]).
pub const STEADY_FRAMES: usize = 5;

/// Where crops are cut: the steady points and the lips of `model`'s mean shape in its
/// reference frame, from which each frame's crop window is placed.
#[derive(Clone, Debug)]
pub struct Cropper {
    steady: Vec<Point>,
    /// Crop pixel (0, 0) in reference-frame pixels, and reference pixels per crop pixel.
    origin: Point,
    step: f64,
}

impl Cropper {
    /// The cropper of an iBUG-68 `model` (`None` for another landmark set).
    pub fn new(model: &FaceModel) -> Option<Self> {
        let points = &model.frame.landmarks;
        if points.len() != 68 {
            return None;
        }
        let lips = &points[48..68];
        let (lo, hi) = lips.iter().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])]),
        );
        let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        // The lips' width and a half again, over the crop's width.
        let step = 1.5 * (hi[0] - lo[0]) / CROP.0 as f64;
        Some(Cropper {
            steady: STEADY.iter().map(|&i| points[i]).collect(),
            origin: [
                centre[0] - step * CROP.0 as f64 / 2.0,
                centre[1] - step * CROP.1 as f64 / 2.0,
            ],
            step,
        })
    }

    /// Every frame's crop ([`Cropper::crop`]) of a sequence, the steady points averaged over
    /// [`STEADY_FRAMES`] frames first, so the crops do not shake with a tracker's jitter (real
    /// frames' landmarks are tracked, synthesised ones are smooth).
    pub fn crops(&self, images: &[RgbImage], landmarks: &[Vec<Point>]) -> Vec<Vec<f32>> {
        let n = images.len().min(landmarks.len());
        let half = STEADY_FRAMES / 2;
        (0..n)
            .map(|t| {
                let (a, b) = (t.saturating_sub(half), (t + half + 1).min(n));
                let steady: Vec<Point> = STEADY
                    .iter()
                    .map(|&i| {
                        let sum = landmarks[a..b]
                            .iter()
                            .fold([0.0, 0.0], |s, l| [s[0] + l[i][0], s[1] + l[i][1]]);
                        [sum[0] / (b - a) as f64, sum[1] / (b - a) as f64]
                    })
                    .collect();
                self.crop_at(&images[t], &steady)
            })
            .collect()
    }

    /// The head-stabilised grey crop (BT.601 luma, `CROP.0 × CROP.1`, row-major) of the mouth
    /// of `image`, whose face has `landmarks` (68 points).
    pub fn crop(&self, image: &RgbImage, landmarks: &[Point]) -> Vec<f32> {
        let steady: Vec<Point> = STEADY.iter().map(|&i| landmarks[i]).collect();
        self.crop_at(image, &steady)
    }

    /// The crop placed by the steady points `steady` (of [`STEADY`]).
    fn crop_at(&self, image: &RgbImage, steady: &[Point]) -> Vec<f32> {
        let to_image = align(&self.steady, steady).unwrap_or(Similarity::new(1.0, 0.0, 0.0, 0.0));
        let mut out = Vec::with_capacity(CROP.0 * CROP.1);
        for v in 0..CROP.1 {
            for u in 0..CROP.0 {
                let r = [
                    self.origin[0] + self.step * (u as f64 + 0.5),
                    self.origin[1] + self.step * (v as f64 + 0.5),
                ];
                let p = to_image.apply(r);
                let rgb = crate::warp::sample_bilinear(image, p[0] - 0.5, p[1] - 0.5);
                out.push(crate::video::luma(rgb.map(f64::from)) as f32);
            }
        }
        out
    }
}

/// Mean gradient magnitude (central differences) of a crop: its sharpness.
pub fn sharpness(crop: &[f32]) -> f64 {
    let (w, h) = (CROP.0 as u32, CROP.1 as u32);
    let grey = |x: u32, y: u32| f64::from(crop[(y * w + x) as usize]);
    super::mouth::mean_gradient(grey, 1..=w - 2, 1..=h - 2)
}

/// Mean absolute Laplacian of a crop: its finest detail.
fn laplacian(crop: &[f32]) -> f64 {
    let (w, h) = CROP;
    let mut sum = 0.0;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let c = crop[y * w + x];
            let l = crop[y * w + x + 1] + crop[y * w + x - 1] + crop[(y + 1) * w + x]
                + crop[(y - 1) * w + x]
                - 4.0 * c;
            sum += f64::from(l.abs());
        }
    }
    sum / ((w - 2) * (h - 2)) as f64
}

/// Mean absolute difference between consecutive crops: flicker and motion together.
pub fn temporal_change(crops: &[Vec<f32>]) -> f64 {
    let n = crops.len().saturating_sub(1);
    if n == 0 {
        return 0.0;
    }
    crops
        .windows(2)
        .map(|w| {
            w[0].iter().zip(&w[1]).map(|(a, b)| f64::from((a - b).abs())).sum::<f64>()
                / w[0].len() as f64
        })
        .sum::<f64>()
        / n as f64
}

fn mean_sd(v: impl Iterator<Item = f64>) -> (f64, f64) {
    super::mean_and_sd(&v.collect::<Vec<_>>())
}

/// The features of one window of crops, with `pca` fitted on training crops: sharpness
/// (mean, s.d.), Laplacian energy, temporal change, the s.d. of the mean brightness, each
/// PC score's s.d., and the mean share of the crop the PCs leave unexplained.
pub fn features(window: &[Vec<f32>], pca: &PcaModel) -> Vec<f64> {
    let (sharp, sharp_sd) = mean_sd(window.iter().map(|c| sharpness(c)));
    let (lap, _) = mean_sd(window.iter().map(|c| laplacian(c)));
    let (_, bright_sd) = mean_sd(
        window
            .iter()
            .map(|c| c.iter().map(|&v| f64::from(v)).sum::<f64>() / c.len() as f64),
    );
    let scores: Vec<Vec<f32>> = window.iter().map(|c| pca.project(c)).collect();
    let unexplained = mean_sd(window.iter().zip(&scores).map(|(c, b)| {
        let r = pca.reconstruct(b);
        c.iter().zip(&r).map(|(a, b)| f64::from(a - b).powi(2)).sum::<f64>().sqrt()
            / c.len() as f64
    }))
    .0;
    let mut f = vec![sharp, sharp_sd, lap, temporal_change(window), bright_sd, unexplained];
    for k in 0..pca.n_components() {
        f.push(mean_sd(scores.iter().map(|s| f64::from(s[k]))).1);
    }
    f
}

/// A logistic regression `p(1 | x) = σ(w·x + c)` with an L2 penalty on `w`.
#[derive(Clone, Debug, PartialEq)]
pub struct Logistic {
    /// Weights, one per feature.
    pub weights: Vec<f64>,
    /// Intercept.
    pub intercept: f64,
}

impl Logistic {
    /// Fits by Newton's method (IRLS) the penalised log-likelihood
    /// `Σ log p(yᵢ | xᵢ) − ridge/2 |w|²` (the intercept unpenalised), to convergence.
    pub fn fit(x: &[Vec<f64>], y: &[bool], ridge: f64) -> Logistic {
        let d = x.first().map_or(0, Vec::len) + 1;
        let mut beta = nalgebra::DVector::<f64>::zeros(d);
        let row = |xi: &[f64]| {
            nalgebra::DVector::from_iterator(d, xi.iter().copied().chain(std::iter::once(1.0)))
        };
        for _ in 0..50 {
            let mut grad = nalgebra::DVector::<f64>::zeros(d);
            let mut hess = nalgebra::DMatrix::<f64>::zeros(d, d);
            for (xi, &yi) in x.iter().zip(y) {
                let xi = row(xi);
                let p = 1.0 / (1.0 + (-xi.dot(&beta)).exp());
                grad += &xi * (f64::from(u8::from(yi)) - p);
                hess += &xi * xi.transpose() * (p * (1.0 - p));
            }
            for k in 0..d - 1 {
                grad[k] -= ridge * beta[k];
                hess[(k, k)] += ridge;
            }
            hess[(d - 1, d - 1)] += 1e-9;
            let Some(step) = hess.clone().cholesky().map(|c| c.solve(&grad)) else {
                break;
            };
            beta += &step;
            if step.amax() < 1e-10 {
                break;
            }
        }
        Logistic {
            weights: beta.as_slice()[..d - 1].to_vec(),
            intercept: beta[d - 1],
        }
    }

    /// `p(1 | x)`.
    pub fn probability(&self, x: &[f64]) -> f64 {
        let z: f64 = self.weights.iter().zip(x).map(|(w, v)| w * v).sum::<f64>() + self.intercept;
        1.0 / (1.0 + (-z).exp())
    }
}

/// One sentence's crops from each side: `a` (label 0: the recording) and `b` (label 1).
#[derive(Clone, Debug)]
pub struct Pair {
    /// The recording's crops, one per frame.
    pub a: Vec<Vec<f32>>,
    /// The other side's crops.
    pub b: Vec<Vec<f32>>,
}

/// Windows of `crops`: [`WINDOW`] frames every half window.
fn windows(crops: &[Vec<f32>]) -> impl Iterator<Item = &[Vec<f32>]> {
    let starts = (0..).step_by(WINDOW / 2).take_while(move |s| s + WINDOW <= crops.len());
    starts.map(move |s| &crops[s..s + WINDOW])
}

/// Names of the [`features`], in order.
pub const FEATURES: [&str; 11] = [
    "sharpness",
    "sharpness s.d.",
    "Laplacian",
    "temporal change",
    "brightness s.d.",
    "unexplained by the PCs",
    "PC1 s.d.",
    "PC2 s.d.",
    "PC3 s.d.",
    "PC4 s.d.",
    "PC5 s.d.",
];

/// A cross-validated accuracy, sentence by sentence: how many of each sentence's windows were
/// told right, so its standard error and differences can treat sentences as the sampled unit
/// (a sentence's windows overlap and share its words, so they are not independent).
#[derive(Clone, Debug, PartialEq)]
pub struct Accuracy {
    /// Per sentence, in the pairs' order: windows told right.
    pub right: Vec<usize>,
    /// Per sentence: windows tested.
    pub total: Vec<usize>,
}

impl Accuracy {
    /// Windows told right over windows tested (0 when none was tested).
    pub fn value(&self) -> f64 {
        self.right.iter().sum::<usize>() as f64 / self.total.iter().sum::<usize>().max(1) as f64
    }

    /// The standard error of [`Self::value`] over sentences: the cluster-robust (sandwich)
    /// estimator of a ratio with the small-sample factor n / (n − 1),
    /// `√(n / (n − 1) · Σ (right_i − p · total_i)²) / Σ total`. With one window per sentence
    /// it is the sample standard error of a proportion; NaN under two sentences or no window.
    pub fn standard_error(&self) -> f64 {
        if self.total.iter().sum::<usize>() == 0 {
            return f64::NAN;
        }
        spread(&self.parts())
    }

    /// `self.value() − other.value()` and its standard error when both were measured on the
    /// same sentences (two systems against one recording): each sentence's part in the two
    /// ratios differenced, so what the sentences share — how hard each is — cancels.
    /// Sentences only: the classifiers' own training is not resampled.
    pub fn minus(&self, other: &Accuracy) -> (f64, f64) {
        let differences: Vec<f64> =
            self.parts().iter().zip(other.parts()).map(|(a, b)| a - b).collect();
        (self.value() - other.value(), spread(&differences))
    }

    /// Each sentence's part in the ratio's deviation (its linearisation):
    /// `(right_i − p · total_i) / Σ total`.
    fn parts(&self) -> Vec<f64> {
        let (p, all) = (self.value(), self.total.iter().sum::<usize>().max(1) as f64);
        self.right
            .iter()
            .zip(&self.total)
            .map(|(&r, &t)| (r as f64 - p * t as f64) / all)
            .collect()
    }
}

/// `√(n / (n − 1) · Σ xᵢ²)` of `n` sentences' parts: a sum's standard error over sentences.
fn spread(parts: &[f64]) -> f64 {
    let n = parts.len();
    if n < 2 {
        return f64::NAN;
    }
    (n as f64 / (n - 1) as f64 * parts.iter().map(|x| x * x).sum::<f64>()).sqrt()
}

/// The classifier's accuracy at telling `a` from `b` windows, cross-validated over
/// [`FOLDS`] folds of sentences (sentence `i` in fold `i mod FOLDS`); the PCA and the
/// features' standardisation are fitted on the training folds only.
pub fn accuracy(pairs: &[Pair]) -> Accuracy {
    accuracy_on(pairs, &(0..FEATURES.len()).collect::<Vec<_>>())
}

/// [`accuracy`] of a classifier given only the features numbered `only` (of [`FEATURES`]).
pub fn accuracy_on(pairs: &[Pair], only: &[usize]) -> Accuracy {
    // Per sentence: windows told right, windows tested.
    let (mut right, mut total) = (vec![0usize; pairs.len()], vec![0usize; pairs.len()]);
    for fold in 0..FOLDS.min(pairs.len()) {
        let train: Vec<&Pair> = pairs.iter().enumerate().filter(|(i, _)| i % FOLDS != fold).map(|(_, p)| p).collect();
        let tested: Vec<usize> = (0..pairs.len()).filter(|i| i % FOLDS == fold).collect();
        let test: Vec<&Pair> = tested.iter().map(|&i| &pairs[i]).collect();
        if train.is_empty() || test.is_empty() {
            continue;
        }
        // PCA on every 5th training crop of both sides.
        let sample: Vec<&[f32]> = train
            .iter()
            .flat_map(|p| p.a.iter().chain(&p.b).step_by(5))
            .map(Vec::as_slice)
            .collect();
        let Ok(pca) = PcaModel::fit(&sample, Components::Count(PCS)) else {
            continue;
        };
        // Rows of (features, label, the set's sentence).
        let labelled = |set: &[&Pair]| {
            let mut rows = Vec::new();
            for (s, p) in set.iter().enumerate() {
                for (crops, label) in [(&p.a, false), (&p.b, true)] {
                    rows.extend(windows(crops).map(|w| {
                        let f = features(w, &pca);
                        (only.iter().filter_map(|&k| f.get(k).copied()).collect::<Vec<_>>(), label, s)
                    }));
                }
            }
            rows
        };
        let (train_rows, test_rows) = (labelled(&train), labelled(&test));
        let d = train_rows.first().map_or(0, |r| r.0.len());
        let stats: Vec<(f64, f64)> = (0..d)
            .map(|k| mean_sd(train_rows.iter().map(|r| r.0[k])))
            .collect();
        let standard = |f: &[f64]| -> Vec<f64> {
            f.iter().zip(&stats).map(|(v, (m, s))| (v - m) / s.max(1e-12)).collect()
        };
        let x: Vec<Vec<f64>> = train_rows.iter().map(|r| standard(&r.0)).collect();
        let y: Vec<bool> = train_rows.iter().map(|r| r.1).collect();
        let model = Logistic::fit(&x, &y, RIDGE);
        for (f, label, s) in &test_rows {
            right[tested[*s]] += usize::from((model.probability(&standard(f)) > 0.5) == *label);
            total[tested[*s]] += 1;
        }
    }
    Accuracy { right, total }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// At the fitted optimum the penalised log-likelihood's gradient vanishes (the KKT
    /// condition, independent of how the fit got there).
    #[test]
    fn logistic_fit_is_a_stationary_point() {
        let mut rng = Rng::new(3);
        let x: Vec<Vec<f64>> = (0..400).map(|_| vec![rng.normal(), rng.normal()]).collect();
        let y: Vec<bool> = x
            .iter()
            .map(|v| rng.uniform() < 1.0 / (1.0 + (-(1.5 * v[0] - 0.5 * v[1] + 0.3)).exp()))
            .collect();
        let m = Logistic::fit(&x, &y, 0.5);
        let mut grad = [0.0; 3];
        for (v, &label) in x.iter().zip(&y) {
            let r = f64::from(u8::from(label)) - m.probability(v);
            grad[0] += r * v[0];
            grad[1] += r * v[1];
            grad[2] += r;
        }
        grad[0] -= 0.5 * m.weights[0];
        grad[1] -= 0.5 * m.weights[1];
        assert!(grad.iter().all(|g| g.abs() < 1e-6), "{grad:?}");
        // And it found the generating direction.
        assert!(m.weights[0] > 1.0 && m.weights[1] < 0.0, "{m:?}");
    }

    /// A crop of an image and of the same image shifted, scaled and turned, with its
    /// landmarks moved alike, are the same crop (up to resampling).
    #[test]
    fn crops_follow_the_head() {
        let model = FaceModel::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/grid/model"),
        )
        .unwrap();
        let cropper = Cropper::new(&model).unwrap();
        let pattern = |x: f64, y: f64| (128.0 + 60.0 * (x / 9.0).sin() * (y / 7.0).cos()) as u8;
        let lips = |pose: &Similarity| -> (RgbImage, Vec<Point>) {
            let inv = pose.invert();
            let image = RgbImage::from_fn(360, 288, |x, y| {
                let p = inv.apply([f64::from(x) + 0.5, f64::from(y) + 0.5]);
                let v = pattern(p[0], p[1]);
                image::Rgb([v, v, v])
            });
            (image, pose.apply_all(&model.frame.landmarks))
        };
        let (a_img, a_pts) = lips(&Similarity::new(1.0, 0.0, 100.0, 60.0));
        let (b_img, b_pts) = lips(&Similarity::new(1.1, 0.08, 90.0, 40.0));
        let (a, b) = (cropper.crop(&a_img, &a_pts), cropper.crop(&b_img, &b_pts));
        let mean_diff = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).sum::<f32>() / a.len() as f32;
        assert!(mean_diff < 4.0, "{mean_diff}");
        assert!(sharpness(&a) > 1.0);
    }

    /// Two sides drawn from one distribution are told apart about half the time; a side
    /// with blurred crops almost always.
    #[test]
    fn accuracy_is_chance_for_alike_and_high_for_blurred() {
        let mut rng = Rng::new(7);
        let mut crop = |blur: bool| -> Vec<f32> {
            let noise: Vec<f32> = (0..CROP.0 * CROP.1).map(|_| (rng.normal() * 20.0) as f32).collect();
            (0..CROP.0 * CROP.1)
                .map(|i| {
                    let v = if blur && i + 1 < noise.len() && i >= 1 {
                        (noise[i - 1] + noise[i] + noise[i + 1]) / 3.0
                    } else {
                        noise[i]
                    };
                    128.0 + v
                })
                .collect()
        };
        let mut pairs = |blur: bool| -> Vec<Pair> {
            (0..20)
                .map(|_| Pair {
                    a: (0..50).map(|_| crop(false)).collect(),
                    b: (0..50).map(|_| crop(blur)).collect(),
                })
                .collect()
        };
        let alike = accuracy(&pairs(false));
        let blurred = accuracy(&pairs(true));
        assert!((alike.value() - 0.5).abs() < 0.15, "{alike:?}");
        assert!(blurred.value() > 0.95, "{blurred:?}");
        // 20 sentences of 3 windows a side: chance's spread is about √(¼ / 120) ≈ 0.046.
        assert!((0.02..0.1).contains(&alike.standard_error()), "{alike:?}");
    }

    /// Analytic cases: one window per sentence is the sample standard error of a proportion;
    /// two sentences of 4 windows, 3 and 1 right: p = ½, residuals ±1, √(2 · 2) / 8.
    #[test]
    fn clustered_standard_error_matches_hand_values() {
        let of = |right: Vec<usize>, total: Vec<usize>| Accuracy { right, total };
        let p: f64 = 6.0 / 8.0;
        let sample = (p * (1.0 - p) / 7.0).sqrt();
        let se = of(vec![1, 0, 1, 1, 0, 1, 1, 1], vec![1; 8]).standard_error();
        assert!((se - sample).abs() < 1e-12, "{se} against {sample}");
        assert!((of(vec![3, 1], vec![4, 4]).standard_error() - 0.25).abs() < 1e-12);
        // Every sentence at the same rate: no spread between sentences.
        assert_eq!(of(vec![2, 4, 6], vec![4, 8, 12]).standard_error(), 0.0);
        assert!(of(vec![1], vec![2]).standard_error().is_nan());
    }

    /// A difference against itself is zero with no spread; against a system whose every
    /// sentence sits at its own mean rate, the difference's error is the other's own.
    #[test]
    fn paired_difference_of_accuracies() {
        let of = |right: Vec<usize>, total: Vec<usize>| Accuracy { right, total };
        let a = of(vec![3, 1, 4, 2], vec![4, 4, 4, 4]);
        assert_eq!(a.minus(&a), (0.0, 0.0));
        let steady = of(vec![2, 2, 2, 2], vec![4, 4, 4, 4]);
        let (d, se) = a.minus(&steady);
        assert!((d - (10.0 / 16.0 - 0.5)).abs() < 1e-12);
        assert!((se - a.standard_error()).abs() < 1e-12, "{se} against {}", a.standard_error());
        // Two systems that rise and fall together on the same sentences: their difference
        // varies less than either.
        let b = of(vec![4, 2, 4, 3], vec![4, 4, 4, 4]);
        assert!(a.minus(&b).1 < a.standard_error().min(b.standard_error()));
    }
}
