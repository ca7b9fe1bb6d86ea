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
