//! Do the words match the speech? (issue 34) Each clip of a GRID s1 split aligned to its own
//! words and to the words of another clip of the split (the next one), with the goodness of
//! fit of every word against the free phone loop (`Aligner::align_checked`): the worst word's
//! and the whole recording's fit, true against false transcripts, to set the threshold on
//! `validation` and check it on `test`.
//!
//! `cargo run --release --example grid_word_check -- ../shared/data/grid-s1 SPLIT [THRESHOLD]`
//! With `TALKER=DIR`, the fit as the talker's own ear hears it (`SoundToFace::align_checked`),
//! and how many pass its rule (the ear's fit and the general model's together, `ear_fit`).

#[path = "common/grid.rs"]
mod grid;

use std::path::PathBuf;

use facespace::align::{Aligner, PHONE_PENALTY, PHONE_WEIGHT, frontend};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let grid = PathBuf::from(&args[0]);
    let split = &args[1];
    let threshold: Option<f64> = args.get(2).map(|t| t.parse().unwrap());
    let ids = grid::split(&grid, split, usize::MAX);
    let aligner = Aligner::load_default(&[]).unwrap();
    let lm = aligner.phone_loop(PHONE_WEIGHT, PHONE_PENALTY);
    let talker = std::env::var("TALKER")
        .ok()
        .map(|dir| facespace::talker::Talker::load(std::path::Path::new(&dir)).unwrap());
    let map = talker.as_ref().map(|t| t.sound_to_face().unwrap().expect("the talker has a map"));
    // (true transcripts accepted, other sentences' refused — a transcript that does not align
    // at all is refused, as the commands refuse it) and the clips judged wrongly.
    let (mut accepted, mut refused) = (0, 0);
    let mut wrong: Vec<String> = Vec::new();
    let (mut truth, mut lies) = (Vec::new(), Vec::new());
    // The talker's rule's scores (`sound_to_face::ear_fit`), true and other transcripts'.
    let (mut true_scores, mut other_scores): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
    for (k, id) in ids.iter().enumerate() {
        let audio = facespace::audio::read(
            &grid.join(format!("clips/{id}.mp4")),
            frontend::SAMPLE_RATE,
            600.0,
        )
        .unwrap();
        let other = &ids[(k + 1) % ids.len()];
        for (text, out, true_words) in [
            (grid::words(&grid, id), &mut truth, true),
            (grid::words(&grid, other), &mut lies, false),
        ] {
            let checked = match map {
                Some(map) => map
                    .align_checked(&aligner, &audio.samples, audio.rate, &text)
                    .map(|c| c.expect("the map has a phone classifier"))
                    .map(|(a, ear, general)| (a, ear, Some(general))),
                None => aligner.align_checked(&audio.samples, audio.rate, &text, &lm).map(|(a, fit)| (a, fit, None)),
            };
            if let Ok((_, fit, Some(general))) = &checked {
                let score = facespace::sound_to_face::ear_fit(fit, general);
                if true_words { true_scores.push(score) } else { other_scores.push(score) }
            }
            let matches = match &checked {
                Ok((_, fit, Some(general))) => facespace::sound_to_face::ear_matches(fit, general),
                Ok((_, fit, None)) => fit.matches(),
                Err(_) => false,
            };
            match (true_words, matches) {
                (true, true) => accepted += 1,
                (false, false) => refused += 1,
                (true, false) => wrong.push(format!("{id} refused")),
                (false, true) => wrong.push(format!("{id} with {other}'s words accepted")),
            }
            let stats = match checked {
                Ok((_, fit, _)) => {
                    let mut w = fit.words.clone();
                    w.sort_by(f64::total_cmp);
                    [
                        w[0],
                        w[1],
                        fit.overall,
                        w.iter().sum::<f64>() / w.len() as f64,
                    ]
                }
                Err(_) => [f64::NEG_INFINITY; 4],
            };
            out.push(stats);
        }
    }
    let show = |name: &str, v: &[[f64; 4]], k: usize| {
        let mut s: Vec<f64> = v.iter().map(|x| x[k]).collect();
        s.sort_by(f64::total_cmp);
        println!(
            "{name} [{}]: min {:.2}, 5 % {:.2}, median {:.2}, 95 % {:.2}, max {:.2}",
            ["worst word", "second worst", "overall", "mean word"][k],
            s[0],
            s[s.len() / 20],
            s[s.len() / 2],
            s[s.len() * 19 / 20],
            s[s.len() - 1]
        );
    };
    if std::env::var_os("FS_DUMP").is_some() {
        for (label, v) in [("true", &truth), ("other", &lies)] {
            for x in v.iter() {
                eprintln!("{label} {} {} {} {}", x[0], x[1], x[2], x[3]);
            }
        }
    }
    println!("GRID s1 {split} split (recorded), {} clips", ids.len());
    for k in 0..4 {
        show("true transcripts ", &truth, k);
        show("other sentences' ", &lies, k);
    }
    if !true_scores.is_empty() {
        let least = true_scores.iter().copied().fold(f64::INFINITY, f64::min);
        let most = other_scores.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        println!(
            "the talker's rule (ear and general fits, `ear_fit`): true transcripts' least {least:.3}, other sentences' greatest {most:.3} (of those that align), threshold {}",
            facespace::sound_to_face::LEAST_FIT
        );
    }
    println!(
        "the rule: {accepted}/{n} true transcripts accepted, {refused}/{n} other sentences' refused{}",
        if wrong.is_empty() { String::new() } else { format!(" (wrong: {})", wrong.join(", ")) },
        n = ids.len()
    );
    if let Some(t) = threshold {
        let accepted = truth.iter().filter(|w| w[1] >= t).count();
        let refused = lies.iter().filter(|w| w[1] < t).count();
        println!(
            "threshold {t}: {accepted}/{} true accepted, {refused}/{} other refused",
            truth.len(),
            lies.len()
        );
    }
}
