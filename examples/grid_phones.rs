//! Phones recognised without words (issue 34) against GRID s1's `phones/` labels: phone error
//! rate (edit distance over the reference's phones, silences left out), viseme-class error
//! (the same over the phones' 22 viseme classes) and Rhubarb-shape error (over the phones'
//! mouth shapes A–H, /hh/ left out and repeats joined: what a 2D rig shows), and the speed on
//! one core.
//!
//! `cargo run --release --example grid_phones -- ../shared/data/grid-s1 SPLIT [LIMIT] [WEIGHT PENALTY]…`
//! (several WEIGHT PENALTY pairs: one row each — the grid searched on `validation`).
//! With `STREAM=LAG+PIECE,…` in the environment, rows of the live recogniser too (20 ms
//! chunks; lag and least piece in frames), with the wait of each frame for its phone.
//! With `ANCHORS=DIR`, pocketsphinx's rows on the same clips: the first run writes the clips'
//! sound to `DIR/wav/`, `python3 tests/reference/pocketsphinx_phones.py DIR` recognises them,
//! and the next run scores its `allphone.tsv` and `words.tsv` beside ours.
//! With `TALKER=DIR`, the talker's own ear ([`facespace::sound_to_face::PhoneClassifier`])
//! replaces the acoustic model's in the loop.

#[path = "common/grid.rs"]
mod grid;

use std::path::PathBuf;

use facespace::align::{Aligner, PHONE_PENALTY, PHONE_WEIGHT, frontend};
use facespace::phonemes::{Phone, PhoneMap, read_htk};
use facespace::visemes::Shape;

/// Phones, each frame's wait for its phone (live only), the seconds taken when timed elsewhere.
type Recognised = (Vec<facespace::align::TimedPhone>, Vec<f64>, Option<f64>);

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let grid = PathBuf::from(&args[0]);
    let split = &args[1];
    let limit: usize = args
        .get(2)
        .and_then(|n| n.parse().ok())
        .unwrap_or(usize::MAX);
    let mut settings: Vec<(f64, f64)> = args[3.min(args.len())..]
        .chunks(2)
        .filter(|c| c.len() == 2)
        .map(|c| (c[0].parse().unwrap(), c[1].parse().unwrap()))
        .collect();
    if settings.is_empty() {
        settings.push((PHONE_WEIGHT, PHONE_PENALTY));
    }
    let ids = grid::split(&grid, split, limit);
    let lags: Vec<(usize, usize)> = std::env::var("STREAM")
        .map(|l| {
            l.split(',')
                .map(|x| {
                    let (a, b) = x.split_once('+').unwrap();
                    (a.parse().unwrap(), b.parse().unwrap())
                })
                .collect()
        })
        .unwrap_or_default();
    let aligner = Aligner::load_default(&[]).unwrap();
    let clips: Vec<(Vec<f32>, f64, Vec<Phone>)> = ids
        .iter()
        .map(|id| {
            let audio = facespace::audio::read(
                &grid.join(format!("clips/{id}.mp4")),
                frontend::SAMPLE_RATE,
                600.0,
            )
            .unwrap();
            let reference: Vec<Phone> =
                read_htk(&grid.join(format!("phones/{id}.lab")), &PhoneMap::default())
                    .unwrap()
                    .iter()
                    .map(|s| s.phone)
                    .filter(|&p| p != Phone::SIL)
                    .collect();
            let seconds = audio.seconds();
            (audio.samples, seconds, reference)
        })
        .collect();
    println!("GRID s1 {split} split (recorded), {} clips", clips.len());
    let anchors = std::env::var("ANCHORS").ok().map(PathBuf::from);
    if let Some(dir) = &anchors {
        std::fs::create_dir_all(dir.join("wav")).unwrap();
        for (id, (samples, _, _)) in ids.iter().zip(&clips) {
            let audio = facespace::audio::Audio {
                samples: samples.clone(),
                rate: frontend::SAMPLE_RATE,
            };
            facespace::audio::write_wav(&dir.join(format!("wav/{id}.wav")), &audio).unwrap();
        }
    }
    let score = |label: String, recognise: &dyn Fn(usize, &[f32]) -> Recognised| {
        let (mut errors, mut verrors, mut total, mut audio, mut spent, mut lag) =
            (0, 0, 0, 0.0, 0.0, Vec::new());
        let (mut serrors, mut stotal) = (0, 0);
        for (k, (samples, seconds, reference)) in clips.iter().enumerate() {
            let clock = std::time::Instant::now();
            let (phones, waits, took) = recognise(k, samples);
            spent += took.unwrap_or(clock.elapsed().as_secs_f64());
            audio += seconds;
            lag.extend(waits);
            let hyp: Vec<Phone> = phones
                .iter()
                .filter_map(|p| Phone::parse(&p.phone))
                .filter(|&p| p != Phone::SIL)
                .collect();
            errors += facespace::eval::edit_distance(&hyp, reference);
            let v = |s: &[Phone]| s.iter().map(|p| p.viseme()).collect::<Vec<_>>();
            verrors += facespace::eval::edit_distance(&v(&hyp), &v(reference));
            total += reference.len();
            let shapes = |s: &[Phone]| {
                let mut v: Vec<Shape> = s.iter().filter_map(|&p| Shape::of_phone(p)).collect();
                v.dedup();
                v
            };
            serrors += facespace::eval::edit_distance(&shapes(&hyp), &shapes(reference));
            stotal += shapes(reference).len();
        }
        println!(
            "| {label} | {:.1} % | {:.1} % | {:.1} % | {:.0}× | {} |",
            100.0 * errors as f64 / total as f64,
            100.0 * verrors as f64 / total as f64,
            100.0 * serrors as f64 / stotal as f64,
            audio / spent,
            if lag.is_empty() {
                "—".into()
            } else {
                lag.sort_by(f64::total_cmp);
                let q = |f: f64| 1000.0 * lag[((lag.len() - 1) as f64 * f) as usize];
                format!("{:.0} / {:.0} / {:.0} ms", q(0.5), q(0.95), q(1.0))
            }
        );
    };
    println!("| weight / penalty | PER | viseme-class error | Rhubarb-shape error | × real time, one core | wait of a frame for its phone: median / 95 % / most |");
    println!("|---|---|---|---|---|---|");
    if let Some(dir) = &anchors {
        for route in ["allphone", "words"] {
            let Ok(table) = std::fs::read_to_string(dir.join(format!("{route}.tsv"))) else {
                println!("(no {route}.tsv yet: run tests/reference/pocketsphinx_phones.py)");
                continue;
            };
            let rows: std::collections::HashMap<&str, (f64, Vec<facespace::align::TimedPhone>)> = table
                .lines()
                .map(|line| {
                    let mut f = line.splitn(3, '\t');
                    let id = f.next().unwrap();
                    let seconds: f64 = f.next().unwrap().parse().unwrap();
                    let phones = f
                        .next()
                        .unwrap_or("")
                        .split_whitespace()
                        .map(|p| facespace::align::TimedPhone {
                            phone: p.to_owned(),
                            start: 0.0,
                            end: 0.0,
                            word: None,
                        })
                        .collect();
                    (id, (seconds, phones))
                })
                .collect();
            score(format!("pocketsphinx {route}"), &|k, _| {
                let (took, phones) = &rows[ids[k].as_str()];
                (phones.clone(), Vec::new(), Some(*took))
            });
        }
    }
    // With `TALKER=DIR`, the talker's own phone classifier (its sound-to-face map) hears
    // them through each loop instead.
    let talker = std::env::var("TALKER")
        .ok()
        .map(|dir| facespace::talker::Talker::load(std::path::Path::new(&dir)).unwrap());
    let map = talker.as_ref().map(|t| t.sound_to_face().unwrap().expect("the talker has a map"));
    for (weight, penalty) in settings {
        let lm = aligner.phone_loop(weight, penalty);
        if let Some(map) = map {
            score(format!("talker's ear, {weight} / {penalty}"), &|_, samples| {
                let phones = map.recognise_through(&aligner, samples, frontend::SAMPLE_RATE, &lm).unwrap();
                (phones.expect("the map has a phone classifier").0, Vec::new(), None)
            });
            continue;
        }
        score(format!("{weight} / {penalty}"), &|_, samples| {
            let phones = aligner.recognise(samples, frontend::SAMPLE_RATE, &lm).unwrap();
            (facespace::align::merge_pieces(phones), Vec::new(), None)
        });
        for &(lag, piece) in &lags {
            score(format!("{weight} / {penalty}, live, lag {lag} + {piece}"), &|_, samples| {
                let mut live = aligner
                    .recogniser(frontend::SAMPLE_RATE, &lm)
                    .unwrap()
                    .with_lag(lag, piece);
                let (mut phones, mut wait) = (Vec::new(), Vec::new());
                for chunk in samples.chunks(320) {
                    let new = live.push(chunk).unwrap();
                    // Every 10 ms frame's wait from its own time to its release.
                    for p in &new {
                        let mut t = p.start;
                        while t < p.end - 1e-9 {
                            wait.push(live.seconds() - t);
                            t += 0.01;
                        }
                    }
                    phones.extend(new);
                }
                phones.extend(live.finish().unwrap());
                (facespace::align::merge_pieces(phones), wait, None)
            });
        }
    }
}
