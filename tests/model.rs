//! FaceModel: build, save/load, project ∘ reconstruct, and every bad-input path.
use crate::common;

use std::path::Path;

use common::{Params, Rng};
use facespace::facespace::FacespaceError;
use facespace::manifest::ManifestError;
use facespace::model::{FaceModel, ModelError, load_training_set};
use facespace::npy::{self, NpyError};
use facespace::shape::Similarity;
use image::RgbImage;
use ndarray::Array2;

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

fn random_params(model: &FaceModel, rng: &mut Rng, pose: Similarity) -> Params {
    let draw = |vars: &[f32], rng: &mut Rng| {
        vars.iter()
            .map(|v| (rng.range(-2.0, 2.0) * (*v as f64).sqrt()) as f32)
            .collect()
    };
    Params {
        pose,
        shape: draw(&model.shape.pca.variances, rng),
        appearance: draw(&model.appearance.pca.variances, rng),
    }
}

#[test]
fn build_reports_sensible_counts() {
    let model = common::small_model();
    assert_eq!(model.shape.n_landmarks(), 68);
    // Four faces: at most 3 modes of variation in each model.
    assert!(
        (1..=3).contains(&model.shape.n_params()),
        "{}",
        model.shape.n_params()
    );
    assert_eq!(model.appearance.n_params(), 3);
    // The mesh covers about the pixels asked for; the mask leaves out a rim.
    let f = &model.frame;
    let (owner, _) = facespace::mesh::cover(&f.landmarks, &f.triangles, f.width, f.height);
    let mesh = owner.iter().filter(|&&o| o != u32::MAX).count() as f64;
    assert!(
        (mesh - 6000.0).abs() < 0.03 * 6000.0,
        "the mesh covers {mesh} pixels for a 6000 target"
    );
    let rim = mesh - f.n_pixels() as f64;
    assert!(
        rim > 0.05 * mesh
            && f.rim_distances()
                .iter()
                .all(|&d| d >= facespace::model::DEFAULT_MARGIN),
        "{rim} rim pixels of {mesh}"
    );
    assert!(
        model.shape.pca.variance_ratio() >= 0.95 && model.appearance.pca.variance_ratio() >= 0.98
    );
}

#[test]
fn save_then_load_gives_identical_arrays() {
    let model = common::small_model();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m");
    model.save(&path).unwrap();
    let back = FaceModel::load(&path).unwrap();
    assert_eq!(back, model);
    // The arrays are plain .npy files a numpy user can open.
    let mean = npy::read::<f32>(&path.join("appearance_mean.npy")).unwrap();
    assert_eq!(mean.shape(), &[model.frame.n_pixels(), 3]);
    // Saving over an existing model replaces it whole.
    model.save(&path).unwrap();
    assert_eq!(FaceModel::load(&path).unwrap(), model);
}

/// `project(reconstruct(b)) == b` for random b within ±2σ, at the level of landmarks and
/// shape-normalised texture, on the real four-face model.
#[test]
fn project_of_reconstruct_recovers_random_parameters() {
    let model = common::small_model();
    let mut rng = Rng::new(42);
    let sd_a: Vec<f32> = model
        .appearance
        .pca
        .variances
        .iter()
        .map(|v| v.sqrt())
        .collect();
    let sd_s: Vec<f32> = model.shape.pca.variances.iter().map(|v| v.sqrt()).collect();
    for _ in 0..40 {
        let pose = Similarity::new(
            2.0 * model.placement.scale,
            rng.range(-0.2, 0.2),
            320.0,
            260.0,
        );
        let b = random_params(&model, &mut rng, pose);
        let r = model.reconstruct(b.view()).unwrap();
        let (pose2, bs) = model.shape.project(&r.landmarks).unwrap();
        for ((x, y), s) in b.shape.iter().zip(&bs).zip(&sd_s) {
            assert!((x - y).abs() < 1e-3 * s, "shape {x} vs {y}");
        }
        // The model is stored in f32: the pose comes back to ~1e-6 of its scale.
        let [a, b2, tx, ty] = pose2.to_array();
        assert!(
            (a - pose.a).abs().max((b2 - pose.b).abs()) < 1e-5 * pose.scale(),
            "{pose:?} vs {pose2:?}"
        );
        assert!(
            (tx - pose.tx).abs().max((ty - pose.ty).abs()) < 1e-3,
            "{pose:?} vs {pose2:?}"
        );
        let ba = model.appearance.project(&r.texture);
        for ((x, y), s) in b.appearance.iter().zip(&ba).zip(&sd_a) {
            assert!((x - y).abs() < 1e-3 * s, "appearance {x} vs {y}");
        }
    }
}

/// The same round trip through rendered 8-bit pixels, on a well-conditioned model: one real
/// face (takeo) under small landmark jitter and lighting gain. (On the four-person model most
/// ±2σ shapes fold the mesh and ~12% of texture values leave 0–255, so pixels cannot carry
/// them; this model is where the renderer and the projection, not the data, are on trial.)
#[test]
fn project_of_rendered_frame_recovers_parameters() {
    let face = common::faces()
        .into_iter()
        .find(|e| e.name.ends_with("takeo.png"))
        .unwrap();
    let mut rng = Rng::new(5);
    let examples: Vec<_> = (0..12)
        .map(|i| {
            let mut e = face.clone();
            let gain = rng.range(0.6, 0.75);
            e.image
                .pixels_mut()
                .for_each(|p| p.0 = p.0.map(|v| (30.0 + v as f64 * gain) as u8));
            let (dx, dy) = (rng.normal(), rng.normal());
            for (k, p) in e.landmarks.points.iter_mut().enumerate() {
                let w = ((k as f64) * 0.3 + i as f64).sin();
                p[0] += 0.4 * w * dx;
                p[1] += 0.4 * w * dy;
            }
            e.name = format!("takeo-{i}");
            e
        })
        .collect();
    let options = facespace::model::BuildOptions {
        pixels: 6_000,
        ..Default::default()
    };
    let model = FaceModel::build(&examples, &options, &mut facespace::no_progress).unwrap();
    let sd_a: Vec<f32> = model
        .appearance
        .pca
        .variances
        .iter()
        .map(|v| v.sqrt())
        .collect();
    // Components are orthonormal, so |Δb| / sqrt(dim) is the RMS texture difference in grey levels.
    let dim = model.appearance.pca.dim() as f32;
    let (mut worst_rms, mut worst_first, mut compared, mut rejected) = (0f32, 0f32, 0, 0);
    for _ in 0..30 {
        let pose = Similarity::new(
            2.0 * model.placement.scale,
            rng.range(-0.2, 0.2),
            320.0,
            260.0,
        );
        let b = random_params(&model, &mut rng, pose);
        let r = model.reconstruct(b.view()).unwrap();
        if folded_triangles(&model, &r.landmarks.points) > 0
            || r.texture.iter().any(|v| !(0.0..=255.0).contains(v))
        {
            rejected += 1;
            continue;
        }
        compared += 1;
        let mut canvas = RgbImage::new(640, 520);
        common::render(&model, &b, &mut canvas);
        let row = model.project(&canvas, &r.landmarks).unwrap();
        let back = model.layout().split(&row).unwrap();
        let sq: f32 = b
            .appearance
            .iter()
            .zip(back.appearance)
            .map(|(x, y)| (x - y).powi(2))
            .sum();
        worst_rms = worst_rms.max((sq / dim).sqrt());
        worst_first = worst_first.max((b.appearance[0] - back.appearance[0]).abs() / sd_a[0]);
    }
    eprintln!(
        "rendered round trip: {compared} draws compared, {rejected} rejected; worst texture RMS {worst_rms:.3} grey levels, \
         worst first-mode error {worst_first:.4} σ"
    );
    assert!(
        compared >= 20,
        "only {compared} of 30 draws were representable"
    );
    // Two bilinear resamplings and 8-bit rounding (alone ±0.5 → 0.29 RMS) cost under 1 grey level.
    assert!(
        worst_rms < 1.0,
        "texture off by {worst_rms} grey levels RMS through pixels"
    );
    assert!(
        worst_first < 0.1,
        "first appearance mode off by {worst_first} σ through pixels"
    );
}

#[test]
fn training_images_project_close_to_themselves() {
    let model = common::small_model();
    for e in common::faces() {
        let p = model.project(&e.image, &e.landmarks).unwrap();
        let r = model
            .reconstruct(model.layout().split(&p).unwrap())
            .unwrap();
        // With every mode kept, reconstruction reproduces the training landmarks.
        let err = r
            .landmarks
            .points
            .iter()
            .zip(&e.landmarks.points)
            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
            .fold(0.0, f64::max);
        let size = e.landmarks.bounds().1[0] - e.landmarks.bounds().0[0];
        assert!(
            err < 0.1 * size,
            "{}: landmark error {err:.2} px on a face {size:.0} px wide",
            e.name
        );
    }
}

#[test]
fn params_vector_round_trip_and_length_check() {
    let model = common::small_model();
    let mut rng = Rng::new(1);
    let b = random_params(&model, &mut rng, Similarity::new(3.0, 0.1, 5.0, 6.0));
    let v = b.to_vector();
    let layout = model.layout();
    assert_eq!(v.len(), layout.dims());
    let back = layout.split(&v).unwrap();
    assert_eq!(back.shape, b.shape.as_slice());
    assert_eq!(back.appearance, b.appearance.as_slice());
    assert!(matches!(
        layout.split(&v[1..]),
        Err(FacespaceError::Width { found, .. }) if found == v.len() - 1
    ));
    // A point of another layout is refused by the model, naming both.
    let short = Params {
        shape: b.shape[1..].to_vec(),
        ..b
    };
    let err = model.reconstruct(short.view()).unwrap_err();
    assert!(
        matches!(
            err,
            ModelError::Facespace(FacespaceError::LayoutMismatch { .. })
        ),
        "{err}"
    );
}

/// Triangles whose orientation at `points` is opposite to the reference frame's: the mesh
/// folds over itself there.
fn folded_triangles(model: &FaceModel, points: &[[f64; 2]]) -> usize {
    let area = |p: &[[f64; 2]], t: &[u32; 3]| {
        facespace::mesh::signed_area(p[t[0] as usize], p[t[1] as usize], p[t[2] as usize])
    };
    model
        .frame
        .triangles
        .iter()
        .filter(|t| area(points, t) * area(&model.frame.landmarks, t) <= 0.0)
        .count()
}

// ---- bad input ----

fn saved_model() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m");
    common::small_model().save(&path).unwrap();
    (dir, path)
}

#[test]
fn truncated_npy_is_named() {
    let (_d, path) = saved_model();
    let f = path.join("appearance_components.npy");
    let bytes = std::fs::read(&f).unwrap();
    std::fs::write(&f, &bytes[..bytes.len() / 2]).unwrap();
    let err = FaceModel::load(&path).unwrap_err();
    assert!(
        err.to_string().contains("appearance_components.npy")
            && err.to_string().contains("truncated"),
        "{err}"
    );
}

#[test]
fn wrong_shape_npy_is_named() {
    let (_d, path) = saved_model();
    npy::write(
        &path.join("shape_mean.npy"),
        Array2::<f32>::zeros((67, 2)).view(),
    )
    .unwrap();
    let err = FaceModel::load(&path).unwrap_err();
    assert!(
        matches!(&err, ModelError::Manifest(ManifestError::Npy(NpyError::Shape { expected, found, .. }))
            if expected == &vec![Some(68), Some(2)] && found == &vec![67, 2]),
        "{err}"
    );
    assert!(err.to_string().contains("shape_mean.npy"));
}

#[test]
fn nan_in_arrays_is_named() {
    let (_d, path) = saved_model();
    let f = path.join("appearance_variances.npy");
    let mut a = npy::read::<f32>(&f).unwrap();
    a[[1]] = f32::NAN;
    npy::write(&f, a.view()).unwrap();
    let err = FaceModel::load(&path).unwrap_err();
    assert!(
        matches!(
            err,
            ModelError::Manifest(ManifestError::Npy(NpyError::NotFinite { index: 1, .. }))
        ),
        "{err}"
    );
    // A negative variance is refused at load, not later in a clamp.
    a[[1]] = -1.0;
    npy::write(&f, a.view()).unwrap();
    let err = FaceModel::load(&path).unwrap_err();
    assert!(err.to_string().contains("negative"), "{err}");
}

#[test]
fn unknown_version_and_broken_manifest() {
    let (_d, path) = saved_model();
    let m = path.join("model.json");
    let text = std::fs::read_to_string(&m).unwrap();
    std::fs::write(&m, text.replace("\"version\": 1", "\"version\": 99")).unwrap();
    let err = FaceModel::load(&path).unwrap_err();
    assert!(
        matches!(
            &err,
            ModelError::Manifest(ManifestError::Version {
                found,
                supported: 1,
                ..
            }) if found == "99"
        ),
        "{err}"
    );
    // A version written as a string is reported as written, not as version 0.
    std::fs::write(&m, text.replace("\"version\": 1", "\"version\": \"1\"")).unwrap();
    let err = FaceModel::load(&path).unwrap_err();
    assert!(err.to_string().contains("version \"1\""), "{err}");
    std::fs::write(&m, &text[..text.len() / 2]).unwrap();
    assert!(matches!(
        FaceModel::load(&path),
        Err(ModelError::Manifest(ManifestError::Invalid { .. }))
    ));
    std::fs::write(&m, text.replace("\"width\"", "\"wide\"")).unwrap();
    assert!(matches!(
        FaceModel::load(&path),
        Err(ModelError::Manifest(ManifestError::Invalid { .. }))
    ));
    // An array file name that leaves the folder is refused.
    std::fs::write(&m, text.replace("\"mask.npy\"", "\"../mask.npy\"")).unwrap();
    let err = FaceModel::load(&path).unwrap_err();
    assert!(matches!(err, ModelError::Inconsistent { .. }), "{err}");
    assert!(err.to_string().contains("../mask.npy"), "{err}");
    let err = FaceModel::load(Path::new("/no/such/model")).unwrap_err();
    assert!(
        err.to_string().contains("/no/such/model/model.json"),
        "{err}"
    );
}

#[test]
fn mask_that_disagrees_with_the_mesh_is_caught() {
    let (_d, path) = saved_model();
    let f = path.join("mask.npy");
    let mut a = npy::read::<u8>(&f).unwrap();
    let first = a.iter_mut().find(|v| **v == 255).unwrap();
    *first = 0;
    npy::write(&f, a.view()).unwrap();
    assert!(matches!(
        FaceModel::load(&path),
        Err(ModelError::Inconsistent { .. })
    ));
}

#[test]
fn missing_and_orphan_landmarks() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&common::faces_dir(), dir.path());
    std::fs::remove_file(dir.path().join("takeo.pts")).unwrap();
    let err = load_training_set(dir.path(), None).unwrap_err();
    assert!(
        matches!(err, ModelError::MissingLandmarks { .. }) && err.to_string().contains("takeo.png"),
        "{err}"
    );
    std::fs::copy(
        common::faces_dir().join("takeo.pts"),
        dir.path().join("takeo.pts"),
    )
    .unwrap();
    std::fs::copy(
        common::faces_dir().join("takeo.pts"),
        dir.path().join("frame9.pts"),
    )
    .unwrap();
    let err = load_training_set(dir.path(), None).unwrap_err();
    assert!(
        matches!(err, ModelError::OrphanLandmarks { .. }) && err.to_string().contains("frame9.pts"),
        "{err}"
    );
    let empty = tempfile::tempdir().unwrap();
    assert!(matches!(
        load_training_set(empty.path(), None),
        Err(ModelError::NoImages { .. })
    ));
}

#[test]
fn mismatched_landmark_counts_name_both_files() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&common::faces_dir(), dir.path());
    let pts = dir.path().join("takeo.pts");
    let mut l = facespace::shape::read_pts(&pts).unwrap();
    l.points.truncate(66);
    facespace::shape::write_pts(&pts, &l).unwrap();
    let err = load_training_set(dir.path(), None).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            ModelError::LandmarkCount {
                expected: 68,
                found: 66,
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("takeo.pts") && msg.contains("breakingbad.pts"),
        "{msg}"
    );
}

#[test]
fn landmarks_of_another_frame_are_caught() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&common::faces_dir(), dir.path());
    // takeo.png is 150×225; breakingbad's landmarks lie far outside it.
    std::fs::copy(
        dir.path().join("breakingbad.pts"),
        dir.path().join("takeo.pts"),
    )
    .unwrap();
    let err = load_training_set(dir.path(), None).unwrap_err();
    assert!(
        matches!(err, ModelError::LandmarksOutsideImage { .. }),
        "{err}"
    );
    assert!(
        err.to_string().contains("takeo.png") && err.to_string().contains("different frames"),
        "{err}"
    );
}

#[test]
fn unreadable_image_and_malformed_pts_are_named() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&common::faces_dir(), dir.path());
    std::fs::write(dir.path().join("lenna.png"), b"not a png").unwrap();
    let err = load_training_set(dir.path(), None).unwrap_err();
    assert!(
        matches!(err, ModelError::Image { .. }) && err.to_string().contains("lenna.png"),
        "{err}"
    );
    std::fs::copy(
        common::faces_dir().join("lenna.png"),
        dir.path().join("lenna.png"),
    )
    .unwrap();
    std::fs::write(
        dir.path().join("einstein.pts"),
        "version: 1\nn_points: 68\n{\n1 2\n",
    )
    .unwrap();
    let err = load_training_set(dir.path(), None).unwrap_err();
    assert!(err.to_string().contains("einstein.pts:4"), "{err}");
}

/// Issue 26: a frame folder only partly marked on the annotate page stops `model build` at
/// the first frame without landmarks, naming it and the flag that leaves such frames out;
/// with `--skip-unmarked` the model is built from the marked ones.
#[test]
fn skip_unmarked_builds_from_the_marked_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    std::fs::create_dir(&dir).unwrap();
    let training = common::root().join("models/demo/training");
    let mut images: Vec<_> = std::fs::read_dir(&training)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "jpg"))
        .collect();
    images.sort();
    for (i, image) in images.iter().take(8).enumerate() {
        std::fs::copy(image, dir.join(image.file_name().unwrap())).unwrap();
        // The last two frames are not marked yet.
        if i < 6 {
            let pts = image.with_extension("pts");
            std::fs::copy(&pts, dir.join(pts.file_name().unwrap())).unwrap();
        }
    }
    let (d, out) = (dir.to_str().unwrap(), tmp.path().join("model"));
    // `model build` of the folder, with `extra` flags.
    let build = |extra: &[&str]| {
        let mut args = vec!["model", "build", "--images", d, "--pixels", "5000"];
        args.extend_from_slice(extra);
        args.extend(["-o", out.to_str().unwrap()]);
        common::facespace(&args)
    };
    let o = build(&[]);
    let t = common::text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("--skip-unmarked") && t.contains(".pts"), "{t}");
    assert!(!out.exists());
    let o = build(&["--skip-unmarked"]);
    let t = common::text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("left out 2 image(s)"), "{t}");
    let model = facespace::model::FaceModel::load(&out).unwrap();
    assert_eq!(model.source.len(), 6);
}

/// The default reference-frame size is the faces' own: the median convex-hull area of the
/// landmarks (analytic: squares of side 100, 120 and 150 px → 14 400), rounded to a thousand
/// and held within `FACE_PIXELS`.
#[test]
fn face_pixels_is_the_median_face_area() {
    use facespace::model::{FACE_PIXELS, TrainingExample, face_pixels};
    let square = |side: f64| TrainingExample {
        name: format!("{side}"),
        image: image::RgbImage::new(1, 1),
        landmarks: facespace::shape::Landmarks {
            points: vec![
                [10.0, 10.0],
                [10.0 + side, 10.0],
                [10.0 + side, 10.0 + side],
                [10.0, 10.0 + side],
                [10.0 + side / 2.0, 10.0 + side / 3.0],
            ],
        },
    };
    assert_eq!(face_pixels(&[square(100.0), square(150.0), square(120.0)]), 14_000);
    assert_eq!(face_pixels(&[square(10.0)]), *FACE_PIXELS.start());
    assert_eq!(face_pixels(&[square(1000.0)]), *FACE_PIXELS.end());
    assert_eq!(face_pixels(&[]), *FACE_PIXELS.start());
}
