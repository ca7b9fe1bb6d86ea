//! Synthesis on real footage (issue 12): the pose is the background's, never blended; a
//! lower-face region model draws the mouth and leaves the rest of the frame as recorded; the
//! seam is anchored to the background's face; no background is learned into the face.
use crate::common;

use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::codec::{self, EncodeOptions};
use facespace::corpus::Sentence;
use facespace::facespace::Frames;
use facespace::mesh::Region;
use facespace::model::{BuildOptions, FaceModel, load_training_set};
use facespace::phonemes::{self, PhoneMap};
use facespace::render::{self, CpuRenderer, DEFAULT_FEATHER, RenderError, feather_alpha};
use facespace::synth::backdrop::{Backdrop, PoseMode};
use facespace::synth::blend::Blend;
use facespace::synth::{self, Request, Smoothing, synthesise};
use facespace::video::{self, Source};
use facespace::{shape, warp};
use image::RgbImage;

fn demo_model() -> FaceModel {
    FaceModel::load(&common::root().join("models/demo/model")).unwrap()
}

fn lower_face(model: &FaceModel) -> FaceModel {
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    FaceModel::build(
        &frames,
        &BuildOptions {
            pixels: model.frame.n_pixels(),
            region: Some(Region::LowerFace),
            ..BuildOptions::default()
        },
        &mut facespace::no_progress,
    )
    .unwrap()
}

/// Pixels within `reach` pixels (chessboard distance) of the region's mesh at `landmarks`.
fn near_mesh(model: &FaceModel, landmarks: &[[f64; 2]], w: u32, h: u32, reach: i64) -> Vec<bool> {
    let (w, h) = (w as i64, h as i64);
    let covered = facespace::eval::face_mask(model, landmarks, w as u32, h as u32);
    let mut near = vec![false; covered.len()];
    for y in 0..h {
        for x in 0..w {
            if covered[(y * w + x) as usize] {
                for dy in -reach..=reach {
                    for dx in -reach..=reach {
                        let (u, v) = (x + dx, y + dy);
                        if u >= 0 && v >= 0 && u < w && v < h {
                            near[(v * w + u) as usize] = true;
                        }
                    }
                }
            }
        }
    }
    near
}

/// The FGNet clip, tracked and projected through the lower-face model with generated phone
/// labels, is the codebook; the same clip is the background. Every output frame's pose is the
/// background frame's, and outside the region's mesh the output is the background frame,
/// pixel for pixel.
#[test]
fn region_synthesis_over_a_real_clip_keeps_the_background() {
    let model = demo_model();
    let region = lower_face(&model);
    let clip = common::root().join("tests/data/clip");
    let options = EncodeOptions {
        init: Some(shape::read_pts(&clip.join("01000.pts")).unwrap()),
        ..EncodeOptions::default()
    };
    let (landmarks, _) = codec::track_landmarks(
        &model,
        Source::open(&clip).unwrap(),
        &options,
        facespace::no_progress,
    )
    .unwrap();
    let images: Vec<RgbImage> = video::frame_files(&clip)
        .unwrap()
        .iter()
        .map(|f| video::read_frame(f).unwrap())
        .collect();
    let rows: Vec<f32> = images
        .iter()
        .zip(&landmarks)
        .flat_map(|(image, l)| region.project(image, l).unwrap())
        .collect();
    let labels = common::root().join("tests/data/labels/clip.lab");
    let phones = phonemes::read_labels(&labels, None, &PhoneMap::default()).unwrap();
    let sentence = Sentence {
        name: "clip".into(),
        source: "tests/data/clip".into(),
        frames: Frames::from_rows(region.layout(), 25.0, rows).unwrap(),
        segments: phones.clone(),
    };
    let cb = Codebook::build(
        vec![sentence],
        25.0,
        region.layout(),
        Some(region.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    // Half a second of silence more than the clip: the background loops back.
    let mut target = phones.clone();
    target.push(facespace::phonemes::Segment {
        start: 2.0,
        end: 2.5,
        phone: facespace::phonemes::Phone::SIL,
    });
    let n = synth::frame_count(&target, 25.0);
    let backdrop = Backdrop::video(
        &model,
        &clip,
        PoseMode::Replay,
        n,
        &options,
        facespace::no_progress,
    )
    .unwrap();
    let poses = match &backdrop.pose {
        synth::Pose::Replay(p) => p.clone(),
        other => panic!("{other:?}"),
    };
    let request = Request {
        pose: backdrop.pose.clone(),
        ..Request::new(target, 25.0, Smoothing::On(synth::DEFAULT_SMOOTHING))
    };
    let mut utterance = synthesise(&Blend::default(), &cb, request).unwrap();
    assert!(backdrop.anchor_region(&region, &mut utterance).unwrap());
    let frames = utterance.smoothed.as_ref().unwrap();
    assert_eq!(frames.len(), n);
    // The utterance is longer than the clip: the clip is extended as footage is, never
    // played backwards — each frame follows the one before, or a dissolve joins stretches.
    assert!(n > images.len());
    let plan = backdrop.plan.clone().expect("a short background is planned as footage");
    assert_eq!(poses.len(), n);
    assert!(!plan.joins.is_empty());
    for t in 1..n {
        assert!(
            plan.frames[t] == plan.frames[t - 1] + 1 || plan.joins.contains(&t) || plan.mix[t - 1].is_some(),
            "frame {t}: {} after {}",
            plan.frames[t],
            plan.frames[t - 1]
        );
    }
    for (t, p) in frames.iter().enumerate() {
        let stored = poses[t].to_array().map(|v| v as f32 as f64);
        assert_eq!(p.pose.to_array(), stored, "frame {t}: pose");
    }
    let mut out = Vec::new();
    render::stream(
        &CpuRenderer::feathered(&region, DEFAULT_FEATHER),
        frames,
        backdrop.background().unwrap(),
        |image| {
            out.push(image);
            Ok::<_, RenderError>(())
        },
        facespace::no_progress,
    )
    .unwrap();
    let mut changed_inside = 0;
    for (t, image) in out.iter().enumerate() {
        if !plan.is_pure(t) {
            continue;
        }
        let bg = &images[plan.frames[t]];
        let l = region.landmarks(frames.params(t)).unwrap().points;
        let near = near_mesh(&region, &l, image.width(), image.height(), 2);
        for ((a, b), near) in image.pixels().zip(bg.pixels()).zip(&near) {
            if !near {
                assert_eq!(a, b, "frame {t}: a pixel away from the region changed");
            } else if a != b {
                changed_inside += 1;
            }
        }
        // The eyes are the background's: no eye landmark lies inside the region.
        let covered = facespace::eval::face_mask(&region, &l, image.width(), image.height());
        for (eye, p) in l.iter().enumerate().skip(36).take(12) {
            let [x, y] = p.map(|v| v.round() as i64);
            assert!(
                !covered[(y * image.width() as i64 + x) as usize],
                "eye landmark {eye}"
            );
        }
    }
    assert!(
        changed_inside > 1000,
        "the region is drawn: {changed_inside}"
    );
}

/// Demo frames: where the face model is drawn at full weight (alpha 1 after the feather),
/// no pixel has the blue of the video's background (B > R: skin is always redder than blue) —
/// the full-face model drew a blue-violet streak down the left cheek there.
#[test]
fn demo_frames_show_no_background_inside_the_face() {
    let dir = tempfile::tempdir().unwrap();
    let options = facespace::demo::DemoOptions {
        output: dir.path().join("demo"),
        talker: facespace::demo::Talker::Fgnet,
        ..Default::default()
    };
    facespace::demo::run(&options, facespace::no_progress).unwrap();
    let out = dir.path().join("demo");
    let region = FaceModel::load(&out.join("model")).unwrap();
    let alpha = feather_alpha(&region, DEFAULT_FEATHER);
    let texture: Vec<f32> = alpha.iter().flat_map(|a| [255.0 * a; 3]).collect();
    let landmarks = facespace::npy::read::<f32>(&out.join("smoothed/landmarks.npy")).unwrap();
    let frames = video::frame_files(&out.join("smoothed/frames")).unwrap();
    let (mut full, mut bluest) = (0, i32::MIN);
    for (t, f) in frames.iter().enumerate() {
        let image = video::read_frame(f).unwrap();
        let points: Vec<[f64; 2]> = (0..68)
            .map(|k| [landmarks[[t, k, 0]] as f64, landmarks[[t, k, 1]] as f64])
            .collect();
        let mut weight = RgbImage::new(image.width(), image.height());
        warp::from_reference_into(&region.frame, &texture, &points, &mut weight).unwrap();
        for (p, w) in image.pixels().zip(weight.pixels()) {
            if w.0[0] == 255 {
                full += 1;
                bluest = bluest.max(i32::from(p.0[2]) - i32::from(p.0[0]));
                assert!(
                    p.0[2] <= p.0[0],
                    "frame {t}: a bluish pixel {:?} inside the face",
                    p.0
                );
            }
        }
    }
    eprintln!("{full} fully drawn pixels; largest B − R among them {bluest}");
    assert!(full > 1000 * frames.len(), "{full} fully drawn pixels");
}

/// At a held pose over a still frame, the lower-face model anchored to the background's face
/// keeps the face outline still: no jaw landmark strays 2 px from its mean over the utterance
/// (the whole-face synthesis slid it by ~5 px: head turns the corpus carries in the shape).
#[test]
fn jaw_outline_holds_still_at_a_held_pose() {
    let model = demo_model();
    let region = lower_face(&model);
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let generated = facespace::corpus::demo::generate(
        &region,
        &frames,
        &facespace::corpus::demo::CorpusOptions::default(),
    )
    .unwrap();
    let cb = Codebook::build(
        generated.part(facespace::corpus::demo::Split::Train),
        25.0,
        region.layout(),
        Some(region.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let still = dir.path().join("still.png");
    frames[generated.still_frame].image.save(&still).unwrap();
    let backdrop = Backdrop::still(&model, &still).unwrap();
    let target =
        phonemes::text_to_segments(facespace::demo::DEMO_TEXT, &cb.mean_durations()).unwrap();
    let request = Request {
        pose: backdrop.pose.clone(),
        ..Request::new(target, 25.0, Smoothing::On(synth::DEFAULT_SMOOTHING))
    };
    let mut utterance = synthesise(&Blend::default(), &cb, request).unwrap();
    let outline = |u: &synth::Utterance| -> f64 {
        let frames = u.smoothed.as_ref().unwrap();
        let l: Vec<Vec<[f64; 2]>> = frames
            .iter()
            .map(|p| region.landmarks(p).unwrap().points)
            .collect();
        (0..17)
            .map(|k| {
                let n = l.len() as f64;
                let m = l
                    .iter()
                    .fold([0.0, 0.0], |a, p| [a[0] + p[k][0] / n, a[1] + p[k][1] / n]);
                l.iter()
                    .map(|p| (p[k][0] - m[0]).hypot(p[k][1] - m[1]))
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max)
    };
    let unanchored = outline(&utterance);
    assert!(backdrop.anchor_region(&region, &mut utterance).unwrap());
    let anchored = outline(&utterance);
    eprintln!("jaw outline strays {unanchored:.2} px unanchored, {anchored:.2} px anchored");
    assert!(anchored < 2.0, "{anchored} px");
}

/// Issue 26, item 1: a region model carries the whole-face model it was cut from and tracks
/// with it — the committed GRID lower-face model follows his face on a test recording as his
/// full model does (none lost), through `track` and `corpus from-videos` alike, with no
/// `--track-model`; the tracker survives a save and load.
#[test]
fn region_models_track_with_the_whole_face_they_were_cut_from() {
    let root = common::root();
    let lower = FaceModel::load(&root.join("models/grid/lower")).unwrap();
    let full = FaceModel::load(&root.join("models/grid/model")).unwrap();
    let tracker = lower
        .tracker
        .as_deref()
        .expect("the region model carries its tracker");
    assert!(tracker.region.is_none());
    assert_eq!(tracker.hash(), full.hash(), "the tracker is his full model");
    let clip = root.join("tests/data/grid/bbbf9a.mp4");
    let track = |model: &FaceModel| {
        codec::track_landmarks(
            model,
            Source::open(&clip).unwrap(),
            &EncodeOptions::default(),
            facespace::no_progress,
        )
        .unwrap()
    };
    let ((by_region, tracking), (by_full, _)) = (track(&lower), track(&full));
    assert!(tracking.iter().all(|t| !t.lost), "a frame was lost");
    let worst = by_region
        .iter()
        .zip(&by_full)
        .flat_map(|(a, b)| a.points.iter().zip(&b.points))
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0f64, f64::max);
    assert!(
        worst < 1e-6,
        "the region tracks {worst} px from the full model"
    );
    // Saved and loaded, it still tracks with it.
    let dir = tempfile::tempdir().unwrap();
    lower.save(&dir.path().join("lower")).unwrap();
    let again = FaceModel::load(&dir.path().join("lower")).unwrap();
    assert_eq!(
        again.tracker.as_deref().map(FaceModel::hash),
        Some(full.hash())
    );
    // A corpus of region-model trajectories from a recording.
    let recordings = dir.path().join("recordings");
    std::fs::create_dir(&recordings).unwrap();
    std::fs::copy(&clip, recordings.join("bbbf9a.mp4")).unwrap();
    std::fs::copy(
        root.join("tests/data/grid/bbbf9a.lab"),
        recordings.join("bbbf9a.lab"),
    )
    .unwrap();
    let corpus = dir.path().join("corpus");
    let s = |p: &std::path::Path| p.to_str().unwrap().to_owned();
    let o = common::facespace(&[
        "corpus",
        "from-videos",
        "--model",
        &s(&root.join("models/grid/lower")),
        &s(&recordings),
        "-o",
        &s(&corpus),
    ]);
    assert!(o.status.success(), "{}", common::text(&o));
    let values: ndarray::ArrayD<f32> = facespace::npy::read(&corpus.join("bbbf9a.npy")).unwrap();
    assert_eq!(values.shape()[1], lower.layout().dims());
    assert!(values.iter().all(|v| v.is_finite()));
}
