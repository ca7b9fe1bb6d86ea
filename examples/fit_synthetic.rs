//! Synthetic AAM fitting experiment: images rendered from the demo model at random
//! parameters (±2σ shape, ±1σ appearance) plus noise, starts perturbed by up to 10% of the
//! face width in translation, ±10° rotation and ±10% scale from the mean shape.
//! Run: cargo run --release --example fit_synthetic [trials]
use facespace::facespace::FaceParams;
use facespace::fit::{FitOptions, Fitter};
use facespace::model::{FaceModel, load_training_set};
use facespace::render::{CpuRenderer, Renderer};
use facespace::rng::Rng;
use facespace::shape::Similarity;

fn main() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/demo/model")).unwrap();
    let frames = load_training_set(&root.join("models/demo/training"), None).unwrap();
    let trials: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(50);
    let levels: usize = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(2);
    let max_iterations: usize = std::env::var("MAX_IT")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(40);
    let clamp_sd: f64 = std::env::var("CLAMP")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3.0);
    let refine_iterations: usize = std::env::var("REFINE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let fitter = Fitter::new(
        &model,
        FitOptions {
            max_iterations,
            clamp_sd,
            refine_iterations,
            ..FitOptions::default()
        },
        levels,
    )
    .unwrap();
    let k: f64 = std::env::args()
        .nth(3)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let mut rng = Rng::new(3);
    let mut errors = Vec::new();
    let mut iters = 0;
    let start = std::time::Instant::now();
    for t in 0..trials {
        let bg = &frames[t % frames.len()];
        let (pose, _) = model.shape.project(&bg.landmarks).unwrap();
        let sd = |v: &[f32], k: f64, rng: &mut Rng| {
            v.iter()
                .map(|x| (rng.range(-k, k) * (*x as f64).sqrt()) as f32)
                .collect::<Vec<_>>()
        };
        let shape = sd(&model.shape.pca.variances, 2.0, &mut rng);
        let appearance = sd(
            &model.appearance.pca.variances,
            std::env::var("APP_SD")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(1.0),
            &mut rng,
        );
        let truth = FaceParams {
            pose,
            shape: &shape,
            appearance: &appearance,
        };
        // A plain background of the video's blue: no second face for the fit to lock onto.
        let mut img = if std::env::var("REAL_BG").is_ok() {
            bg.image.clone()
        } else {
            image::RgbImage::from_pixel(
                bg.image.width(),
                bg.image.height(),
                image::Rgb([40, 90, 210]),
            )
        };
        CpuRenderer::new(&model)
            .render_into(truth, &mut img)
            .unwrap();
        let r = model.reconstruct(truth).unwrap();
        for p in img.pixels_mut() {
            for c in p.0.iter_mut() {
                *c = (*c as f64 + 2.0 * rng.normal()).round().clamp(0.0, 255.0) as u8;
            }
        }
        let (lo, hi) = r.landmarks.bounds();
        let width = hi[0] - lo[0];
        let c = facespace::shape::centroid(&r.landmarks.points);
        let perturb = Similarity::new(
            1.0 + k * rng.range(-0.1, 0.1),
            (k * rng.range(-10f64, 10.0)).to_radians(),
            0.0,
            0.0,
        );
        let shift = [
            k * rng.range(-0.1, 0.1) * width,
            k * rng.range(-0.1, 0.1) * width,
        ];
        let mean = model
            .shape
            .instance(&truth.pose, &vec![0.0; model.shape.n_params()]);
        let init = facespace::shape::Landmarks {
            points: mean
                .points
                .iter()
                .map(|p| {
                    let q = perturb.apply([p[0] - c[0], p[1] - c[1]]);
                    [q[0] + c[0] + shift[0], q[1] + c[1] + shift[1]]
                })
                .collect(),
        };
        let f = fitter.fit(&img, &init).unwrap();
        iters += f.iterations;
        let e = f
            .landmarks
            .points
            .iter()
            .zip(&r.landmarks.points)
            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
            .sum::<f64>()
            / 68.0;
        if e > 1.0 && std::env::var("VERBOSE").is_ok() {
            let z: Vec<String> = truth
                .shape
                .iter()
                .zip(&model.shape.pca.variances)
                .map(|(b, v)| format!("{:+.1}", *b as f64 / (*v as f64).sqrt()))
                .collect();
            let fitted = model.shape.project(&f.landmarks).unwrap().1;
            let zf: Vec<String> = fitted
                .iter()
                .zip(&model.shape.pca.variances)
                .map(|(b, v)| format!("{:+.1}", *b as f64 / (*v as f64).sqrt()))
                .collect();
            println!(
                "trial {t} bg {} err {e:.2} iters {} truth σ [{}] fitted σ [{}]",
                bg.name.rsplit('/').next().unwrap(),
                f.iterations,
                z.join(" "),
                zf.join(" ")
            );
        }
        errors.push(e);
    }
    let el = start.elapsed().as_secs_f64();
    errors.sort_by(f64::total_cmp);
    let under = errors.iter().filter(|&&e| e < 1.0).count();
    println!(
        "{trials} fits: {under} ({:.0}%) under 1 px mean point error; median {:.3}, p90 {:.3}, max {:.3}; {:.1} iterations/fit; {:.1} ms/fit",
        100.0 * under as f64 / trials as f64,
        errors[trials / 2],
        errors[trials * 9 / 10],
        errors[trials - 1],
        iters as f64 / trials as f64,
        1e3 * el / trials as f64
    );
}
