//! Recorded mouths (issue 38): the detail kept from a talker's recordings brings the recorded
//! mouth back, the chooser plays recorded runs, and damaged stores are refused.

use std::path::{Path, PathBuf};

use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::codec::{self, EncodeOptions};
use facespace::corpus::{Photometric, Sentence};
use facespace::facespace::Frames;
use facespace::model::FaceModel;
use facespace::mouths::{Chooser, Mouths, Pick};
use facespace::phonemes::{self, PhoneMap};
use facespace::mouths::SampledRenderer;
use facespace::render::{Background, CpuRenderer, DEFAULT_FEATHER, Edge, Renderer};
use facespace::video::Source;
use image::RgbImage;

use crate::common::root;

fn grid_model() -> FaceModel {
    FaceModel::load(&root().join("models/grid/model")).unwrap()
}

/// A committed GRID clip's frames and their tracked face-space points.
pub fn tracked(model: &FaceModel, id: &str) -> (Vec<RgbImage>, Frames) {
    let clip = root().join(format!("tests/data/grid/{id}.mp4"));
    let (mut images, mut rows) = (Vec::new(), Vec::new());
    codec::track(
        model,
        Source::open(&clip).unwrap(),
        &EncodeOptions::default(),
        facespace::no_progress,
        |image, t| {
            rows.extend(model.project(&image, &t.landmarks)?);
            images.push(image);
            Ok(())
        },
    )
    .unwrap();
    (images, Frames::from_rows(model.layout(), 25.0, rows).unwrap())
}

/// A one-sentence codebook of the committed clip `id` in `model`'s space, with the clip's
/// frames and their tracked points.
pub fn codebook_of(model: &FaceModel, id: &str) -> (Codebook, Vec<RgbImage>, Frames) {
    let (images, frames) = tracked(model, id);
    let labels = root().join(format!("tests/data/grid/{id}.lab"));
    let sentence = Sentence {
        name: id.into(),
        source: format!("tests/data/grid/{id}.mp4"),
        frames: frames.clone(),
        segments: phonemes::read_labels(&labels, None, &PhoneMap::default()).unwrap(),
    };
    let codebook = Codebook::from_sentences(
        vec![sentence],
        model,
        25.0,
        SimilarityOptions::default(),
        Photometric::None,
        &mut facespace::no_progress,
    )
    .unwrap();
    (codebook, images, frames)
}

/// Recorded mouths kept from the committed clip `bbbf9a`, in `dir`, with its frames.
fn store(model: &FaceModel, dir: &Path) -> (Mouths, Vec<RgbImage>, Frames) {
    let (codebook, images, frames) = codebook_of(model, "bbbf9a");
    let recordings = root().join("tests/data/grid");
    let mouths = Mouths::build(
        model,
        &codebook,
        |name| Some(recordings.join(format!("{name}.mp4"))).filter(|p| p.is_file()),
        1000,
        dir,
        facespace::no_progress,
    )
    .unwrap();
    (mouths, images, frames)
}

/// Mean absolute difference of two images over the lips' box (iBUG 48–67 of `frames`' frame
/// `t`, 3 px around), every channel.
fn mouth_error(a: &RgbImage, b: &RgbImage, model: &FaceModel, frames: &Frames, t: usize) -> f64 {
    let points = model.landmarks(frames.params(t)).unwrap().points;
    let lips = &points[48..68];
    let x0 = lips.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min) as u32 - 3;
    let x1 = lips.iter().map(|p| p[0]).fold(0.0, f64::max) as u32 + 3;
    let y0 = lips.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min) as u32 - 3;
    let y1 = lips.iter().map(|p| p[1]).fold(0.0, f64::max) as u32 + 3;
    let (mut sum, mut n) = (0.0, 0);
    for y in y0..=y1 {
        for x in x0..=x1 {
            for c in 0..3 {
                sum += (f64::from(a.get_pixel(x, y)[c]) - f64::from(b.get_pixel(x, y)[c])).abs();
                n += 1;
            }
        }
    }
    sum / f64::from(n)
}

/// A clip drawn again from its own tracked points over its own frames: the appearance model's
/// mouth differs from the recording; with the clip's own recorded mouths (each frame's nearest
/// kept frame is itself) the drawn mouth comes back much closer to the recording.
#[test]
fn recorded_detail_brings_back_the_recording() {
    let model = grid_model();
    let dir = tempfile::tempdir().unwrap();
    let (mut mouths, images, frames) = store(&model, dir.path());
    assert_eq!(mouths.len(), frames.len());
    mouths.gain = 1.0;
    let edge = Edge::Articulators(DEFAULT_FEATHER);
    let sampled = SampledRenderer::new(&model, edge, &mouths, &frames);
    // The chooser plays the clip's own frames, in order, from its first.
    for (t, pick) in sampled.picks().iter().enumerate() {
        assert_eq!(pick.frames[0], (t as u32, 1.0), "frame {t}: {pick:?}");
        assert_eq!(pick.frames[1].1, 0.0);
    }
    let pca = CpuRenderer::with_edge(&model, edge);
    let draw = |r: &dyn Renderer| {
        facespace::render::images(
            r,
            &frames,
            Background::Loop {
                frames: images.clone(),
                next: 0,
            },
        )
        .unwrap()
    };
    let (a, b) = (draw(&pca), draw(&sampled));
    let (mut model_error, mut recorded_error) = (0.0, 0.0);
    for t in 0..frames.len() {
        model_error += mouth_error(&a[t], &images[t], &model, &frames, t);
        recorded_error += mouth_error(&b[t], &images[t], &model, &frames, t);
    }
    let n = frames.len() as f64;
    let (model_error, recorded_error) = (model_error / n, recorded_error / n);
    assert!(
        recorded_error < 0.75 * model_error,
        "mouth error: model {model_error:.2}, recorded {recorded_error:.2} grey levels"
    );
}

/// A pick of no weight draws exactly what the model alone draws; the chooser forgets its run
/// on reset, and a face far from any kept frame still gets the nearest.
#[test]
fn picks_without_weight_draw_the_model_face() {
    let model = grid_model();
    let dir = tempfile::tempdir().unwrap();
    let (mouths, images, frames) = store(&model, dir.path());
    let cpu = CpuRenderer::with_edge(&model, Edge::Articulators(DEFAULT_FEATHER));
    let (mut a, mut b) = (images[10].clone(), images[10].clone());
    cpu.render_into(frames.params(10), &mut a).unwrap();
    let none = Pick {
        frames: [(3, 0.0), (7, 0.0)],
    };
    cpu.render_with(frames.params(10), mouths.drawing(&none), &mut b)
        .unwrap();
    assert_eq!(a, b);
    let mut chooser = Chooser::new(&mouths, &model);
    assert_eq!(chooser.next(frames.params(40)).frames[0], (40, 1.0));
    assert_eq!(chooser.next(frames.params(41)).frames[0], (41, 1.0));
    chooser.reset();
    assert_eq!(chooser.next(frames.params(5)).frames[0], (5, 1.0));
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

/// Damaged or foreign stores are refused with the reason, never a panic: a truncated video, a
/// key that is not a number, another model's store, a talker naming a folder that is not there.
#[test]
fn damaged_mouths_are_refused() {
    let model = grid_model();
    let made = tempfile::tempdir().unwrap();
    let _ = store(&model, made.path());
    let case = |name: &str, damage: &dyn Fn(&Path)| -> String {
        let dir: PathBuf = made.path().with_extension(name);
        copy_dir(made.path(), &dir);
        damage(&dir);
        let e = Mouths::load(&dir, &model).expect_err(name).to_string();
        std::fs::remove_dir_all(&dir).unwrap();
        e
    };
    let truncated = case("truncated", &|d| {
        let video = d.join("mouths.mp4");
        let bytes = std::fs::read(&video).unwrap();
        std::fs::write(&video, &bytes[..bytes.len() / 3]).unwrap();
    });
    assert!(truncated.contains("mouths"), "{truncated}");
    let nan = case("nan", &|d| {
        let keys = d.join("keys.npy");
        let a: ndarray::Array2<f32> = facespace::npy::read_checked(&keys, &[None, None]).unwrap();
        let mut a = a;
        a[[2, 3]] = f32::NAN;
        facespace::npy::write(&keys, a.view()).unwrap();
    });
    assert!(nan.contains("not finite"), "{nan}");
    let missing = case("missing", &|d| std::fs::remove_file(d.join("appearance.npy")).unwrap());
    assert!(missing.contains("appearance.npy"), "{missing}");
    // Another model's store.
    let other = FaceModel::load(&root().join("models/demo/model")).unwrap();
    let foreign = Mouths::load(made.path(), &other).unwrap_err().to_string();
    assert!(foreign.contains("made for model"), "{foreign}");
    // A talker whose manifest names a mouths folder that is not there (refused before any
    // part is read).
    let talker = tempfile::tempdir().unwrap();
    let src = root().join("models/grid");
    let mut manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(src.join("talker.json")).unwrap()).unwrap();
    manifest["mouths"] = "gone".into();
    std::fs::write(
        talker.path().join("talker.json"),
        serde_json::to_vec(&manifest).unwrap(),
    )
    .unwrap();
    let e = facespace::talker::Talker::load(talker.path())
        .err()
        .expect("a missing mouths folder is refused")
        .to_string();
    assert!(e.contains("gone") && e.contains("missing"), "{e}");
}

/// The detail is decoded a piece of the video at a time, when a frame of it is first drawn:
/// frames asked for backwards (every piece entered at its end, the last piece first) are the
/// frames asked for forwards, and a store changed after loading is refused, not mixed in.
#[test]
fn detail_decoded_in_any_order_is_the_same_and_a_changed_store_is_refused() {
    let model = grid_model();
    let dir = tempfile::tempdir().unwrap();
    let (built, _, _) = store(&model, dir.path());
    let forwards = Mouths::load(dir.path(), &model).unwrap();
    let backwards = Mouths::load(dir.path(), &model).unwrap();
    let n = forwards.len();
    assert!(n > 50, "{n} frames: more than one piece of the video");
    let ahead: Vec<Vec<i8>> = (0..n).map(|k| forwards.detail(k).unwrap().to_vec()).collect();
    for k in (0..n).rev() {
        assert_eq!(backwards.detail(k).unwrap(), &ahead[k][..], "frame {k}");
    }
    assert!(ahead.iter().flatten().any(|&d| d != 0));
    // The store made again (the same frames, a new file) while `built` still holds the
    // first: what it has decoded stays; what it has not is refused.
    let _ = built.detail(0).unwrap();
    let _ = store(&model, dir.path());
    assert_eq!(built.detail(0).unwrap(), &ahead[0][..]);
    let e = built.detail(n - 1).unwrap_err().to_string();
    assert!(e.contains("changed since"), "{e}");
    assert!(built.detail(n).is_err(), "a frame past the last");
}
