//! Blend synthesis on the demo corpus, evaluated honestly: λ chosen on the validation split,
//! every system scored on the test split with the same smoothing (DESIGN §9).
use crate::common;

use facespace::corpus::demo::Split;
use facespace::synth::systems::{LAMBDA_GRID, choose_smoothing};
use facespace::synth::systems::{System, evaluate};
use facespace::synth::blend::Blend;

#[test]
fn blend_beats_fair_baselines_on_the_test_split() {
    let (model, generated, cb) = common::demo_corpus_codebook();
    let validation = generated.part(Split::Validation);
    let test = generated.part(Split::Test);
    assert!(
        validation
            .iter()
            .all(|v| test.iter().all(|t| t.name != v.name))
    );
    let choice =
        choose_smoothing(&model, &cb, &validation, Blend::default(), &LAMBDA_GRID).unwrap();
    let table = evaluate(
        &model,
        &cb,
        &test,
        &System::comparison(choice.lambda, Default::default()),
    )
    .unwrap();
    for row in &table {
        let m = row.mean;
        eprintln!(
            "{:<42} r_pca {:.3}  DTW {:.1}  mouth sd {:.3} px",
            row.system, m.r_pca, m.dtw, m.mouth_sd_px
        );
    }
    let row = |name: &str| {
        table
            .iter()
            .find(|r| r.system == name)
            .unwrap_or_else(|| panic!("no row {name}"))
            .mean
    };
    let l = format!("{:e}", choice.lambda);
    for suffix in [format!("smoothed λ={l}"), "unsmoothed".into()] {
        let n3 = row(&format!("blend C=1 N=3, {suffix}"));
        for other in ["blend C=1 N=1", "per-phoneme mean", "random lips"] {
            let o = row(&format!("{other}, {suffix}"));
            assert!(
                n3.r_pca > o.r_pca && n3.dtw < o.dtw,
                "{suffix}: N=3 (r_pca {:.3}, DTW {:.1}) vs {other} (r_pca {:.3}, DTW {:.1})",
                n3.r_pca,
                n3.dtw,
                o.r_pca,
                o.dtw
            );
        }
    }
    // Smoothing lowers the articulation amplitude (std of mouth height).
    let (smoothed, raw) = (
        row(&format!("blend C=1 N=3, smoothed λ={l}")),
        row("blend C=1 N=3, unsmoothed"),
    );
    assert!(smoothed.mouth_sd_px < raw.mouth_sd_px);
}

/// Issue 22's mouth measures ([unitsel] §7) against analytic cases: the inner-mouth height of
/// known points; flicker 1 for a copy and 2 for doubled motion; eq. 16's mouth PC recovers a
/// one-parameter appearance motion (|r| > 0.99 with it), scores a copy 1 and an inversion −1.
#[test]
fn mouth_measures_on_analytic_cases() {
    use facespace::eval::mouth::{MouthPc, flicker, inner_mouth_height};
    use facespace::eval::pearson;
    use facespace::facespace::Frames;
    let mut points = vec![[0.0, 0.0]; 68];
    for (top, bottom, gap) in [(61, 67, 2.0), (62, 66, 4.0), (63, 65, 6.0)] {
        points[top] = [0.0, 10.0];
        points[bottom] = [0.0, 10.0 + gap];
    }
    assert!((inner_mouth_height(&points) - 4.0).abs() < 1e-12);

    let model =
        facespace::model::FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let layout = model.layout();
    let first = layout.appearance_range().start;
    let motion: Vec<f64> = (0..40).map(|k| (0.3 * k as f64).sin()).collect();
    let frames_with = |amp: f64| {
        let values = ndarray::Array2::from_shape_fn((40, layout.dims()), |(t, k)| {
            if k == first {
                (amp * motion[t]) as f32
            } else if k == 0 {
                1.0
            } else {
                0.0
            }
        });
        Frames::new(layout, 25.0, values).unwrap()
    };
    let sd0 = model.appearance.pca.variances[0].sqrt() as f64;
    let real = frames_with(sd0);
    let f = flicker(&real, &real);
    assert!((f[0] - 1.0).abs() < 1e-9);
    let doubled = frames_with(2.0 * sd0);
    assert!((flicker(&doubled, &real)[0] - 2.0).abs() < 1e-6);

    let pc = MouthPc::fit(&model, &[&real]).expect("the demo model has lips");
    let series = pc.series(&real);
    assert!(
        pearson(&series, &motion).abs() > 0.99,
        "{}",
        pearson(&series, &motion)
    );
    assert!((pearson(&series, &pc.series(&real)) - 1.0).abs() < 1e-12);
    let inverted = frames_with(-sd0);
    assert!(pearson(&pc.series(&inverted), &series) < -0.99);
    let norm: f64 = pc.axis().iter().map(|v| v * v).sum();
    assert!((norm - 1.0).abs() < 1e-9);
}

/// Lip motion (issue 33) as properties: zero for a still mouth under a moving head (the pose
/// is not the mouth's), linear in the amplitude of a shape motion, and for a shape parameter
/// stepping 0 → a → 0 … the mean lip displacement of that step computed from the landmarks.
#[test]
fn lip_motion_is_the_mouths_own_speed() {
    use facespace::eval::mouth::lip_motion;
    use facespace::facespace::Frames;
    use facespace::shape::Similarity;
    let model =
        facespace::model::FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let layout = model.layout();
    let first = layout.shape_range().start;
    let frames_with = |amp: f64, head: f64| {
        let values = ndarray::Array2::from_shape_fn((30, layout.dims()), |(t, k)| {
            if k == first {
                (amp * (t % 2) as f64) as f32
            } else if k == 0 {
                1.0 + (head * t as f64) as f32
            } else if k == 2 {
                (head * 10.0 * t as f64) as f32
            } else {
                0.0
            }
        });
        Frames::new(layout, 25.0, values).unwrap()
    };
    assert_eq!(lip_motion(&model, &frames_with(0.0, 0.01)), 0.0);
    let sd = model.shape.pca.variances[0].sqrt() as f64;
    let one = lip_motion(&model, &frames_with(sd, 0.0));
    assert!(one > 0.0);
    assert!((lip_motion(&model, &frames_with(2.0 * sd, 0.03)) / one - 2.0).abs() < 1e-4);
    let mut b = vec![0f32; layout.shape_range().len()];
    let rest = model.shape.instance(&Similarity::IDENTITY, &b).points;
    b[0] = sd as f32;
    let moved = model.shape.instance(&Similarity::IDENTITY, &b).points;
    let step: f64 = (48..68)
        .map(|i| (rest[i][0] - moved[i][0]).hypot(rest[i][1] - moved[i][1]))
        .sum::<f64>()
        / 20.0;
    assert!((one - step).abs() < 1e-4 * step, "{one} vs {step}");
    assert_eq!(lip_motion(&model, &frames_with(sd, 0.0).slice(0..1)), 0.0);
}

/// A talker's settings (issue 33) chosen on the demo corpus's validation split: one trial per
/// N and λ of the grids; smoothing more never makes the mouth move faster (lip motion over
/// real falls with λ for every N); and the chosen trial is the rule's — within the motion
/// floor and amplitude band if any trial is, and then no trial within them correlates better.
#[test]
fn talker_settings_keep_the_lip_motion() {
    use facespace::synth::systems::{SETTINGS_LAMBDA_GRID, TOP_N_GRID, choose_settings};
    let (model, generated, cb) = common::demo_corpus_codebook();
    let validation = generated.part(Split::Validation);
    let choice = choose_settings(&model, &cb, &validation, &TOP_N_GRID, &SETTINGS_LAMBDA_GRID)
        .unwrap()
        .expect("the demo face has lips");
    assert_eq!(
        choice.trials.len(),
        TOP_N_GRID.len() * SETTINGS_LAMBDA_GRID.len()
    );
    for by_n in choice.trials.chunks(SETTINGS_LAMBDA_GRID.len()) {
        for w in by_n.windows(2) {
            assert!(
                w[1].mouth.lip_motion_ratio <= w[0].mouth.lip_motion_ratio + 1e-9,
                "N={} λ {} → {}: motion {} → {}",
                w[0].top_n,
                w[0].smoothing,
                w[1].smoothing,
                w[0].mouth.lip_motion_ratio,
                w[1].mouth.lip_motion_ratio
            );
        }
    }
    let within: Vec<_> = choice.trials.iter().filter(|t| t.shortfall() == 0.0).collect();
    assert_eq!(choice.within_bounds, !within.is_empty());
    if choice.within_bounds {
        assert!(choice.chosen.mouth.lip_motion_ratio >= 0.9);
        assert!(within.iter().all(|t| t.correlation() <= choice.chosen.correlation()));
    }
    assert_eq!(choice.sentences, validation.len());
}

/// Mouth sharpness against analytic images: a grey ramp of slope g per pixel (any direction)
/// scores g inside the lips' box, a flat image 0, and a box reaching past the border is
/// clipped, not a panic.
#[test]
fn mouth_sharpness_of_ramps() {
    use facespace::eval::mouth::mouth_sharpness;
    let mut lips = vec![[0.0, 0.0]; 68];
    for (k, p) in lips.iter_mut().enumerate().skip(48) {
        *p = [40.0 + (k - 48) as f64, 30.0 + ((k * 7) % 11) as f64];
    }
    let ramp = |gx: f64, gy: f64| {
        image::RgbImage::from_fn(100, 80, |x, y| {
            let v = (10.0 + gx * f64::from(x) + gy * f64::from(y)) as u8;
            image::Rgb([v, v, v])
        })
    };
    let s = mouth_sharpness(&[ramp(2.0, 0.0)], &[lips.clone()]);
    assert!((s - 2.0).abs() < 0.02, "{s}");
    let s = mouth_sharpness(&[ramp(0.0, 1.0), ramp(1.0, 0.0)], &[lips.clone(), lips.clone()]);
    assert!((s - 1.0).abs() < 0.02, "{s}");
    let s = mouth_sharpness(&[ramp(0.6, 0.8)], &[lips.clone()]);
    assert!((s - 1.0).abs() < 0.05, "{s}");
    assert_eq!(mouth_sharpness(&[ramp(0.0, 0.0)], &[lips.clone()]), 0.0);
    let far: Vec<[f64; 2]> = lips.iter().map(|p| [p[0] + 500.0, p[1] - 500.0]).collect();
    assert!(mouth_sharpness(&[ramp(1.0, 0.0)], &[far]).is_finite());
}
