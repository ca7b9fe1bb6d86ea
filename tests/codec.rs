//! Video through face-space: encode → clip folder → decode, on synthetic frames with exact
//! ground truth and on the real clip; the file format's checks; the CLI.
use crate::common;

use common::Params;
use facespace::codec::{self, Clip, CodecError, EncodeOptions};
use facespace::eval;
use facespace::model::FaceModel;
use facespace::render::{Background, CpuRenderer};
use facespace::shape::Landmarks;
use facespace::video::{Sink, Source};
use image::{Rgb, RgbImage};
use serde_json::Value;

fn demo_model() -> FaceModel {
    FaceModel::load(&common::root().join("models/demo/model")).unwrap()
}

/// `n` frames rendered from known parameters moving smoothly (shape within ±1.5σ, appearance
/// within ±1σ, a slow drift of the head) on a plain background: (frames, truth rows,
/// landmarks of frame 0).
fn synthetic_sequence(model: &FaceModel, n: usize) -> (Vec<RgbImage>, Vec<Vec<f32>>, Landmarks) {
    let mut rng = common::Rng::new(7);
    let sd = |v: &[f32]| -> Vec<f64> { v.iter().map(|x| (*x as f64).sqrt()).collect() };
    let (ss, sa) = (
        sd(&model.shape.pca.variances),
        sd(&model.appearance.pca.variances),
    );
    let phase: Vec<f64> = (0..ss.len() + sa.len())
        .map(|_| rng.range(0.0, std::f64::consts::TAU))
        .collect();
    let base = model
        .shape
        .project(
            &facespace::shape::read_pts(&common::root().join("tests/data/clip/01000.pts")).unwrap(),
        )
        .unwrap()
        .0;
    let (mut frames, mut truth, mut first) = (Vec::new(), Vec::new(), None);
    for i in 0..n {
        let t = i as f64 / n as f64 * std::f64::consts::TAU;
        let wave = |k: usize, amp: f64| (amp * (t + phase[k]).sin()) as f32;
        let mut pose = base;
        pose.tx += 4.0 * t.sin();
        pose.ty += 2.0 * t.cos();
        let params = Params {
            pose,
            shape: ss
                .iter()
                .enumerate()
                .map(|(k, s)| wave(k, 1.5 * s))
                .collect(),
            appearance: sa
                .iter()
                .enumerate()
                .map(|(k, s)| wave(ss.len() + k, 1.0 * s))
                .collect(),
        };
        let mut img = RgbImage::from_pixel(360, 288, Rgb([40, 90, 210]));
        common::render(model, &params, &mut img);
        first.get_or_insert(model.landmarks(params.view()).unwrap());
        truth.push(params.to_vector());
        frames.push(img);
    }
    (frames, truth, first.unwrap())
}

fn write_frames(dir: &std::path::Path, frames: &[RgbImage]) {
    let mut sink = Sink::create(dir, 360, 288, 25.0, None).unwrap();
    for f in frames {
        sink.write(f).unwrap();
    }
    sink.finish().unwrap();
}

#[test]
fn synthetic_round_trip_recovers_the_parameters() {
    let model = demo_model();
    let (frames, truth, first) = synthetic_sequence(&model, 24);
    let dir = tempfile::tempdir().unwrap();
    write_frames(&dir.path().join("frames"), &frames);
    // With the alternating refinement: project-out alone settles up to 0.5σ off in the
    // frames whose appearance is far from the mean (BENCHMARKS.md).
    let options = EncodeOptions {
        init: Some(first),
        fit: facespace::fit::FitOptions {
            refine_iterations: 10,
            ..Default::default()
        },
        ..EncodeOptions::default()
    };
    let source = Source::open(&dir.path().join("frames")).unwrap();
    let clip = codec::encode(&model, source, &options, facespace::no_progress)
        .unwrap()
        .clip;
    assert_eq!(clip.frames.len(), 24);
    let sd = model.standard_deviations();
    let ns = model.shape.n_params();
    let (mut worst_shape, mut worst_app) = (0.0f64, 0.0f64);
    let mut shape_errors = Vec::new();
    for (i, row) in truth.iter().enumerate() {
        for (k, (a, b)) in clip.frames.row(i).iter().zip(row).enumerate().skip(4) {
            let e = ((a - b) as f64).abs() / sd[k - 4];
            if k - 4 < ns {
                worst_shape = worst_shape.max(e);
                shape_errors.push(e);
            } else {
                worst_app = worst_app.max(e);
            }
        }
    }
    // Decode onto the same plain background and compare inside the face.
    let mut sink = Sink::create(&dir.path().join("decoded"), 360, 288, 25.0, None).unwrap();
    codec::decode(
        &CpuRenderer::new(&model),
        &clip,
        Background::Plain {
            width: 360,
            height: 288,
        },
        &mut sink,
        facespace::no_progress,
    )
    .unwrap();
    sink.finish().unwrap();
    let decoded: Vec<RgbImage> = Source::open(&dir.path().join("decoded"))
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    let psnr: Vec<f64> = decoded
        .iter()
        .zip(&frames)
        .enumerate()
        .map(|(i, (d, f))| {
            let p = model.layout().split(&truth[i]).unwrap();
            let l = model.landmarks(p).unwrap();
            eval::psnr_masked(d, f, &eval::face_mask(&model, &l.points, 360, 288))
        })
        .collect();
    let min_psnr = psnr.iter().cloned().fold(f64::INFINITY, f64::min);
    println!(
        "max error: shape {worst_shape:.2e} σ, appearance {worst_app:.2e} σ; PSNR min {min_psnr:.2} dB"
    );
    shape_errors.sort_by(f64::total_cmp);
    let median = shape_errors[shape_errors.len() / 2];
    println!("shape error median {median:.2e} σ");
    // 40 dB before the demo model was rebuilt with its rim left out (issue 25): the rebuilt
    // model has one appearance component fewer and frames 16–20 now reach 39.8 dB.
    assert!(min_psnr >= 39.0, "PSNR {psnr:?}");
    // Measured: median 0.012σ, worst 0.086σ (shape) / 0.66σ (appearance: the smallest-variance
    // components, where resampling twice is a large fraction of σ). The 1e-3σ is not
    // reached: see BENCHMARKS.md.
    assert!(median < 0.03, "median shape error {median} σ");
    // With the rebuilt demo model (rim left out): worst 0.13σ shape, 1.14σ appearance.
    assert!(worst_shape < 0.2 && worst_app < 1.5);
}

#[test]
fn ssim_and_psnr_match_scikit_image() {
    let v: Value = serde_json::from_str(
        &std::fs::read_to_string(common::root().join("tests/data/ssim_skimage.json")).unwrap(),
    )
    .unwrap();
    let (w, h) = (
        v["width"].as_u64().unwrap() as u32,
        v["height"].as_u64().unwrap() as u32,
    );
    let image = |k: &str| {
        let bytes: Vec<u8> = v[k]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap() as u8)
            .collect();
        RgbImage::from_raw(w, h, bytes).unwrap()
    };
    let (a, b) = (image("a"), image("b"));
    let mask: Vec<bool> = v["mask"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64() == Some(1))
        .collect();
    let ssim = eval::ssim_masked(&a, &b, &mask);
    assert!((ssim - v["ssim"].as_f64().unwrap()).abs() < 1e-9, "{ssim}");
    let psnr = eval::psnr_masked(&a, &b, &mask);
    assert!((psnr - v["psnr"].as_f64().unwrap()).abs() < 1e-9, "{psnr}");
    // scikit-image's scalar SSIM averages the map without a 3-pixel border.
    let inner: Vec<bool> = (0..(w * h))
        .map(|i| {
            let (x, y) = (i % w, i / w);
            x >= 3 && y >= 3 && x + 3 < w && y + 3 < h
        })
        .collect();
    let whole = eval::ssim_masked(&a, &b, &inner);
    assert!(
        (whole - v["ssim_unmasked"].as_f64().unwrap()).abs() < 1e-9,
        "{whole}"
    );
    assert_eq!(eval::ssim_masked(&a, &a, &mask), 1.0);
}

fn encoded_clip(model: &FaceModel) -> Clip {
    let (frames, _, first) = synthetic_sequence(model, 6);
    let dir = tempfile::tempdir().unwrap();
    write_frames(&dir.path().join("frames"), &frames);
    let options = EncodeOptions {
        init: Some(first),
        ..EncodeOptions::default()
    };
    let source = Source::open(&dir.path().join("frames")).unwrap();
    codec::encode(model, source, &options, facespace::no_progress)
        .unwrap()
        .clip
}

#[test]
fn clip_folders_round_trip_quantise_and_refuse_other_models() {
    let model = demo_model();
    let clip = encoded_clip(&model);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("clip.fsp");
    clip.save(&path, None).unwrap();
    let back = Clip::load(&path, &model).unwrap();
    assert!(
        back.frames == clip.frames,
        "float32 parameters load exactly"
    );
    // The tracking record is stored compactly: residuals to 0.01 grey level, flags exact,
    // the pose taken from the parameters (f32).
    assert_tracking_close(&back, &clip);
    assert!(
        Clip {
            tracking: clip.tracking.clone(),
            ..back.clone()
        } == clip
    );
    // A version-1 folder (tracking in meta.json) still loads, its record as written.
    let v1 = dir.path().join("v1.fsp");
    clip.save(&v1, None).unwrap();
    let mut meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(v1.join("meta.json")).unwrap()).unwrap();
    meta["version"] = 1.into();
    meta["tracking"] = serde_json::to_value(&clip.tracking).unwrap();
    std::fs::write(v1.join("meta.json"), meta.to_string()).unwrap();
    std::fs::remove_file(v1.join("tracking.npy")).unwrap();
    assert!(Clip::load(&v1, &model).unwrap() == clip);
    // A version-2 folder without its tracking record is an error naming the file.
    std::fs::remove_file(path.join("tracking.npy")).unwrap();
    let err = Clip::load(&path, &model).unwrap_err().to_string();
    assert!(err.contains("tracking.npy"), "{err}");
    clip.save(&path, None).unwrap();
    for bits in [16, 8] {
        let q = clip.quantised(bits).unwrap();
        let table = q.quantisation.clone().unwrap();
        let dims = clip.frames.layout().dims();
        for (i, (a, b)) in q
            .frames
            .as_slice()
            .iter()
            .zip(clip.frames.as_slice())
            .enumerate()
        {
            let step = (table.max[i % dims] - table.min[i % dims]) / ((1u32 << bits) - 1) as f32;
            assert!(
                (a - b).abs() <= step / 2.0 + 1e-6 * b.abs().max(1.0),
                "{bits} bits, value {i}"
            );
        }
        assert_eq!(
            q.stream_bytes(),
            clip.frames.as_slice().len() * bits as usize / 8 + 8 * dims
        );
        q.save(&path, None).unwrap();
        assert!(path.join(format!("params_u{bits}.npy")).is_file());
        let loaded = Clip::load(&path, &model).unwrap();
        for (a, b) in loaded.frames.as_slice().iter().zip(q.frames.as_slice()) {
            assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0));
        }
    }
    assert!(matches!(clip.quantised(12), Err(CodecError::Bits(12))));
    // Another model: refused by hash.
    let err = Clip::load(&path, &common::small_model()).unwrap_err();
    assert!(matches!(err, CodecError::HashMismatch { .. }), "{err}");
    // A damaged parameter file: a clear error naming it.
    clip.save(&path, None).unwrap();
    let npy = path.join("params.npy");
    let bytes = std::fs::read(&npy).unwrap();
    std::fs::write(&npy, &bytes[..bytes.len() - 10]).unwrap();
    let err = Clip::load(&path, &model).unwrap_err().to_string();
    assert!(err.contains("params.npy"), "{err}");
    // A folder of something else is never replaced.
    let other = dir.path().join("other");
    std::fs::create_dir(&other).unwrap();
    std::fs::write(other.join("keep.txt"), "mine").unwrap();
    assert!(clip.save(&other, None).is_err());
    assert!(other.join("keep.txt").is_file());
}

fn assert_tracking_close(a: &Clip, b: &Clip) {
    assert_eq!(a.tracking.len(), b.tracking.len());
    for (x, y) in a.tracking.iter().zip(&b.tracking) {
        assert_eq!((x.reinitialised, x.lost), (y.reinitialised, y.lost));
        assert!(
            (x.fit_error - y.fit_error).abs() <= 0.005 + 1e-9,
            "{x:?} vs {y:?}"
        );
        for (p, q) in x.pose.iter().zip(&y.pose) {
            assert!((p - q).abs() <= 1e-6 * q.abs().max(1.0), "{x:?} vs {y:?}");
        }
    }
}

fn cli(args: &[&str]) -> String {
    let out = common::facespace(args);
    let text = common::text(&out);
    assert!(out.status.success(), "{args:?}: {text}");
    text
}

/// The real clip (50 frames of the talking-face video) through encode → decode →
/// codec-report. Measured: PSNR mean 29.7 dB, SSIM mean 0.819 inside the face.
#[test]
fn real_clip_through_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    let frames = common::root().join("tests/data/clip");
    let frames = frames.to_str().unwrap();
    let init = format!("{frames}/01000.pts");
    let text = cli(&[
        "encode",
        frames,
        "--fps",
        "24",
        "--init",
        &init,
        "--bits",
        "16",
        "-o",
        &p("clip.fsp"),
    ]);
    assert!(text.contains("50 frames"), "{text}");
    cli(&[
        "decode",
        &p("clip.fsp"),
        "--background",
        frames,
        "-o",
        &p("out.mp4"),
    ]);
    let source = Source::open(&dir.path().join("out.mp4")).unwrap();
    assert_eq!(source.info().frames, Some(50));
    assert!((source.info().fps - 24.0).abs() < 1e-6);
    cli(&[
        "codec-report",
        frames,
        &p("clip.fsp"),
        "-o",
        &p("report.json"),
    ]);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(p("report.json")).unwrap()).unwrap();
    let (psnr, ssim) = (
        report["psnr"]["mean"].as_f64().unwrap(),
        report["ssim"]["mean"].as_f64().unwrap(),
    );
    println!("real clip: PSNR {psnr:.2} dB, SSIM {ssim:.4}");
    // 28.5 dB / 0.78 with the stale demo model, which had learned the blue backdrop at the
    // face's rim and so reproduced this clip's backdrop inside the mesh; the rebuilt one draws
    // face there (25.7 dB / 0.777 measured, BENCHMARKS.md "Stale models").
    assert!(psnr > 25.0 && ssim > 0.76, "{report}");
    assert_eq!(report["frames"], 50);
    assert!(report["compression_ratio"].as_f64().unwrap() > 50.0);
    // The honest size: the whole folder on disk, more than the parameters alone.
    let on_disk = report["clip_bytes_per_frame"].as_f64().unwrap();
    assert!(on_disk > report["params_bytes_per_frame"].as_f64().unwrap());
    assert!(
        (on_disk * 50.0 - Clip::disk_bytes(&dir.path().join("clip.fsp")).unwrap() as f64).abs()
            < 1.0
    );
    assert!(dir.path().join("report.png").is_file());
    // The clip was encoded with the demo model; any other is refused, and nothing written.
    let faces = common::root().join("models/faces/training");
    cli(&[
        "model",
        "build",
        "--images",
        faces.to_str().unwrap(),
        "--pixels",
        "6000",
        "-o",
        &p("other"),
    ]);
    let out = common::facespace(&[
        "decode",
        "--model",
        &p("other"),
        &p("clip.fsp"),
        "-o",
        &p("bad.mp4"),
    ]);
    assert!(!out.status.success());
    assert!(
        common::text(&out).contains("encoded with model"),
        "{}",
        common::text(&out)
    );
    assert!(!dir.path().join("bad.mp4").exists());
    // No frames to encode.
    std::fs::create_dir(p("empty")).unwrap();
    let out = common::facespace(&["encode", &p("empty"), "-o", &p("e.fsp")]);
    assert!(!out.status.success() && common::text(&out).contains("no frames"));
    assert!(!dir.path().join("e.fsp").exists());
}
