//! GRID s1 helpers shared by the examples that read its folder (each uses some of them).
#![allow(dead_code)]

use std::path::Path;

/// The words of a GRID `.align` file, `sil` and `sp` left out: (start, end, word), seconds
/// (the file counts 25 000 units a second). The tests include this file too (`tests/common`).
pub fn read_align(path: &Path) -> Vec<(f64, f64, String)> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .filter_map(|l| {
            let mut f = l.split_whitespace();
            let start: f64 = f.next()?.parse().ok()?;
            let end: f64 = f.next()?.parse().ok()?;
            let word = f.next()?;
            (word != "sil" && word != "sp").then(|| (start / 25_000.0, end / 25_000.0, word.to_owned()))
        })
        .collect()
}

/// A clip's words (`align/ID.align`).
pub fn words(grid: &Path, id: &str) -> String {
    read_align(&grid.join(format!("align/{id}.align")))
        .into_iter()
        .map(|(_, _, word)| word)
        .collect::<Vec<_>>()
        .join(" ")
}

/// A clip's words with their start times, seconds (`align/ID.align`), as a text-to-speech
/// engine's word timestamps give them.
pub fn timed_words(grid: &Path, id: &str) -> Vec<(String, f64)> {
    read_align(&grid.join(format!("align/{id}.align")))
        .into_iter()
        .map(|(start, _, word)| (word, start))
        .collect()
}

/// The clips of `split` (`SPLIT.txt`), at most `limit`, the damaged ones (`damaged.txt`) left
/// out as `corpus from-videos` leaves them out.
pub fn split(grid: &Path, split: &str, limit: usize) -> Vec<String> {
    let damaged = std::fs::read_to_string(grid.join("damaged.txt")).unwrap_or_default();
    std::fs::read_to_string(grid.join(format!("{split}.txt")))
        .unwrap()
        .split_whitespace()
        .filter(|id| !damaged.split_whitespace().any(|d| d == *id))
        .take(limit)
        .map(str::to_owned)
        .collect()
}

/// The command line `GRID [LIMIT|all] [SPLIT]`: the GRID s1 folder, at most how many clips,
/// and the split (`test` by default).
pub fn args() -> (std::path::PathBuf, usize, String) {
    let mut args = std::env::args().skip(1);
    let grid = std::path::PathBuf::from(args.next().expect("the GRID s1 folder"));
    let limit = args
        .next()
        .map_or(usize::MAX, |n| n.parse().unwrap_or(usize::MAX));
    (grid, limit, args.next().unwrap_or_else(|| "test".into()))
}

/// Clip `id` performed by `talker` from its recorded sound and words (`say --audio CLIP
/// --text WORDS`, up to the pixels), its speech staged in `staging`. The corpus's own words:
/// scored as given, never refused.
pub fn perform(
    talker: &facespace::talker::Talker,
    grid: &Path,
    id: &str,
    staging: &Path,
) -> facespace::talker::Performance {
    use facespace::talker::{SayRequest, Speech};
    let request = SayRequest {
        accept_mismatch: true,
        ..SayRequest::new(Speech::Recording {
            audio: grid.join(format!("clips/{id}.mp4")),
            words: words(grid, id),
        })
    };
    talker.perform(&request, staging).unwrap()
}
