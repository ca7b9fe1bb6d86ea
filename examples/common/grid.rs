//! GRID s1 helpers shared by the examples that read its folder.

use std::path::Path;

/// A clip's words: `align/ID.align` without `sil` / `sp`.
pub fn words(grid: &Path, id: &str) -> String {
    std::fs::read_to_string(grid.join(format!("align/{id}.align")))
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .filter(|w| *w != "sil" && *w != "sp")
        .collect::<Vec<_>>()
        .join(" ")
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
