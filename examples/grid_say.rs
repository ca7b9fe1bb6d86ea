//! `say` on GRID s1's test split (issue 33; BENCHMARKS.md "Say"): each test clip's recorded
//! speech and its words (`align/ID.align`) through the committed talker with its default
//! settings — the face drawn over his idle footage, only lips and jaw synthesised — scored
//! against the clip tracked with the talker's model:
//!
//! - mouth r_pca by eq. 16 of \[unitsel\] (the mouth PCA fitted on the real test frames) and
//!   inner-mouth r_h;
//! - the inner-mouth height's s.d. and the lips' mean frame-to-frame motion (landmarks 48–67
//!   without the pose), each synthesised over real;
//! - the sharpness of the mouth as drawn: mean grey gradient magnitude inside the lips'
//!   bounding box (3 px margin) of the rendered frames over that of the recorded ones.
//!
//! Rows: `say` as shipped (the talker's settings, chosen on GRID's validation split for
//! correlation with the lip motion and amplitude kept), and the same phones by the settings
//! chosen for correlation alone before (blend N = 5, λ = 3e-5) and by the old `synth`
//! defaults (N = 3, λ = 3e-6), everything else alike — the same anchoring, re-lighting and
//! footage; and `say --audio CLIP` without the words: the lips predicted from the sound by
//! the talker's sound-to-face map, and (the talker loaded without its map) from phones
//! recognised in the sound.
//!
//! `cargo run --release --example grid_say -- ../shared/data/grid-s1 [LIMIT|all] [SPLIT]`
//! (SPLIT: `test`, the default, or `validation`, where the constants were chosen).

#[path = "common/grid.rs"]
mod grid;
#[path = "common/track.rs"]
mod track;

use std::path::Path;

use facespace::eval::mouth::{MouthPc, inner_mouth_height, lip_motion, mouth_sharpness};
use facespace::eval::{pearson, standard_deviation};
use facespace::facespace::Frames;
use facespace::render::{CpuRenderer, DEFAULT_FEATHER, Edge, Renderer};
use facespace::synth::blend::Blend;
use facespace::talker::{SayRequest, Speech, Talker};
use image::RgbImage;

struct Sentence {
    real: Frames,
    real_images: Vec<RgbImage>,
    rows: Vec<(Frames, Vec<RgbImage>)>,
}

fn main() {
    let (grid, limit, split) = grid::args();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let clock = std::time::Instant::now();
    let talker = Talker::load(&root.join("models/grid")).unwrap();
    let ids = grid::split(&grid, &split, limit);
    let settings = &talker.manifest.settings;
    let say = format!(
        "say (talker settings: blend N={}, λ={:e})",
        settings.top_n, settings.smoothing
    );
    let others = [(5, 3e-5), (3, 3e-6)];
    let systems = [
        say.as_str(),
        "chosen for correlation alone (blend N=5, λ=3e-5)",
        "old synth defaults (blend N=3, λ=3e-6)",
        "say without the words (the talker's sound-to-face map)",
        "say without the words, phones recognised (no sound-to-face map)",
        "say without the words, the phones the talker's ear hears, performed (no map's face)",
    ];
    // The same talker without its map: the phones recognised from the sound drive the blend.
    let mut phones_only = Talker::load(&root.join("models/grid")).unwrap();
    phones_only.manifest.sound_to_face = None;
    let renderer = CpuRenderer::with_edge(&talker.model, Edge::Articulators(DEFAULT_FEATHER));
    let mut sentences = Vec::new();
    for id in &ids {
        let clip = grid.join(format!("clips/{id}.mp4"));
        let (real_images, real, _) = track::tracked(&talker.model, &clip);
        let staging = tempfile::tempdir().unwrap();
        let p = grid::perform(&talker, &grid, id, staging.path());
        let mut rows = Vec::new();
        // The same recording without its words: phones recognised from the sound alone.
        let heard = talker
            .perform(
                &SayRequest::new(Speech::Sound(clip.clone())),
                staging.path(),
            )
            .unwrap();
        let recognised = phones_only
            .perform(
                &SayRequest::new(Speech::Sound(clip.clone())),
                staging.path(),
            )
            .unwrap();
        // The phones the talker's own ear hears, performed as labels (the map's face unused).
        let labels = staging.path().join("ear.lab");
        let ear = facespace::align::segments(&talker.recognise(&clip).unwrap());
        facespace::phonemes::write_labels(&labels, &ear).unwrap();
        let by_ear = talker
            .perform(
                &SayRequest::new(Speech::Labels {
                    labels,
                    tier: None,
                    map: facespace::phonemes::PhoneMap::default(),
                    audio: Some(clip.clone()),
                }),
                staging.path(),
            )
            .unwrap();
        for system in 0..systems.len() {
            let backdrop = match system {
                3 => &heard.backdrop,
                4 => &recognised.backdrop,
                5 => &by_ear.backdrop,
                _ => &p.backdrop,
            };
            let frames = if system == 0 {
                p.utterance.variants()[0].1.clone()
            } else if system == 3 {
                heard.utterance.variants()[0].1.clone()
            } else if system == 4 {
                recognised.utterance.variants()[0].1.clone()
            } else if system == 5 {
                by_ear.utterance.variants()[0].1.clone()
            } else {
                let (top_n, lambda) = others[system - 1];
                let blend = Blend {
                    top_n,
                    ..Blend::default()
                };
                let req = facespace::synth::Request {
                    pose: p.backdrop.pose.clone(),
                    ..facespace::synth::Request::new(
                        p.target.clone(),
                        real.fps(),
                        facespace::synth::Smoothing::On(lambda),
                    )
                };
                let mut u = facespace::synth::synthesise(&blend, &talker.codebook, req).unwrap();
                p.backdrop.anchor_region(&talker.model, &mut u).unwrap();
                p.backdrop
                    .match_lighting(&talker.model, &talker.codebook, &mut u);
                u.variants()[0].1.clone()
            };
            let images = facespace::render::images(
                &renderer as &dyn Renderer,
                &frames,
                backdrop.background().unwrap(),
            )
            .unwrap();
            rows.push((frames, images));
        }
        sentences.push(Sentence {
            real,
            real_images,
            rows,
        });
        eprint!(".");
    }
    eprintln!();
    let reals: Vec<&Frames> = sentences.iter().map(|s| &s.real).collect();
    let pc = MouthPc::fit(&talker.model, &reals).expect("a 68-point model");
    let points = |f: &Frames| facespace::eval::landmarks(&talker.model, f);
    println!(
        "GRID s1 {split} split (recorded), {} sentences, `say --audio CLIP --text WORDS` over the talker's idle footage:\n",
        sentences.len()
    );
    println!(
        "| system | r_pca eq. 16 | r_h inner | inner s.d. × real | lip motion × real | mouth sharpness × real |"
    );
    println!("|---|---|---|---|---|---|");
    for (k, name) in systems.iter().enumerate() {
        let (mut r_pca, mut r_h, mut sd, mut mo, mut sharp) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for s in &sentences {
            let (synth, images) = &s.rows[k];
            let n = synth.len().min(s.real.len());
            let (a, b) = (synth.slice(0..n), s.real.slice(0..n));
            r_pca += pearson(&pc.series(&a), &pc.series(&b));
            let h = |f: &Frames| {
                points(f)
                    .iter()
                    .map(|p| inner_mouth_height(p))
                    .collect::<Vec<_>>()
            };
            let (ha, hb) = (h(&a), h(&b));
            r_h += pearson(&ha, &hb);
            sd += standard_deviation(&ha) / standard_deviation(&hb).max(1e-9);
            mo += lip_motion(&talker.model, &a) / lip_motion(&talker.model, &b).max(1e-12);
            sharp += mouth_sharpness(&images[..n], &points(&a))
                / mouth_sharpness(&s.real_images[..n], &points(&b)).max(1e-9);
        }
        let m = sentences.len() as f64;
        println!(
            "| {name} | {:.3} | {:.3} | {:.2} | {:.3} | {:.2} |",
            r_pca / m,
            r_h / m,
            sd / m,
            mo / m,
            sharp / m
        );
    }
    println!("\n({:.0} s on this machine)", clock.elapsed().as_secs_f64());
}
