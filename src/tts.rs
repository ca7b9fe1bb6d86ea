//! Speech out from text: a system text-to-speech engine writes a WAV, which
//! [`crate::align`] then times. Festival with the CMU ARCTIC "slt" HTS voice is preferred — a
//! statistical parametric voice, far more natural than espeak-ng's formant synthesis — and
//! espeak-ng is the fallback. Neither is required: without one, `--say` is an error that
//! gives the install line.

use std::path::Path;
use std::process::{Command, Stdio};

use thiserror::Error;

use crate::video::program_on_path;

/// The one line that installs the preferred engine on Debian/Ubuntu.
pub const INSTALL_LINE: &str = "apt-get install festival festvox-us-slt-hts";

/// What can go wrong making speech.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum TtsError {
    /// No engine on PATH.
    #[error(
        "no text-to-speech engine found (looked for Festival's text2wave and espeak-ng on PATH); install one: `{INSTALL_LINE}` (or `apt-get install espeak-ng`)"
    )]
    Missing,
    /// The engine ran and failed.
    #[error("{engine} failed ({status}): {stderr}")]
    Failed {
        /// The engine.
        engine: &'static str,
        /// How it exited.
        status: String,
        /// The end of what it printed.
        stderr: String,
    },
    /// The engine could not be started or its output read.
    #[error("{engine}: {source}")]
    Io {
        /// The engine.
        engine: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// Nothing to say.
    #[error("no words to say")]
    NoWords,
    /// More words than one utterance takes.
    #[error(
        "{words} words: at most {MAX_WORDS} (about 13 minutes of speech) are spoken at once; split the text"
    )]
    TooLong {
        /// How many were given.
        words: usize,
    },
}

/// The engine that spoke.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Engine {
    /// Festival (`text2wave`), with the slt HTS voice when it is installed.
    Festival,
    /// espeak-ng.
    EspeakNg,
}

impl Engine {
    /// The engine's name.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Festival => "Festival",
            Engine::EspeakNg => "espeak-ng",
        }
    }
}

/// The engine `speak` would use, if any.
pub fn available() -> Option<Engine> {
    if program_on_path("text2wave").is_some() {
        Some(Engine::Festival)
    } else if program_on_path("espeak-ng").is_some() {
        Some(Engine::EspeakNg)
    } else {
        None
    }
}

fn run(engine: &'static str, command: &mut Command) -> Result<(), TtsError> {
    let out = command
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .map_err(|source| TtsError::Io { engine, source })?;
    if out.status.success() {
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    let tail: String = stderr.lines().rev().take(3).collect::<Vec<_>>().join(" / ");
    Err(TtsError::Failed {
        engine,
        status: out.status.to_string(),
        stderr: tail,
    })
}

/// Most words `speak` takes at once: about 13 minutes of speech, refused before any engine
/// runs (an engine given 10 000 words ran for five minutes before the length was refused).
pub const MAX_WORDS: usize = 2000;

/// Speaks `text` into the WAV `out` with the best engine installed. The text is handed to
/// Festival in a file beside `out` (`out` with `.txt`), so a caller that puts `out` in its
/// own staging folder leaves nothing of the user's words elsewhere if it is killed.
pub fn speak(text: &str, out: &Path) -> Result<Engine, TtsError> {
    let words = crate::align::dict::words(text).len();
    if words == 0 {
        return Err(TtsError::NoWords);
    }
    if words > MAX_WORDS {
        return Err(TtsError::TooLong { words });
    }
    match available() {
        Some(Engine::Festival) => {
            let engine = "Festival";
            let input = out.with_extension("txt");
            std::fs::write(&input, text).map_err(|source| TtsError::Io { engine, source })?;
            let with_voice = run(
                engine,
                Command::new("text2wave")
                    .arg("-eval")
                    .arg("(voice_cmu_us_slt_arctic_hts)")
                    .arg(&input)
                    .arg("-o")
                    .arg(out),
            );
            // Without the HTS voice, Festival's default voice.
            if with_voice.is_err() {
                run(
                    engine,
                    Command::new("text2wave").arg(&input).arg("-o").arg(out),
                )?;
            }
            Ok(Engine::Festival)
        }
        Some(Engine::EspeakNg) => {
            run(
                "espeak-ng",
                Command::new("espeak-ng")
                    .arg("-w")
                    .arg(out)
                    .arg("--")
                    .arg(text),
            )?;
            Ok(Engine::EspeakNg)
        }
        None => Err(TtsError::Missing),
    }
}
