//! Trajectories: PCHIP against scipy, no overshoot, time warps.
use facespace::trajectory::{Trajectory, TrajectoryError, frame_times};
use proptest::prelude::*;
use serde::Deserialize;

#[derive(Deserialize)]
struct Case {
    name: String,
    x: Vec<f64>,
    y: Vec<Vec<f64>>,
    q: Vec<f64>,
    value: Vec<Vec<f64>>,
    slope: Vec<Vec<f64>>,
}

/// Values and knot slopes match scipy's `PchipInterpolator` to 1e-9.
#[test]
fn pchip_matches_scipy() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/pchip_scipy.json");
    let cases: Vec<Case> = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert!(cases.len() >= 6);
    for c in cases {
        let dims = c.y[0].len();
        let tr = Trajectory::new(c.x.clone(), c.y.concat(), dims).unwrap();
        let mut worst = 0f64;
        for (q, expected) in c.q.iter().zip(&c.value) {
            for (a, b) in tr.eval(*q).iter().zip(expected) {
                worst = worst.max((a - b).abs());
            }
        }
        // Slopes: finite differences of our curve at the knots' right side agree with scipy's.
        for (i, (x, expected)) in c.x.iter().zip(&c.slope).enumerate().take(c.x.len() - 1) {
            let h = 1e-7 * (c.x[i + 1] - x);
            let (a, b) = (tr.eval(*x), tr.eval(x + h));
            for k in 0..dims {
                let fd = (b[k] - a[k]) / h;
                assert!(
                    (fd - expected[k]).abs() < 1e-4 * (1.0 + expected[k].abs()),
                    "{}: slope at {x}: {fd} vs {}",
                    c.name,
                    expected[k]
                );
            }
        }
        assert!(worst < 1e-9, "{}: worst difference {worst:e}", c.name);
    }
}

#[test]
fn passes_through_samples_and_holds_outside() {
    let tr = Trajectory::new(
        vec![0.0, 1.0, 3.0],
        vec![1.0, 10.0, 4.0, 40.0, 2.0, 20.0],
        2,
    )
    .unwrap();
    assert_eq!(tr.eval(1.0), vec![4.0, 40.0]);
    assert_eq!(tr.eval(-5.0), vec![1.0, 10.0]);
    assert_eq!(tr.eval(9.0), vec![2.0, 20.0]);
    let single = Trajectory::new(vec![2.0], vec![7.0], 1).unwrap();
    assert_eq!(single.eval(0.0), vec![7.0]);
}

#[test]
fn time_warp_is_a_linear_reparameterisation() {
    let times: Vec<f64> = (0..50).map(|i| i as f64 / 25.0).collect();
    let values: Vec<f64> = times.iter().map(|t| (5.0 * t).sin()).collect();
    let tr = Trajectory::new(times, values, 1).unwrap();
    let w = tr.warp(0.4, 1.0, 0.3).unwrap();
    let mut out = [0.0];
    for (t, src) in [(0.0, 0.4), (0.15, 0.7), (0.3, 1.0)] {
        w.eval_into(t, &mut out);
        assert_eq!(out[0], tr.eval(src)[0]);
    }
    assert_eq!(w.sample(&[0.15])[0], tr.eval(0.7)[0]);
    assert!(matches!(
        tr.warp(1.0, 1.0, 0.3),
        Err(TrajectoryError::BadSegment { .. })
    ));
    assert!(matches!(
        tr.warp(0.0, 1.0, 0.0),
        Err(TrajectoryError::BadDuration(_))
    ));
    assert_eq!(frame_times(1.0, 25.0).len(), 26);
    assert_eq!(tr.resample(25.0).len(), 50);
}

#[test]
fn bad_samples_are_errors() {
    assert_eq!(
        Trajectory::new(vec![], vec![], 1),
        Err(TrajectoryError::Empty)
    );
    assert!(matches!(
        Trajectory::new(vec![0.0, 1.0], vec![1.0], 1),
        Err(TrajectoryError::Shape { .. })
    ));
    assert!(matches!(
        Trajectory::new(vec![0.0, 0.0], vec![1.0, 2.0], 1),
        Err(TrajectoryError::NotIncreasing { index: 1, .. })
    ));
    assert!(matches!(
        Trajectory::new(vec![0.0, 1.0], vec![1.0, f64::NAN], 1),
        Err(TrajectoryError::NotFinite { index: 1 })
    ));
}

proptest! {
    /// On monotone data the curve is monotone between every pair of knots and never leaves
    /// the range of its two end samples (no overshoot).
    #[test]
    fn never_overshoots_monotone_data(
        steps in proptest::collection::vec((0.01f64..2.0, 0.0f64..5.0), 2..30),
        decreasing in any::<bool>(),
    ) {
        let mut t = 0.0;
        let mut y = 0.0;
        let (mut times, mut values) = (vec![0.0], vec![0.0]);
        for (dt, dy) in steps {
            t += dt;
            y += if decreasing { -dy } else { dy };
            times.push(t);
            values.push(y);
        }
        let tr = Trajectory::new(times.clone(), values.clone(), 1).unwrap();
        for i in 0..times.len() - 1 {
            let (lo, hi) = (values[i].min(values[i + 1]), values[i].max(values[i + 1]));
            let mut prev = values[i];
            for k in 1..=20 {
                let v = tr.eval(times[i] + (times[i + 1] - times[i]) * k as f64 / 20.0)[0];
                prop_assert!(v >= lo - 1e-9 && v <= hi + 1e-9, "overshoot {v} outside [{lo}, {hi}]");
                prop_assert!(if decreasing { v <= prev + 1e-9 } else { v >= prev - 1e-9 }, "not monotone");
                prev = v;
            }
        }
    }
}

/// The row-major slopes a trajectory is built with are, bit for bit, the per-column PCHIP
/// slopes (the scipy-checked routine), flat stretches and sign changes included.
#[test]
fn row_major_slopes_equal_the_column_routine() {
    use facespace::trajectory::{pchip_slopes, pchip_slopes_rows};
    let mut rng = crate::common::Rng::new(7);
    for (n, dims) in [(1, 3), (2, 4), (3, 1), (4, 5), (40, 7)] {
        let mut x = vec![0.0];
        for _ in 1..n {
            x.push(x[x.len() - 1] + 0.01 + rng.uniform());
        }
        // Some values repeat (zero secants), some alternate (sign changes).
        let values: Vec<f64> = (0..n * dims)
            .map(|i| match i % 5 {
                0 => 1.0,
                1 => if (i / dims) % 2 == 0 { -1.0 } else { 2.0 },
                _ => rng.uniform() * 4.0 - 2.0,
            })
            .collect();
        let rows = pchip_slopes_rows(&x, &values, dims);
        let mut d = vec![0.0; n];
        for k in 0..dims {
            let column: Vec<f64> = (0..n).map(|i| values[i * dims + k]).collect();
            pchip_slopes(&x, &column, &mut d);
            for i in 0..n {
                assert_eq!(rows[i * dims + k].to_bits(), d[i].to_bits(), "n {n} dim {k} sample {i}");
            }
        }
    }
}
