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

/// Festival's voice when none is asked for: the CMU ARCTIC "slt" HTS voice (a woman).
pub const DEFAULT_VOICE: &str = "cmu_us_slt_arctic_hts";

/// Speech that was made: by which engine, in which voice, and why not the voice asked for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Spoken {
    /// The engine.
    pub engine: Engine,
    /// The voice that spoke (Festival's name; espeak-ng's default voice).
    pub voice: String,
    /// When the voice asked for was not installed: what spoke instead, and how to get it.
    pub note: Option<String>,
}

/// Speaks `text` into the WAV `out` with the best engine installed, in Festival's slt voice
/// ([`speak_as`] with no voice).
pub fn speak(text: &str, out: &Path) -> Result<Engine, TtsError> {
    speak_as(text, out, None).map(|s| s.engine)
}

/// Whether `voice` is a plain Festival voice name (letters, digits, `_`): it is spliced into
/// a Scheme expression, so nothing else is taken.
fn plain_voice(voice: &str) -> bool {
    !voice.is_empty() && voice.len() <= 64 && voice.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Speaks `text` into the WAV `out` with the best engine installed: Festival in `voice` (a
/// Festival voice name such as `kal_diphone`; `None`: [`DEFAULT_VOICE`]), falling back to
/// the default voice, then Festival's own, with a note saying so; else espeak-ng. The text is
/// handed to Festival in a file beside `out` (`out` with `.txt`), so a caller that puts `out`
/// in its own staging folder leaves nothing of the user's words elsewhere if it is killed.
pub fn speak_as(text: &str, out: &Path, voice: Option<&str>) -> Result<Spoken, TtsError> {
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
            let asked = voice.unwrap_or(DEFAULT_VOICE);
            let mut tried = vec![asked];
            if asked != DEFAULT_VOICE {
                tried.push(DEFAULT_VOICE);
            }
            // Festival exits 0 without writing anything when a voice is not installed: a
            // voice spoke only if the WAV is there.
            let wrote = |ok: Result<(), TtsError>| {
                ok.is_ok() && std::fs::metadata(out).is_ok_and(|m| m.len() > 44)
            };
            for v in tried.iter().filter(|v| plain_voice(v)) {
                let _ = std::fs::remove_file(out);
                let ok = run(
                    engine,
                    Command::new("text2wave")
                        .arg("-eval")
                        .arg(format!("(voice_{v})"))
                        .arg(&input)
                        .arg("-o")
                        .arg(out),
                );
                if wrote(ok) {
                    let note = (*v != asked).then(|| {
                        format!("Festival has no voice {asked} here; {v} spoke instead")
                    });
                    return Ok(Spoken {
                        engine: Engine::Festival,
                        voice: (*v).to_owned(),
                        note,
                    });
                }
            }
            // Without either voice, Festival's default voice.
            let _ = std::fs::remove_file(out);
            run(
                engine,
                Command::new("text2wave").arg(&input).arg("-o").arg(out),
            )?;
            if !wrote(Ok(())) {
                return Err(TtsError::Failed {
                    engine,
                    status: "no speech written".into(),
                    stderr: format!("no Festival voice spoke (tried {})", tried.join(", ")),
                });
            }
            Ok(Spoken {
                engine: Engine::Festival,
                voice: "Festival's default".into(),
                note: Some(format!(
                    "Festival has no voice {asked} here; its default voice spoke instead"
                )),
            })
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
            Ok(Spoken {
                engine: Engine::EspeakNg,
                voice: "espeak-ng's default".into(),
                note: voice.map(|v| format!("no Festival here; espeak-ng spoke instead of {v}")),
            })
        }
        None => Err(TtsError::Missing),
    }
}
