//! Does the mouth look recorded? (issue 38; BENCHMARKS.md "Recorded mouths") GRID s1's clips
//! of a split (recorded speech), each synthesised by the committed talker from its own sound
//! and words (its settings, as `say` hears and synthesises), with the mouth from the appearance
//! model (PCA) and with the detail of recorded mouths ([`facespace::mouths`]), drawn two ways —
//! over the clip's own video (its pose, anchored to its face and re-lit to it: the issue's
//! test) and over the talker's idle footage as `say` draws it — against the clip itself:
//!
//! - the discriminator of [`facespace::eval::realism`]: a logistic regression on one-second
//!   windows of head-stabilised grey mouth crops, cross-validated by sentence (0.5: cannot
//!   tell); its sanity row tells the recording's even sentences from its odd ones;
//! - the crops' sharpness and temporal change (flicker and motion), each over the recording's;
//! - lip sync on the pixels: mouth r_pca (eq. 16 of \[unitsel\]) of each drawn frame projected
//!   back into the model at its own landmarks, and inner-mouth r_h.
//!
//! `cargo run --release --example grid_realism -- ../shared/data/grid-s1 [LIMIT|all] [SPLIT]
//! [MOUTHS]` (SPLIT: `test`, the default, or `validation`; MOUTHS: a mouths folder other than
//! the talker's, e.g. one built with other settings). `FACESPACE_SWITCH_COST` sets the
//! chooser's switch cost and `FACESPACE_DETAIL_GAIN` the detail's gain (chosen on validation);
//! `FACESPACE_FEATURES` adds each feature's accuracy alone, `FACESPACE_MEANS` each feature's
//! mean over the recording's, `FACESPACE_GEOMETRY` where the lips
//! sit below the nose in each clip and each drawing (the footage's head pitch).
//! `FACESPACE_ENCODED` scores the drawn frames as a viewer gets them: written to an MP4 by the
//! writer `say` uses and decoded (the recordings are scored as stored, x264 at CRF 21);
//! `FACESPACE_ENCODED=QP` at that quantiser instead.
//! `FACESPACE_TRACKED` adds the recording's own tracked trajectory drawn over its video (its
//! motion and appearance as tracked, only the drawing ours): which cues are the drawing's.
//! `FACESPACE_APPEARANCE_GAIN=1,1.3` adds the synthesis over its own video with these appearance
//! gains (`Blend::appearance_gain`) in place of the talker's, each paired against it.
//! Each accuracy comes with its standard error over sentences.
//! `FACESPACE_TALKER=T` scores another talker than the committed GRID one, e.g. the 720×576
//! one built from `examples/grid_upscale`'s folder (given as GRID).

#[path = "common/grid.rs"]
mod grid;

use std::path::Path;

use facespace::eval::mouth::{MouthPc, inner_mouth_height, mouth_sharpness};
use facespace::eval::pearson;
use facespace::eval::realism::{
    Accuracy, Cropper, FEATURES, Pair, WINDOW, accuracy, accuracy_on, features, sharpness, temporal_change,
};
use facespace::facespace::Frames;
use facespace::mouths::Mouths;
use facespace::mouths::SampledRenderer;
use facespace::render::{CpuRenderer, DEFAULT_FEATHER, Edge, Renderer};
use facespace::shape::Landmarks;
use facespace::codec::EncodeOptions;
use facespace::synth::backdrop::{Backdrop, PoseMode};
use facespace::synth::{Request, Smoothing};
use facespace::talker::Talker;

struct Drawn {
    crops: Vec<Vec<f32>>,
    /// Each drawn frame projected back into the model at its landmarks.
    projected: Frames,
    heights: Vec<f64>,
    /// The mouth's sharpness in the full-size frames (`eval::mouth::mouth_sharpness`).
    sharpness: f64,
}

fn main() {
    let (grid, limit, split) = grid::args();
    let other = std::env::args().nth(4);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let clock = std::time::Instant::now();
    let talker = match std::env::var_os("FACESPACE_TALKER") {
        Some(t) => Talker::load(Path::new(&t)).unwrap(),
        None => Talker::load(&root.join("models/grid")).unwrap(),
    };
    let model = &talker.model;
    let mouths = match &other {
        Some(dir) => Mouths::load(Path::new(dir), model).unwrap(),
        None => talker.mouths().unwrap().expect("the talker keeps recorded mouths").clone(),
    };
    // One store per detail gain compared (`FACESPACE_DETAIL_GAIN=1.25,1.5`).
    let gains: Vec<f32> = std::env::var("FACESPACE_DETAIL_GAIN")
        .map(|g| g.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or(vec![mouths.gain]);
    let stores: Vec<Mouths> = gains
        .iter()
        .map(|&gain| {
            let mut m = mouths.clone();
            m.gain = gain;
            m
        })
        .collect();
    // The systems scored against the recording, in the order they are drawn.
    let mut systems = Vec::new();
    // `FACESPACE_TRACKED`: also the recording's own tracked trajectory drawn over its video —
    // which cues are the drawing's and which the synthesised motion's.
    let tracked = std::env::var_os("FACESPACE_TRACKED").is_some();
    let mut places = vec!["synthesis over the clip's own video", "say over the idle footage"];
    if tracked {
        places.push("the recording's own tracked trajectory over its video");
    }
    // `FACESPACE_APPEARANCE_GAIN=1.15,1.3`: also the synthesis over its own video with these
    // appearance gains (`synth::blend::Blend::appearance_gain`) in place of the talker's.
    let appearance_gains: Vec<f64> = std::env::var("FACESPACE_APPEARANCE_GAIN")
        .map(|g| g.split(',').map(|v| v.parse().unwrap()).collect())
        .unwrap_or_default();
    let lively: Vec<String> = appearance_gains
        .iter()
        .map(|g| format!("synthesis over the clip's own video, appearance gain {g}"))
        .collect();
    let places_before_lively = places.len();
    places.extend(lively.iter().map(String::as_str));
    for place in places {
        systems.push(format!("{place}, the model's mouth (PCA)"));
        for g in &gains {
            systems.push(format!("{place}, recorded mouths, detail gain {g}"));
        }
    }
    let switch = std::env::var("FACESPACE_SWITCH_COST")
        .ok()
        .map(|v| v.parse::<f32>().unwrap());
    // `FACESPACE_STRIP=ID:FIRST:OUT.jpg`: the README's strip of one sentence.
    let strip = std::env::var("FACESPACE_STRIP").ok().map(|s| {
        let parts: Vec<&str> = s.splitn(3, ':').collect();
        (parts[0].to_string(), parts[1].parse::<usize>().unwrap(), parts[2].to_string())
    });
    let cropper = Cropper::new(model).unwrap();
    let edge = Edge::Articulators(DEFAULT_FEATHER);
    let pca = CpuRenderer::with_edge(model, edge);
    let mut ids = grid::split(&grid, &split, limit);
    if let Some((id, ..)) = &strip {
        ids = vec![id.clone()];
    }
    let draw = |images: &[image::RgbImage], marks: &[Vec<[f64; 2]>]| -> Drawn {
        let rows: Vec<f32> = images
            .iter()
            .zip(marks)
            .flat_map(|(image, m)| {
                model
                    .project(image, &Landmarks { points: m.clone() })
                    .unwrap()
            })
            .collect();
        Drawn {
            crops: cropper.crops(images, marks),
            projected: Frames::from_rows(model.layout(), 25.0, rows).unwrap(),
            heights: marks.iter().map(|m| inner_mouth_height(m)).collect(),
            sharpness: mouth_sharpness(images, marks),
        }
    };
    // The drawn frames as a viewer gets them: through the MP4 writer `say` uses, decoded.
    let encoded = std::env::var("FACESPACE_ENCODED").ok().map(|q| q.parse::<u8>().ok());
    // Per sentence: the recording, then each system.
    let mut sentences: Vec<Vec<Drawn>> = Vec::new();
    let mut switches = 0usize;
    let mut frames_total = 0usize;
    let settings = &talker.manifest.settings;
    for id in &ids {
        let clip = grid.join(format!("clips/{id}.mp4"));
        let real_images: Vec<image::RgbImage> = facespace::video::Source::open(&clip)
            .and_then(|source| source.collect())
            .unwrap();
        let staging = tempfile::tempdir().unwrap();
        let p = grid::perform(&talker, &grid, id, staging.path());
        let n = p.utterance.variants()[0].1.len().min(real_images.len());
        // The same phones synthesised over the clip's own video (its pose, anchored to its
        // face, re-lit to it), as the test draws them. Its tracking gives the
        // recording's landmarks too (the clip is tracked once).
        let own = Backdrop::video(
            model,
            &clip,
            PoseMode::Replay,
            n,
            &EncodeOptions::default(),
            facespace::no_progress,
        )
        .unwrap();
        // The phones synthesised with `settings` over the clip's own video.
        let over_own_with = |settings: &facespace::talker::Settings| {
            let request = Request::new(p.target.clone(), 25.0, Smoothing::On(settings.smoothing));
            own.synthesise(settings.synthesiser().as_ref(), &talker.codebook, model, request).unwrap()
        };
        // Over its own video as `synth --talker T --background CLIP` draws it (the talker's
        // pipeline with the clip as its canvas).
        let over_own = {
            let request = facespace::talker::SayRequest {
                accept_mismatch: true,
                canvas: facespace::talker::Canvas::Video { path: clip.clone(), pose: PoseMode::Replay },
                ..facespace::talker::SayRequest::new(facespace::talker::Speech::Recording {
                    audio: clip.clone(),
                    words: grid::words(&grid, id),
                })
            };
            talker.perform(&request, staging.path()).unwrap().utterance
        };
        let real_marks: Vec<Vec<[f64; 2]>> = own.landmarks.iter().map(|l| l.points.clone()).collect();
        let mut drawn = vec![draw(&real_images[..n], &real_marks[..n])];
        // Rows of the README's strip: the recording, then each system over its own video.
        let mut strip_rows = vec![real_images[..n].to_vec()];
        // (frames, backdrop, whether the README's strip shows them: the synthesis over its own
        // video only).
        let mut drawings = vec![
            (over_own.variants()[0].1.slice(0..n), &own, true),
            (p.utterance.variants()[0].1.slice(0..n), &p.backdrop, false),
        ];
        if tracked {
            drawings.push((own.tracked.slice(0..n), &own, false));
        }
        for &appearance_gain in &appearance_gains {
            let lively = over_own_with(&facespace::talker::Settings { appearance_gain, ..settings.clone() });
            drawings.push((lively.variants()[0].1.slice(0..n), &own, false));
        }
        for (frames, backdrop, in_strip) in drawings {
            let marks = facespace::eval::landmarks(model, &frames);
            let mut renderers: Vec<Box<dyn Renderer + '_>> = vec![Box::new(pca.clone())];
            for store in &stores {
                let sampled = match switch {
                    Some(s) => SampledRenderer::with_switch_cost(model, edge, store, &frames, s),
                    None => SampledRenderer::new(model, edge, store, &frames),
                };
                switches += sampled.picks().iter().filter(|p| p.frames[1].1 > 0.0).count();
                frames_total += n;
                renderers.push(Box::new(sampled));
            }
            for r in &renderers {
                let r = r.as_ref();
                let mut images =
                    facespace::render::images(r, &frames, backdrop.background().unwrap()).unwrap();
                if let Some(qp) = encoded {
                    images = as_written(&images, qp);
                }
                drawn.push(draw(&images, &marks));
                if in_strip {
                    strip_rows.push(images);
                }
            }
            if std::env::var_os("FACESPACE_GEOMETRY").is_some() {
                // Where the lips sit below the nose tip, in interocular distances: a head's
                // pitch moves them, and a similarity fitted to the eyes and nose cannot undo it.
                let below = |m: &[Vec<[f64; 2]>]| {
                    let mut acc = [0f64; 3];
                    for l in m {
                        let iod = (l[45][0] - l[36][0]).hypot(l[45][1] - l[36][1]);
                        for (a, i) in acc.iter_mut().zip([51usize, 57, 48]) {
                            *a += (l[i][1] - l[30][1]) / iod / m.len() as f64;
                        }
                    }
                    acc.map(|v| format!("{v:.3}")).join(" ")
                };
                println!("{id}: lips 51 57 48 below the nose, real {}, drawn {}", below(&real_marks[..n]), below(&marks));
            }
        }
        if let Some((_, first, out)) = strip.as_ref().filter(|s| s.0 == *id) {
            save_strip(&strip_rows, &real_marks[*first + STRIP_FRAMES / 2], *first, out);
        }
        sentences.push(drawn);
        eprint!(".");
    }
    eprintln!();
    let reals: Vec<&Frames> = sentences.iter().map(|s| &s[0].projected).collect();
    let pc = MouthPc::fit(model, &reals).unwrap();
    println!(
        "GRID s1 {split} split (recorded), {} sentences, from each clip's sound and words, talker {:?}; {} recorded mouths kept, source changes on {:.1} % of frames:\n",
        sentences.len(),
        talker.manifest.name,
        mouths.len(),
        100.0 * switches as f64 / frames_total.max(1) as f64
    );
    // An accuracy with its standard error over sentences.
    let shown = |a: &Accuracy| format!("{:.3} ± {:.3}", a.value(), a.standard_error());
    println!(
        "| system | discriminator accuracy (± s.e.) | crop sharpness × real | full-size mouth sharpness × real | temporal change × real | r_pca eq. 16 (pixels) | r_h inner |"
    );
    println!("|---|---|---|---|---|---|---|");
    let halves: Vec<Pair> = sentences
        .chunks_exact(2)
        .map(|s| Pair {
            a: s[0][0].crops.clone(),
            b: s[1][0].crops.clone(),
        })
        .collect();
    println!(
        "| the recording, its even sentences against its odd ones (sanity) | {} | 1 | 1 | 1 | 1 | 1 |",
        shown(&accuracy(&halves))
    );
    let mean = |f: &dyn Fn(&[Drawn]) -> f64| {
        sentences.iter().map(|s| f(s)).sum::<f64>() / sentences.len() as f64
    };
    let pairs_of = |k: usize| -> Vec<Pair> {
        sentences
            .iter()
            .map(|s| Pair {
                a: s[0].crops.clone(),
                b: s[k].crops.clone(),
            })
            .collect()
    };
    let accuracies: Vec<Accuracy> = (1..=systems.len()).map(|k| accuracy(&pairs_of(k))).collect();
    for (k, name) in systems.iter().enumerate().map(|(k, n)| (k + 1, n)) {
        let sharp = |d: &Drawn| d.crops.iter().map(|c| sharpness(c)).sum::<f64>() / d.crops.len() as f64;
        println!(
            "| {name} | {} | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} |",
            shown(&accuracies[k - 1]),
            mean(&|s| sharp(&s[k]) / sharp(&s[0])),
            mean(&|s| s[k].sharpness / s[0].sharpness),
            mean(&|s| temporal_change(&s[k].crops) / temporal_change(&s[0].crops)),
            mean(&|s| pearson(&pc.series(&s[k].projected), &pc.series(&s[0].projected))),
            mean(&|s| pearson(&s[k].heights, &s[0].heights)),
        );
    }
    // Systems per place: the model's mouth, then one per detail gain.
    let per_place = 1 + gains.len();
    // With several gains, each against the talker's own on the same sentences (paired).
    let default_gain = gains.iter().position(|&g| g == mouths.gain);
    if let (Some(d), true) = (default_gain, gains.len() > 1) {
        for (k, name) in systems.iter().enumerate() {
            let base = k - k % per_place + 1 + d;
            if k % per_place != 0 && k != base {
                let (diff, se) = accuracies[k].minus(&accuracies[base]);
                println!("{name}: {diff:+.3} ± {se:.3} against gain {} (paired over sentences)", mouths.gain);
            }
        }
    }
    // Each appearance gain's recorded mouths against the talker's, on the same sentences.
    for (k, name) in systems.iter().enumerate().skip(places_before_lively * per_place) {
        if k % per_place != 0 {
            let (diff, se) = accuracies[k].minus(&accuracies[k % per_place]);
            println!(
                "{name}: {diff:+.3} ± {se:.3} against the talker's {} (paired over sentences)",
                settings.appearance_gain
            );
        }
    }
    if std::env::var_os("FACESPACE_FEATURES").is_some() {
        for (k, name) in systems.iter().enumerate().map(|(k, n)| (k + 1, n)) {
            let pairs = pairs_of(k);
            let each: Vec<String> = FEATURES
                .iter()
                .enumerate()
                .map(|(f, feature)| format!("{feature} {:.2}", accuracy_on(&pairs, &[f]).value()))
                .collect();
            println!("{name}, one feature at a time: {}", each.join(", "));
        }
    }
    if std::env::var_os("FACESPACE_MEANS").is_some() {
        // Each feature's mean over every window, drawn over real, and the difference in units
        // of the real windows' s.d. (d′); the crops' PCA fitted on the recordings' alone.
        let sample: Vec<&[f32]> =
            sentences.iter().flat_map(|s| s[0].crops.iter().step_by(5)).map(Vec::as_slice).collect();
        let pca = facespace::pca::PcaModel::fit(&sample, facespace::pca::Components::Count(5)).unwrap();
        let rows = |k: usize| -> Vec<Vec<f64>> {
            sentences
                .iter()
                .flat_map(|s| {
                    let c = &s[k].crops;
                    (0..).step_by(WINDOW / 2).take_while(|st| st + WINDOW <= c.len()).map(|st| features(&c[st..st + WINDOW], &pca))
                })
                .collect()
        };
        let real = rows(0);
        let mean = |r: &[Vec<f64>], f: usize| r.iter().map(|x| x[f]).sum::<f64>() / r.len() as f64;
        let sd = |r: &[Vec<f64>], f: usize| {
            let m = mean(r, f);
            (r.iter().map(|x| (x[f] - m).powi(2)).sum::<f64>() / r.len() as f64).sqrt()
        };
        for (k, name) in systems.iter().enumerate().map(|(k, n)| (k + 1, n)) {
            let drawn = rows(k);
            let each: Vec<String> = FEATURES
                .iter()
                .enumerate()
                .map(|(f, n)| {
                    let (d, r) = (mean(&drawn, f), mean(&real, f));
                    format!("{n} {:.3} (d′ {:+.2})", d / r, (d - r) / sd(&real, f))
                })
                .collect();
            println!("{name}, each feature's mean over real: {}", each.join(", "));
        }
    }
    println!("\n({:.0} s on this machine)", clock.elapsed().as_secs_f64());
}

/// Consecutive frames in the README's strip.
const STRIP_FRAMES: usize = 6;

/// `STRIP_FRAMES` frames from `first` of each row (the recording, then each system), as 3×
/// crops of one box around the lips of `lips` (the recording's middle frame), one row each;
/// beside `OUT`, `OUT-full.png`: the middle frame of every row at full size, side by side.
fn save_strip(rows: &[Vec<image::RgbImage>], lips: &[[f64; 2]], first: usize, out: &str) {
    let mouth = &lips[48..68];
    let cx = mouth.iter().map(|p| p[0]).sum::<f64>() / 20.0;
    let cy = mouth.iter().map(|p| p[1]).sum::<f64>() / 20.0;
    // A box 1.6 mouths wide (64×44 at 360×288), so a larger face gets a larger box.
    let width = mouth.iter().map(|p| p[0]).fold(f64::MIN, f64::max)
        - mouth.iter().map(|p| p[0]).fold(f64::MAX, f64::min);
    let w = (1.6 * width / 2.0).round() as u32 * 2;
    let h = (w as f64 * 44.0 / 64.0).round() as u32;
    let middle = rows
        .iter()
        .map(|row| row[first + STRIP_FRAMES / 2].clone())
        .reduce(|a, b| facespace::video::side_by_side(&a, &b))
        .unwrap();
    middle.save(format!("{}-full.png", out.trim_end_matches(".jpg").trim_end_matches(".png"))).unwrap();
    let (x0, y0) = ((cx - w as f64 / 2.0).round() as u32, (cy - h as f64 / 2.0).round() as u32);
    let (sw, sh) = (3 * w, 3 * h);
    let mut strip = image::RgbImage::new(sw * STRIP_FRAMES as u32 + (STRIP_FRAMES as u32 - 1) * 4, sh * rows.len() as u32 + (rows.len() as u32 - 1) * 4);
    for (r, row) in rows.iter().enumerate() {
        for k in 0..STRIP_FRAMES {
            let crop = image::imageops::crop_imm(&row[first + k], x0, y0, w, h).to_image();
            let big = image::imageops::resize(&crop, sw, sh, image::imageops::FilterType::Nearest);
            image::imageops::replace(&mut strip, &big, i64::from(k as u32 * (sw + 4)), i64::from(r as u32 * (sh + 4)));
        }
    }
    strip.save(out).unwrap();
}

/// `images` written to an MP4 as `say` writes its video (`mp4_file::Writer::create`, 25
/// fps), or at the quantiser `qp`, and decoded again.
fn as_written(images: &[image::RgbImage], qp: Option<u8>) -> Vec<image::RgbImage> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("drawn.mp4");
    let (w, h) = images[0].dimensions();
    let mut writer = match qp {
        Some(qp) => facespace::mp4_file::Writer::create_with_qp(&path, w, h, 25.0, qp),
        None => facespace::mp4_file::Writer::create(&path, w, h, 25.0),
    }
    .unwrap();
    for image in images {
        writer.write(image).unwrap();
    }
    writer.finish(&path, None).unwrap();
    facespace::video::Source::open(&path).and_then(|source| source.collect()).unwrap()
}
