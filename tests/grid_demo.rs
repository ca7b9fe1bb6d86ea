//! The GRID talker as the demo (issue 22): the committed codebook belongs to his model and
//! holds no test sentence; the demo speaks with the recording's own sound, beside the real
//! recording; synthesis from a per-sentence re-centred codebook is re-lit to the take it is
//! drawn over.

use crate::common;

use std::path::{Path, PathBuf};

use facespace::codebook::Codebook;
use facespace::codec::EncodeOptions;
use facespace::corpus::Photometric;
use facespace::model::FaceModel;
use facespace::phonemes::{self, PhoneMap};
use facespace::synth::backdrop::{Backdrop, PoseMode};
use facespace::synth::blend::Blend;
use facespace::synth::{self, Request, Smoothing, synthesise};
use facespace::video::Source;

const TEST_CLIPS: [&str; 3] = ["bbbf9a", "bbbs7a", "bbwtzp"];

fn grid(name: &str) -> PathBuf {
    common::root().join("tests/data/grid").join(name)
}

#[test]
fn the_committed_codebook_is_his_training_split_only() {
    let model = FaceModel::load(&facespace::demo::grid_model()).unwrap();
    let cb = Codebook::load(&facespace::demo::grid_codebook()).unwrap();
    cb.check_model(&model).unwrap();
    assert_eq!(cb.photometric, Photometric::Sentence);
    assert_eq!(
        cb.sentences.len(),
        741,
        "750 training clips less the 9 damaged"
    );
    for s in &cb.sentences {
        assert!(
            !TEST_CLIPS.contains(&s.name.as_str()),
            "test sentence {} in the codebook",
            s.name
        );
    }
}

/// Mean of column `k` of a trajectory.
fn column_mean(frames: &facespace::facespace::Frames, k: usize) -> f64 {
    let v = frames.values();
    v.column(k).iter().map(|&x| f64::from(x)).sum::<f64>() / v.nrows() as f64
}

/// Re-lighting moves the synthesis's lighting parameter (b_a1, the between-session drift)
/// towards the take it is drawn over, on every committed test clip; a codebook that was not
/// re-centred is left alone.
/// A test clip's phone labels, frame rate and the clip tracked as a replayed backdrop.
fn take(model: &FaceModel, name: &str) -> (Vec<phonemes::Segment>, f64, Backdrop) {
    let clip = grid(&format!("{name}.mp4"));
    let target =
        phonemes::read_labels(&grid(&format!("{name}.lab")), None, &PhoneMap::default()).unwrap();
    let fps = Source::open(&clip).unwrap().info().fps;
    let backdrop = Backdrop::video(
        model,
        &clip,
        PoseMode::Replay,
        synth::frame_count(&target, fps),
        &EncodeOptions::default(),
        facespace::no_progress,
    )
    .unwrap();
    (target, fps, backdrop)
}

#[test]
fn synthesis_is_relit_to_the_take_it_is_drawn_over() {
    let model = FaceModel::load(&facespace::demo::grid_model()).unwrap();
    let cb = Codebook::load(&facespace::demo::grid_codebook()).unwrap();
    let a1 = model.layout().appearance_range().start;
    let talker = common::root().join("models/grid");
    let settings = facespace::talker::Talker::load(&talker).unwrap().manifest.settings;
    for name in TEST_CLIPS {
        let (target, fps, backdrop) = take(&model, name);
        let request = Request {
            pose: backdrop.pose.clone(),
            ..Request::new(target, fps, Smoothing::On(settings.smoothing))
        };
        let blend = Blend {
            top_n: settings.top_n,
            ..Blend::default()
        };
        let mut utterance = synthesise(&blend, &cb, request).unwrap();
        let real = column_mean(&backdrop.tracked, a1);
        let before = column_mean(utterance.smoothed.as_ref().unwrap(), a1);
        let mut plain = utterance.clone();
        assert!(backdrop.match_lighting(&model, &cb, &mut utterance));
        let after = column_mean(utterance.smoothed.as_ref().unwrap(), a1);
        // The shift is exactly (take's mean − codebook's mean) …
        let shift = real - cb.appearance_mean()[0];
        assert!(
            (after - before - shift).abs() < 1e-3 * (1.0 + shift.abs()),
            "{name}: moved {} instead of {shift}",
            after - before
        );
        // … and brings the lighting nearer the real take's.
        eprintln!("{name}: b_a1 real {real:.1}, synthesised {before:.1} → re-lit {after:.1}");
        assert!(
            (after - real).abs() < (before - real).abs(),
            "{name}: b_a1 real {real:.1}, synthesised {before:.1}, re-lit {after:.1}"
        );
        let untouched = Codebook {
            photometric: Photometric::None,
            ..cb.clone()
        };
        assert!(!backdrop.match_lighting(&model, &untouched, &mut plain));
        let still = column_mean(plain.smoothed.as_ref().unwrap(), a1);
        assert_eq!(still, before);
    }
}

/// Mean absolute difference of two equally sized images.
fn mean_abs_diff(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    a.as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).abs())
        .sum::<f64>()
        / a.as_raw().len() as f64
}

fn half(image: &image::RgbImage, right: bool) -> image::RgbImage {
    let w = image.width() / 2;
    image::imageops::crop_imm(image, if right { w } else { 0 }, 0, w, image.height()).to_image()
}

/// `facespace demo` (GRID, the default): every promised file; `beside_background.mp4` is the
/// real recording (left, as recorded) beside the synthesis drawn over it (right, different
/// inside the face, the same outside it), both with the recording's sound for its length.
#[test]
fn the_demo_speaks_beside_the_real_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let o = common::facespace(&["demo", "--renderer", "cpu", "-o", out.to_str().unwrap()]);
    let t = common::text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("741 recorded GRID s1 training sentences") && t.contains("re-lit"),
        "{t}"
    );
    for f in [
        "beside_background.mp4",
        "smoothed/video.mp4",
        "unsmoothed/video.mp4",
        "side_by_side.mp4",
        "key.json",
        "plot.png",
        "utterance.TextGrid",
        "utterance.lab",
        "unit/smoothed/video.mp4",
        "unit/beside_background.mp4",
        "unit/report.json",
        "say.mp4",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    // The talker's own blend, as `say` draws it: its appearance gain included (issue 68).
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["method"], "blend C=1 N=12, appearance ×1.15");
    let grid_words = std::fs::read_to_string(out.join("utterance.TextGrid")).unwrap();
    assert!(grid_words.contains("\"bin\"") && grid_words.contains("\"again\""));
    let clip = facespace::demo::grid_clip();
    let recorded: Vec<_> = Source::open(&clip).unwrap().map(|f| f.unwrap()).collect();
    let beside: Vec<_> = Source::open(&out.join("beside_background.mp4"))
        .unwrap()
        .map(|f| f.unwrap())
        .collect();
    assert_eq!(beside.len(), recorded.len());
    let synthesised: Vec<_> = facespace::video::frame_files(&out.join("smoothed/frames"))
        .unwrap()
        .iter()
        .map(|f| facespace::video::read_frame(f).unwrap())
        .collect();
    assert_eq!(synthesised.len(), recorded.len());
    // The demo's blend is `say`'s pipeline (issue 68): the same recording and words drawn by
    // the talker over the same take give the demo's smoothed frames, pixel for pixel.
    let talker = facespace::talker::Talker::load(&common::root().join("models/grid")).unwrap();
    let words = std::fs::read_to_string(clip.with_extension("txt")).unwrap();
    let request = facespace::talker::SayRequest {
        canvas: facespace::talker::Canvas::Video { path: clip.clone(), pose: PoseMode::Replay },
        renderer: facespace::render::RendererChoice::Cpu,
        ..facespace::talker::SayRequest::new(facespace::talker::Speech::Recording {
            audio: clip.clone(),
            words: words.trim().to_owned(),
        })
    };
    let said = tmp.path().join("said");
    let (report, _) = talker.say_parts(&request, &said, facespace::no_progress).unwrap();
    assert!(report.renderer.contains("recorded"), "{}", report.renderer);
    let frames = facespace::video::frame_files(&said.join("frames")).unwrap();
    assert_eq!(frames.len(), synthesised.len());
    for (t, (f, s)) in frames.iter().zip(&synthesised).enumerate() {
        assert!(facespace::video::read_frame(f).unwrap() == *s, "frame {t} differs from say's");
    }
    // Over the face: each half is nearer its own source than the other half is (both
    // halves went through one more encoding, which alone costs 2–3 grey levels).
    let face = |i: &image::RgbImage| image::imageops::crop_imm(i, 110, 100, 140, 150).to_image();
    let (mut left_real, mut right_real, mut left_synth, mut right_synth) = (0.0, 0.0, 0.0, 0.0);
    for ((b, r), s) in beside.iter().zip(&recorded).zip(&synthesised) {
        assert_eq!((b.width(), b.height()), (2 * r.width(), r.height()));
        let (l, rt) = (face(&half(b, false)), face(&half(b, true)));
        left_real += mean_abs_diff(&l, &face(r));
        right_real += mean_abs_diff(&rt, &face(r));
        left_synth += mean_abs_diff(&l, &face(s));
        right_synth += mean_abs_diff(&rt, &face(s));
    }
    eprintln!(
        "face |Δ| summed over frames: left–recorded {left_real:.0}, right–recorded {right_real:.0}, left–synthesised {left_synth:.0}, right–synthesised {right_synth:.0}"
    );
    assert!(left_real < right_real, "the left half is not the recording");
    assert!(
        right_synth < left_synth,
        "the right half is not the synthesis"
    );
    // The sound is the recording's, for its whole length.
    for video in [
        "beside_background.mp4",
        "smoothed/video.mp4",
        "side_by_side.mp4",
        "say.mp4",
    ] {
        let sound = facespace::audio::read(&out.join(video), 16_000, 60.0).unwrap();
        let source = facespace::audio::read(&clip, 16_000, 60.0).unwrap();
        assert!(
            (sound.seconds() - source.seconds()).abs() < 0.05,
            "{video}: {:.3} s of sound, the recording has {:.3}",
            sound.seconds(),
            source.seconds()
        );
        let rms = |s: &[f32]| (s.iter().map(|x| x * x).sum::<f32>() / s.len() as f32).sqrt();
        assert!(
            rms(&sound.samples) > 0.5 * rms(&source.samples),
            "{video}: silent"
        );
    }
}

/// A recording that is one of the codebook's sentences is refused: the demo shows held-out
/// speech.
#[test]
fn the_demo_refuses_a_codebook_sentence() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("bbaf2n.mp4");
    std::fs::copy(grid("bbbf9a.mp4"), &clip).unwrap();
    std::fs::copy(grid("bbbf9a.txt"), tmp.path().join("bbaf2n.txt")).unwrap();
    let out = tmp.path().join("demo");
    let o = common::facespace(&[
        "demo",
        "--clip",
        clip.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let t = common::text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("is a codebook sentence"), "{t}");
    // Without its words beside it, the remedy is named.
    let bare = tmp.path().join("bare.mp4");
    std::fs::copy(grid("bbbf9a.mp4"), &bare).unwrap();
    let o = common::facespace(&[
        "demo",
        "--clip",
        bare.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let t = common::text(&o);
    assert!(t.contains("bare.txt") && t.contains("--text"), "{t}");
    assert!(!Path::new(&out).exists());
}

/// Full-face synthesis over a recording takes everything but the lips and chin from the
/// recording's tracked face — eyes, brows, nose and jaw line at its head pose, not at the
/// codebook examples' — and keeps the synthesised articulation.
#[test]
fn full_face_synthesis_takes_the_head_from_the_background() {
    let model = FaceModel::load(&facespace::demo::grid_model()).unwrap();
    let cb = Codebook::load(&facespace::demo::grid_codebook()).unwrap();
    let articulators = model
        .articulators()
        .expect("a 68-point face knows its lips and chin");
    assert!(articulators.contains(&8) && articulators.contains(&62) && !articulators.contains(&30));
    let name = TEST_CLIPS[0];
    let (target, fps, backdrop) = take(&model, name);
    let request = Request {
        pose: backdrop.pose.clone(),
        ..Request::new(target, fps, Smoothing::Off)
    };
    let mut u = synthesise(&Blend::default(), &cb, request).unwrap();
    let before = u.synthesis.frames.clone();
    assert!(backdrop.anchor_region(&model, &mut u).unwrap());
    // Mean distance (px) of the head's landmarks, and of the lips', to the recording's.
    let distance = |frames: &facespace::facespace::Frames, lips: bool| {
        let (mut sum, mut n) = (0.0, 0);
        for t in 0..frames.len().min(backdrop.landmarks.len()) {
            let p = model.landmarks(frames.params(t)).unwrap().points;
            for i in 0..68u32 {
                if articulators.contains(&i) == lips {
                    let (a, b) = (p[i as usize], backdrop.landmarks[t].points[i as usize]);
                    sum += (a[0] - b[0]).hypot(a[1] - b[1]);
                    n += 1;
                }
            }
        }
        sum / f64::from(n)
    };
    let (head_before, head_after) = (
        distance(&before, false),
        distance(&u.synthesis.frames, false),
    );
    let (lips_before, lips_after) = (distance(&before, true), distance(&u.synthesis.frames, true));
    eprintln!(
        "{name}: head landmarks {head_before:.2} → {head_after:.2} px from the recording's; lips {lips_before:.2} → {lips_after:.2}"
    );
    assert!(
        head_after < 0.5 * head_before && head_after < 1.5,
        "{head_before} → {head_after}"
    );
    // The lips are still the synthesis's, not copied from the recording.
    assert!(
        lips_after > 0.3,
        "lips {lips_after} px from the recording's: copied?"
    );
}
