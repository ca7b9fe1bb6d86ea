//! How much of the talker's ear is its vocabulary (issue 34): GRID has 51 words, and the ear's
//! ±200 ms window hears most of one, so its phone error rate on GRID's own sentences may owe
//! much to having heard every word before. This learns the committed talker's map again
//! without the sentences whose letter is one of LETTERS (default `fkquy`, a fifth of them),
//! then scores both ears — the committed one, which heard those letters, and the new one,
//! which never did — on the validation and test clips with those letters: phone error rate
//! over the letter word's phones alone (reference and recognised phones whose middle lies
//! inside the word's interval in `align/`) and over the rest of the sentence.
//!
//! `cargo run --release --example grid_ear_words -- ../shared/data/grid-s1 [LETTERS] [SPLITS]`
//! (SPLITS: `validation,test` by default; `train` scores the training sentences with those
//! letters, which the new ear never heard — the committed one did: a held-out set ten times
//! larger).

#[path = "common/grid.rs"]
mod grid;

use std::path::{Path, PathBuf};

use facespace::align::{Aligner, PHONE_PENALTY, PHONE_WEIGHT, TimedPhone, frontend};
use facespace::phonemes::{Phone, PhoneMap, Segment, read_htk};
use facespace::sound_to_face::SoundToFace;
use facespace::talker::Talker;

/// The speech phones of `segments` whose middle is (or is not, `inside` false) within `span`.
fn phones_in(segments: &[Segment], span: (f64, f64), inside: bool) -> Vec<Phone> {
    segments
        .iter()
        .filter(|s| s.phone != Phone::SIL)
        .filter(|s| {
            let middle = 0.5 * (s.start + s.end);
            (middle >= span.0 && middle < span.1) == inside
        })
        .map(|s| s.phone)
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let grid = PathBuf::from(&args[0]);
    let letters: Vec<char> = args.get(1).map_or("fkquy", String::as_str).chars().collect();
    let splits: Vec<String> = args
        .get(2)
        .map_or("validation,test", String::as_str)
        .split(',')
        .map(str::to_owned)
        .collect();
    let held = |id: &str| id.chars().nth(3).is_some_and(|c| letters.contains(&c));
    let talker = Talker::load(Path::new("models/grid")).unwrap();
    let aligner = Aligner::load_default(&[]).unwrap();
    let mut codebook = talker.codebook.clone();
    let before = codebook.sentences.len();
    codebook.sentences.retain(|s| !held(&s.name));
    println!(
        "learning the map on {} of the codebook's {before} sentences (none with the letters {letters:?})…",
        codebook.sentences.len()
    );
    let started = std::time::Instant::now();
    let without = SoundToFace::learn(&talker.model, &codebook, &aligner, &grid.join("clips"), 1500, |_| {}).unwrap();
    println!("learnt in {:.0} s", started.elapsed().as_secs_f64());
    // The committed ear, where its window is this build's.
    let with = talker.sound_to_face().ok().flatten();
    let lm = aligner.phone_loop(PHONE_WEIGHT, PHONE_PENALTY);
    let ids: Vec<String> = splits
        .iter()
        .flat_map(|split| grid::split(&grid, split, usize::MAX))
        .filter(|id| held(id))
        .collect();
    // Per ear: errors and reference phones in the letter word, then in the rest.
    // Per ear: errors and reference phones in the letter word, then in the rest.
    let mut counts = [[0usize; 4]; 3];
    let mut refused = 0;
    for id in &ids {
        let sound =
            facespace::audio::read(&grid.join(format!("clips/{id}.mp4")), frontend::SAMPLE_RATE, 600.0).unwrap();
        let words = grid::read_align(&grid.join(format!("align/{id}.align")));
        let span = (words[3].0, words[3].1);
        let reference = read_htk(&grid.join(format!("phones/{id}.lab")), &PhoneMap::default()).unwrap();
        // A clip refused as not speech is counted and left out.
        let general = match aligner.recognise(&sound.samples, sound.rate, &lm) {
            Ok(phones) => phones,
            Err(e) => {
                println!("{id}: {e}");
                refused += 1;
                continue;
            }
        };
        let heard: [Vec<TimedPhone>; 3] = [
            with.map_or_else(Vec::new, |m| m.recognise(&aligner, &sound.samples, sound.rate).unwrap().unwrap().0),
            without.recognise(&aligner, &sound.samples, sound.rate).unwrap().unwrap().0,
            general,
        ];
        for (count, phones) in counts.iter_mut().zip(&heard) {
            let segments = facespace::align::segments(phones);
            for (k, inside) in [(0, true), (2, false)] {
                let truth = phones_in(&reference, span, inside);
                count[k] += facespace::eval::edit_distance(&phones_in(&segments, span, inside), &truth);
                count[k + 1] += truth.len();
            }
        }
    }
    println!(
        "\nGRID s1 {} clips with the letters {letters:?} (recorded), {} clips ({refused} refused as not speech)\n",
        splits.join(" + "),
        ids.len()
    );
    println!("| ear | PER in the letter word | PER in the rest of the sentence |");
    println!("|---|---|---|");
    let names = [
        "the talker's ear, learnt on every training sentence (on `train`: these sentences too)",
        "the talker's ear, learnt without these letters",
        "the general acoustic model's phone loop",
    ];
    for (name, c) in names.iter().zip(&counts) {
        println!(
            "| {name} | {:.1} % ({} phones) | {:.1} % ({} phones) |",
            100.0 * c[0] as f64 / c[1] as f64,
            c[1],
            100.0 * c[2] as f64 / c[3] as f64,
            c[3]
        );
    }
}
