//! AAM search on synthetic renders with exact ground truth and on real held-out frames.
use crate::common;

use common::{Params, Rng};
use facespace::fit::{FitError, FitOptions, Fitter};
use facespace::model::{FaceModel, load_training_set};
use facespace::shape::{Landmarks, Similarity, centroid};
use image::{Rgb, RgbImage};

fn demo_model() -> FaceModel {
    FaceModel::load(&common::root().join("models/demo/model")).unwrap()
}

/// Renders the model at random parameters (shape ±2σ, appearance ±1σ) at a real frame's
/// pose on a plain background, plus Gaussian noise (σ = 2 grey levels).
fn synthetic(
    model: &FaceModel,
    rng: &mut Rng,
    pose: Similarity,
    size: (u32, u32),
) -> (RgbImage, Landmarks) {
    let draw = |v: &[f32], k: f64, rng: &mut Rng| {
        v.iter()
            .map(|x| (rng.range(-k, k) * (*x as f64).sqrt()) as f32)
            .collect()
    };
    let truth = Params {
        pose,
        shape: draw(&model.shape.pca.variances, 2.0, rng),
        appearance: draw(&model.appearance.pca.variances, 1.0, rng),
    };
    let mut img = RgbImage::from_pixel(size.0, size.1, Rgb([40, 90, 210]));
    common::render(model, &truth, &mut img);
    let landmarks = model.landmarks(truth.view()).unwrap();
    for p in img.pixels_mut() {
        p.0 =
            p.0.map(|c| (c as f64 + 2.0 * rng.normal()).round().clamp(0.0, 255.0) as u8);
    }
    (img, landmarks)
}

/// `points` moved about their centroid by a similarity and shifted.
fn perturb(points: &Landmarks, scale: f64, angle_deg: f64, shift: [f64; 2]) -> Landmarks {
    let c = centroid(&points.points);
    let t = Similarity::new(scale, angle_deg.to_radians(), 0.0, 0.0);
    Landmarks {
        points: points
            .points
            .iter()
            .map(|p| {
                let q = t.apply([p[0] - c[0], p[1] - c[1]]);
                [q[0] + c[0] + shift[0], q[1] + c[1] + shift[1]]
            })
            .collect(),
    }
}

fn poses() -> Vec<Similarity> {
    let model = demo_model();
    load_training_set(&common::root().join("models/demo/training"), None)
        .unwrap()
        .iter()
        .map(|e| model.shape.project(&e.landmarks).unwrap().0)
        .collect()
}

/// Tracking-like starts (the true shape moved by up to 2 px, 2° and 2%). Measured: median
/// 0.05 px; one draw in 20 stops at 1.7 px (it does so from a single level too).
#[test]
fn converges_from_nearby_starts() {
    let model = demo_model();
    let fitter = Fitter::new(&model, FitOptions::default(), 2).unwrap();
    let poses = poses();
    let mut rng = Rng::new(11);
    let mut errors = Vec::new();
    for t in 0..20 {
        let (img, truth) = synthetic(&model, &mut rng, poses[t % poses.len()], (360, 288));
        let init = perturb(
            &truth,
            rng.range(0.98, 1.02),
            rng.range(-2.0, 2.0),
            [rng.range(-2.0, 2.0), rng.range(-2.0, 2.0)],
        );
        let fit = fitter.fit(&img, &init).unwrap();
        errors.push(common::mean_error(&fit.landmarks, &truth));
    }
    errors.sort_by(f64::total_cmp);
    eprintln!(
        "nearby starts: median {:.3} px, max {:.3} px",
        errors[10], errors[19]
    );
    let under = errors.iter().filter(|&&e| e < 0.5).count();
    assert!(
        under >= 18 && errors[10] < 0.1,
        "{under}/20 under 0.5 px, median {:.3} px",
        errors[10]
    );
}

/// The protocol: the model rendered at random parameters (shape ±2σ, appearance ±1σ)
/// plus noise, started from the mean shape at the true pose moved by up to 10% of the face
/// width, ±10° and ±10% scale. Target: ≥ 95% of fits under 1 px mean point error. With the
/// alternating refinement (40 steps at most) 299 of 300 draws of `examples/fit_synthetic`
/// land under 1 px; project-out alone about 80% (its bias under appearance change pulls it
/// off), kept here as a regression floor. The distribution is printed.
#[test]
fn synthetic_protocol_distribution() {
    let model = demo_model();
    let project_out = Fitter::new(&model, FitOptions::default(), 2).unwrap();
    let refined = Fitter::new(
        &model,
        FitOptions {
            refine_iterations: 40,
            ..FitOptions::default()
        },
        2,
    )
    .unwrap();
    let poses = poses();
    let mut rng = Rng::new(3);
    let (mut plain, mut errors) = (Vec::new(), Vec::new());
    for t in 0..40 {
        let (img, truth) = synthetic(&model, &mut rng, poses[t % poses.len()], (360, 288));
        let width = truth.bounds().1[0] - truth.bounds().0[0];
        let pose = model.shape.project(&truth).unwrap().0;
        let mean = model
            .shape
            .instance(&pose, &vec![0.0; model.shape.n_params()]);
        let init = perturb(
            &mean,
            rng.range(0.9, 1.1),
            rng.range(-10.0, 10.0),
            [rng.range(-0.1, 0.1) * width, rng.range(-0.1, 0.1) * width],
        );
        let fit = project_out.fit(&img, &init).unwrap();
        plain.push(common::mean_error(&fit.landmarks, &truth));
        let fit = refined.fit(&img, &init).unwrap();
        errors.push(common::mean_error(&fit.landmarks, &truth));
    }
    for (name, e) in [("project-out", &mut plain), ("refined", &mut errors)] {
        e.sort_by(f64::total_cmp);
        eprintln!(
            "synthetic protocol, {name}: {}/40 under 1 px; quartiles {:.3} {:.3} {:.3}, p90 {:.3}, max {:.3} px",
            e.iter().filter(|&&v| v < 1.0).count(),
            e[10],
            e[20],
            e[30],
            e[36],
            e[39]
        );
    }
    let under = |e: &[f64]| e.iter().filter(|&&v| v < 1.0).count();
    assert!(
        under(&errors) >= 38,
        "refined: only {}/40 under 1 px",
        under(&errors)
    );
    assert!(errors[20] < 0.1, "refined median {:.3} px", errors[20]);
    assert!(
        under(&plain) >= 30,
        "project-out: only {}/40 under 1 px",
        under(&plain)
    );
}

/// Real frames not used to build the model (dlib landmarks as reference), started from the
/// mean shape at the reference pose, moved by 3 px: mean point-to-point error over the
/// inter-ocular distance.
#[test]
fn real_held_out_frames() {
    let model = demo_model();
    let fitter = Fitter::new(&model, FitOptions::default(), 2).unwrap();
    let held = load_training_set(&common::root().join("tests/data/demo-heldout"), None).unwrap();
    let mut normalised = Vec::new();
    for e in &held {
        let pose = model.shape.project(&e.landmarks).unwrap().0;
        let init = perturb(
            &model
                .shape
                .instance(&pose, &vec![0.0; model.shape.n_params()]),
            1.0,
            0.0,
            [3.0, -3.0],
        );
        let fit = fitter.fit(&e.image, &init).unwrap();
        normalised.push(common::iod_error(&fit.landmarks, &e.landmarks));
    }
    let mean = normalised.iter().sum::<f64>() / normalised.len() as f64;
    eprintln!(
        "real held-out frames: mean error / inter-ocular distance = {mean:.4} (per frame {normalised:.3?})"
    );
    // Measured 0.023 (dlib's own landmarks are the reference, and are themselves noisy).
    assert!(mean < 0.04, "mean normalised error {mean:.4}");
}

#[test]
fn a_model_without_appearance_is_refused() {
    let mut model = demo_model();
    model.appearance.pca.components.clear();
    model.appearance.pca.variances.clear();
    assert!(matches!(
        Fitter::new(&model, FitOptions::default(), 2),
        Err(FitError::NoAppearance)
    ));
}
