//! External programs found on PATH at run time (ffmpeg, Festival's text2wave, espeak-ng):
//! detected and reported, never required.

use std::path::PathBuf;

/// A system ffmpeg on PATH, if any (detected at run time, never required).
pub fn system_ffmpeg() -> Option<PathBuf> {
    program_on_path("ffmpeg")
}

/// The first file named `program` in a folder of PATH.
pub fn program_on_path(program: &str) -> Option<PathBuf> {
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|p| p.join(program))
            .find(|p| p.is_file())
    })
}
