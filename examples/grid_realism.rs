//! Does the mouth look recorded? (issue 38; BENCHMARKS.md "Recorded mouths") GRID s1's clips
//! of a split (recorded speech), each said by the committed talker from its own sound and words
//! over his idle footage as `say` draws it, with the mouth from the appearance model (PCA)
//! and with the detail of recorded mouths ([`facespace::mouths`]), against the clip itself:
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
//! chooser's switch cost (chosen on validation).

#[path = "common/grid.rs"]
mod grid;
#[path = "common/track.rs"]
mod track;

use std::path::Path;

use facespace::eval::mouth::{MouthPc, inner_mouth_height};
use facespace::eval::pearson;
use facespace::eval::realism::{
    Cropper, FEATURES, Pair, accuracy, accuracy_on, sharpness, temporal_change,
};
use facespace::facespace::Frames;
use facespace::mouths::Mouths;
use facespace::render::sampled::SampledRenderer;
use facespace::render::{CpuRenderer, DEFAULT_FEATHER, Edge, Renderer};
use facespace::shape::Landmarks;
use facespace::talker::Talker;

struct Drawn {
    crops: Vec<Vec<f32>>,
    /// Each drawn frame projected back into the model at its landmarks.
    projected: Frames,
    heights: Vec<f64>,
}

fn main() {
    let (grid, limit, split) = grid::args();
    let other = std::env::args().nth(4);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let clock = std::time::Instant::now();
    let talker = Talker::load(&root.join("models/grid")).unwrap();
    let model = &talker.model;
    let mouths = match &other {
        Some(dir) => Mouths::load(Path::new(dir), model).unwrap(),
        None => talker.mouths().unwrap().expect("the talker keeps recorded mouths").clone(),
    };
    let mut mouths = mouths;
    if let Ok(g) = std::env::var("FACESPACE_DETAIL_GAIN") {
        mouths.gain = g.parse().unwrap();
    }
    let switch = std::env::var("FACESPACE_SWITCH_COST")
        .ok()
        .map(|v| v.parse::<f32>().unwrap());
    let cropper = Cropper::new(model).unwrap();
    let edge = Edge::Articulators(DEFAULT_FEATHER);
    let pca = CpuRenderer::with_edge(model, edge);
    let ids = grid::split(&grid, &split, limit);
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
        }
    };
    // Per sentence: the recording, then each system.
    let mut sentences: Vec<[Drawn; 3]> = Vec::new();
    let mut switches = 0usize;
    let mut frames_total = 0usize;
    for id in &ids {
        let clip = grid.join(format!("clips/{id}.mp4"));
        let (real_images, _, real_marks) = track::tracked(model, &clip);
        let staging = tempfile::tempdir().unwrap();
        let p = grid::perform(&talker, &grid, id, staging.path());
        let frames = p.utterance.variants()[0].1.clone();
        let n = frames.len().min(real_images.len());
        let frames = frames.slice(0..n);
        let marks = facespace::eval::landmarks(model, &frames);
        let mut sampled = SampledRenderer::new(model, edge, &mouths, &frames);
        if let Some(s) = switch {
            sampled = SampledRenderer::with_switch_cost(model, edge, &mouths, &frames, s);
        }
        switches += sampled.picks().iter().filter(|p| p.frames[1].1 > 0.0).count();
        frames_total += n;
        let images = |r: &dyn Renderer| {
            facespace::render::images(r, &frames, p.backdrop.background().unwrap()).unwrap()
        };
        let (a, b) = (images(&pca), images(&sampled));
        sentences.push([
            draw(&real_images[..n], &real_marks[..n]),
            draw(&a, &marks),
            draw(&b, &marks),
        ]);
        eprint!(".");
    }
    eprintln!();
    let reals: Vec<&Frames> = sentences.iter().map(|s| &s[0].projected).collect();
    let pc = MouthPc::fit(model, &reals).unwrap();
    println!(
        "GRID s1 {split} split (recorded), {} sentences, `say --audio CLIP --text WORDS` over the talker's idle footage; {} recorded mouths kept, source changes on {:.1} % of frames:\n",
        sentences.len(),
        mouths.len(),
        100.0 * switches as f64 / frames_total.max(1) as f64
    );
    println!(
        "| system | discriminator accuracy | crop sharpness × real | temporal change × real | r_pca eq. 16 (pixels) | r_h inner |"
    );
    println!("|---|---|---|---|---|---|");
    let halves: Vec<Pair> = sentences
        .chunks_exact(2)
        .map(|s| Pair {
            a: s[0][0].crops.clone(),
            b: s[1][0].crops.clone(),
        })
        .collect();
    println!(
        "| the recording, its even sentences against its odd ones (sanity) | {:.3} | 1 | 1 | 1 | 1 |",
        accuracy(&halves)
    );
    let mean = |f: &dyn Fn(&[Drawn; 3]) -> f64| {
        sentences.iter().map(f).sum::<f64>() / sentences.len() as f64
    };
    for (k, name) in [(1, "say, the mouth from the model (PCA)"), (2, "say, recorded mouths")] {
        let pairs: Vec<Pair> = sentences
            .iter()
            .map(|s| Pair {
                a: s[0].crops.clone(),
                b: s[k].crops.clone(),
            })
            .collect();
        let sharp = |d: &Drawn| d.crops.iter().map(|c| sharpness(c)).sum::<f64>() / d.crops.len() as f64;
        println!(
            "| {name} | {:.3} | {:.2} | {:.2} | {:.3} | {:.3} |",
            accuracy(&pairs),
            mean(&|s| sharp(&s[k]) / sharp(&s[0])),
            mean(&|s| temporal_change(&s[k].crops) / temporal_change(&s[0].crops)),
            mean(&|s| pearson(&pc.series(&s[k].projected), &pc.series(&s[0].projected))),
            mean(&|s| pearson(&s[k].heights, &s[0].heights)),
        );
    }
    if std::env::var_os("FACESPACE_FEATURES").is_some() {
        for k in [1, 2] {
            let pairs: Vec<Pair> = sentences
                .iter()
                .map(|s| Pair { a: s[0].crops.clone(), b: s[k].crops.clone() })
                .collect();
            let each: Vec<String> = FEATURES
                .iter()
                .enumerate()
                .map(|(f, name)| format!("{name} {:.2}", accuracy_on(&pairs, &[f])))
                .collect();
            println!("system {k}, one feature at a time: {}", each.join(", "));
        }
        let sample: Vec<&[f32]> = sentences
            .iter()
            .flat_map(|s| s[0].crops.iter().step_by(5))
            .map(Vec::as_slice)
            .collect();
        let pca = facespace::pca::PcaModel::fit(&sample, facespace::pca::Components::Count(5)).unwrap();
        for k in 0..3 {
            let mut sum = vec![0.0; FEATURES.len()];
            let mut n = 0.0;
            for s in &sentences {
                for w in s[k].crops.chunks_exact(25) {
                    let f = facespace::eval::realism::features(w, &pca);
                    sum.iter_mut().zip(&f).for_each(|(a, b)| *a += b);
                    n += 1.0;
                }
            }
            let each: Vec<String> = FEATURES.iter().zip(&sum).map(|(name, v)| format!("{name} {:.3}", v / n)).collect();
            println!("side {k} mean features: {}", each.join(", "));
        }
    }
    println!("\n({:.0} s on this machine)", clock.elapsed().as_secs_f64());
}
