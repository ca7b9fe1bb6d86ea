//! The cubic smoothing spline against scipy, and its limits.
use facespace::synth::smooth::{SmoothError, SmoothingSpline};
use serde::Deserialize;

#[derive(Deserialize)]
struct Case {
    name: String,
    x: Vec<f64>,
    y: Vec<f64>,
    w: Option<Vec<f64>>,
    lam: f64,
    fit: Vec<f64>,
}

/// Matches scipy's `make_smoothing_spline` for the same λ to 1e-6.
#[test]
fn matches_scipy() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/smoothing_scipy.json"
    );
    let cases: Vec<Case> = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(cases.len(), 6);
    for c in cases {
        let s = SmoothingSpline::new(&c.x, c.w.as_deref(), c.lam).unwrap();
        let g = s.smooth(&c.y).unwrap();
        let worst = g
            .iter()
            .zip(&c.fit)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{}: worst difference {worst:e}", c.name);
    }
}

#[test]
fn limits_interpolate_and_fit_a_line() {
    let x: Vec<f64> = (0..30)
        .map(|i| i as f64 * 0.04 + (i % 3) as f64 * 0.005)
        .collect();
    let y: Vec<f64> = x.iter().map(|t| (7.0 * t).sin() + 0.3 * t).collect();
    let g = SmoothingSpline::new(&x, None, 0.0)
        .unwrap()
        .smooth(&y)
        .unwrap();
    assert!(
        g.iter().zip(&y).all(|(a, b)| (a - b).abs() < 1e-9),
        "λ = 0 interpolates"
    );
    // λ → ∞: the least-squares line.
    let g = SmoothingSpline::new(&x, None, 1e12)
        .unwrap()
        .smooth(&y)
        .unwrap();
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let slope = x
        .iter()
        .zip(&y)
        .map(|(a, b)| (a - mx) * (b - my))
        .sum::<f64>()
        / x.iter().map(|a| (a - mx).powi(2)).sum::<f64>();
    for (xi, gi) in x.iter().zip(&g) {
        assert!(
            (gi - (my + slope * (xi - mx))).abs() < 1e-6,
            "{gi} vs the line"
        );
    }
}

#[test]
fn rows_and_errors() {
    let x = [0.0, 1.0, 2.0, 3.0];
    let s = SmoothingSpline::new(&x, None, 0.5).unwrap();
    let mut rows = vec![0.0, 10.0, 1.0, 11.0, 0.0, 10.0, 1.0, 11.0];
    s.smooth_rows(&mut rows, 2).unwrap();
    let col0 = s.smooth(&[0.0, 1.0, 0.0, 1.0]).unwrap();
    assert_eq!(rows[2], col0[1]);
    assert_eq!(
        SmoothingSpline::new(&x[..2], None, 1.0).unwrap_err(),
        SmoothError::TooFewPoints(2)
    );
    assert_eq!(
        SmoothingSpline::new(&[0.0, 1.0, 1.0], None, 1.0).unwrap_err(),
        SmoothError::NotIncreasing(2)
    );
    assert!(matches!(
        SmoothingSpline::new(&x, None, -1.0),
        Err(SmoothError::BadLambda(_))
    ));
    assert!(matches!(
        SmoothingSpline::new(&x, Some(&[1.0, 0.0, 1.0, 1.0]), 1.0),
        Err(SmoothError::BadWeight(1))
    ));
    assert!(matches!(s.smooth(&[1.0]), Err(SmoothError::Length { .. })));
}
