//! Speech out from text: a system text-to-speech engine writes a WAV, which
//! [`crate::align`] then times. Festival with the CMU ARCTIC "slt" HTS voice is preferred — a
//! statistical parametric voice, far more natural than espeak-ng's formant synthesis — and
//! espeak-ng is the fallback. Neither is required: without one, `--say` is an error that
//! gives the install line.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use thiserror::Error;

use crate::programs::program_on_path;

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
        "{words} words: at most {MAX_WORDS} (about 4 minutes of speech) are spoken at once; split the text"
    )]
    TooLong {
        /// How many were given.
        words: usize,
    },
    /// More letters than one utterance takes.
    #[error(
        "{letters} letters: at most {MAX_LETTERS} (about 6 minutes of speech) are spoken at once; split the text"
    )]
    TooManyLetters {
        /// How many were given.
        letters: usize,
    },
    /// A word longer than any the engine is given.
    #[error("a word of {letters} letters: words of at most {MAX_WORD_LETTERS} letters are spoken")]
    WordTooLong {
        /// Its letters.
        letters: usize,
    },
    /// The engine ran past its time and was stopped.
    #[error("{engine} took more than {seconds} s and was stopped")]
    TimedOut {
        /// The engine.
        engine: &'static str,
        /// Its limit, seconds.
        seconds: u64,
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

/// Runs one engine with `text` on its standard input and its standard output into `wav`
/// (emptied first), for at most `limit`: past it the engine is killed and the run is an
/// error. The engine dies with this process (`PR_SET_PDEATHSIG`), so a killed `say` or
/// `serve` leaves no engine speaking on.
fn run(
    engine: &'static str,
    command: &mut Command,
    text: &str,
    wav: &File,
    limit: Duration,
) -> Result<(), TtsError> {
    let io = |source| TtsError::Io { engine, source };
    wav.set_len(0).map_err(io)?;
    (&*wav).seek(SeekFrom::Start(0)).map_err(io)?;
    command
        .stdin(Stdio::piped())
        .stdout(Stdio::from(wav.try_clone().map_err(io)?))
        .stderr(Stdio::piped());
    #[cfg(target_os = "linux")]
    // SAFETY: prctl is async-signal-safe and touches only the child being started.
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(command, || {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            Ok(())
        });
    }
    let mut child = command.spawn().map_err(io)?;
    let (stdin, stderr) = (child.stdin.take(), child.stderr.take());
    let status = std::thread::scope(|scope| {
        // The text goes in, and what the engine says comes back, beside the wait.
        scope.spawn(move || {
            if let Some(mut stdin) = stdin {
                let _ = stdin.write_all(text.as_bytes());
            }
        });
        let said = scope.spawn(move || {
            let mut said = Vec::new();
            if let Some(stderr) = stderr {
                let _ = stderr.take(1 << 20).read_to_end(&mut said);
            }
            said
        });
        let deadline = Instant::now() + limit;
        let status = loop {
            match child.try_wait() {
                Ok(Some(status)) => break Ok(status),
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(10));
                }
                Ok(None) => {
                    let _ = child.kill();
                    let _ = child.wait();
                    break Err(TtsError::TimedOut {
                        engine,
                        seconds: limit.as_secs(),
                    });
                }
                Err(e) => {
                    let _ = child.kill();
                    let _ = child.wait();
                    break Err(io(e));
                }
            }
        };
        status.map(|s| (s, said.join().unwrap_or_default()))
    });
    let (status, said) = status?;
    if status.success() {
        return Ok(());
    }
    let said = String::from_utf8_lossy(&said);
    let tail: String = said.lines().rev().take(3).collect::<Vec<_>>().join(" / ");
    Err(TtsError::Failed {
        engine,
        status: status.to_string(),
        stderr: crate::options::clipped(&tail, 300),
    })
}

/// Most words spoken at once, refused before any engine runs: an engine given 10 000 words
/// ran for five minutes, and 2 000 made more speech than is aligned at once
/// ([`crate::align::MAX_SECONDS`]); 1 200 short words are about 4 minutes of Festival's kal.
pub const MAX_WORDS: usize = 1200;

/// Most letters and digits spoken at once: about 6½ minutes of speech (Festival's voices
/// speak 55–65 ms a letter), under the 10 minutes aligned at once.
pub const MAX_LETTERS: usize = 6000;

/// Longest word spoken: Festival's letter-to-sound rules ran for minutes over one
/// 5 000-letter word (the dictionary's longest words have about 30 letters).
pub const MAX_WORD_LETTERS: usize = 40;

/// How long an engine may take for `letters` letters: far more than Festival's slowest voice
/// needs (slt: about 6 ms a letter, kal: 0.5 ms) on a busy machine.
fn time_limit(letters: usize) -> Duration {
    Duration::from_secs(60) + Duration::from_millis(20 * letters as u64)
}

/// Refuses text that would cost an engine unbounded work or make more speech than is aligned
/// at once ([`MAX_WORDS`], [`MAX_LETTERS`], [`MAX_WORD_LETTERS`]); gives its letters.
pub fn check_text(text: &str) -> Result<usize, TtsError> {
    let words = crate::align::dict::word_count(text);
    if words == 0 {
        return Err(TtsError::NoWords);
    }
    if words > MAX_WORDS {
        return Err(TtsError::TooLong { words });
    }
    let letters = text.chars().filter(|c| c.is_alphanumeric()).count();
    if letters > MAX_LETTERS {
        return Err(TtsError::TooManyLetters { letters });
    }
    let longest = text
        .split(|c: char| !c.is_alphanumeric())
        .map(|w| w.chars().count())
        .max()
        .unwrap_or(0);
    if longest > MAX_WORD_LETTERS {
        return Err(TtsError::WordTooLong { letters: longest });
    }
    Ok(letters)
}

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

/// Speaks `text` into the WAV `out` with the best engine installed ([`speak_into`]).
pub fn speak_as(text: &str, out: &Path, voice: Option<&str>) -> Result<Spoken, TtsError> {
    // Refused before the file is made.
    let letters = check_text(text)?;
    let engine = available().ok_or(TtsError::Missing)?;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(out)
        .map_err(|source| TtsError::Io {
            engine: "text-to-speech",
            source,
        })?;
    speak_checked(engine, text, letters, &file, voice)
}

/// Speaks `text` into the file `wav` (a WAV; emptied first) with the best engine installed:
/// Festival in `voice` (a Festival voice name such as `kal_diphone`; `None`:
/// [`DEFAULT_VOICE`]), falling back to the default voice, then Festival's own, with a note
/// saying so; else espeak-ng. The text goes to the engine through a pipe and the speech comes
/// back through one, so no file of the user's words is ever written (a caller that keeps
/// `wav` in memory — `serve` — leaves nothing on disk if it is killed). Text is checked first
/// ([`check_text`]) and the engine's time bounded.
pub fn speak_into(text: &str, wav: &File, voice: Option<&str>) -> Result<Spoken, TtsError> {
    let letters = check_text(text)?;
    let engine = available().ok_or(TtsError::Missing)?;
    speak_checked(engine, text, letters, wav, voice)
}

/// [`speak_into`] of text [`check_text`] took (its `letters`) with `engine`.
fn speak_checked(
    engine: Engine,
    text: &str,
    letters: usize,
    wav: &File,
    voice: Option<&str>,
) -> Result<Spoken, TtsError> {
    let limit = time_limit(letters);
    match engine {
        Engine::Festival => {
            let engine = "Festival";
            let asked = voice.unwrap_or(DEFAULT_VOICE);
            let mut tried = vec![asked];
            if asked != DEFAULT_VOICE {
                tried.push(DEFAULT_VOICE);
            }
            // Festival exits 0 without writing anything when a voice is not installed: a
            // voice spoke only if the WAV is there.
            let wrote = |ok: Result<(), TtsError>| -> Result<bool, TtsError> {
                match ok {
                    Err(e @ TtsError::TimedOut { .. }) => Err(e),
                    ok => Ok(ok.is_ok() && wav.metadata().is_ok_and(|m| m.len() > 44)),
                }
            };
            for v in tried.iter().filter(|v| plain_voice(v)) {
                let ok = run(
                    engine,
                    Command::new("text2wave")
                        .arg("-eval")
                        .arg(format!("(voice_{v})"))
                        .args(["-o", "-"]),
                    text,
                    wav,
                    limit,
                );
                if wrote(ok)? {
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
            run(
                engine,
                Command::new("text2wave").args(["-o", "-"]),
                text,
                wav,
                limit,
            )?;
            if !wrote(Ok(()))? {
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
        Engine::EspeakNg => {
            let engine = "espeak-ng";
            run(
                engine,
                Command::new("espeak-ng").args(["--stdin", "--stdout"]),
                text,
                wav,
                limit,
            )?;
            close_streamed_wav(wav).map_err(|source| TtsError::Io { engine, source })?;
            Ok(Spoken {
                engine: Engine::EspeakNg,
                voice: "espeak-ng's default".into(),
                note: voice.map(|v| format!("no Festival here; espeak-ng spoke instead of {v}")),
            })
        }
    }
}

/// Writes the true sizes into a WAV written to a pipe (espeak-ng's `--stdout` leaves
/// 0x7ffff000 in its RIFF and `data` sizes, not knowing the length): a plain 44-byte header.
fn close_streamed_wav(wav: &File) -> std::io::Result<()> {
    let len = wav.metadata()?.len();
    let mut head = [0u8; 44];
    let mut f = wav;
    f.seek(SeekFrom::Start(0))?;
    f.read_exact(&mut head)?;
    if &head[..4] != b"RIFF" || &head[36..40] != b"data" {
        return Ok(());
    }
    let riff = u32::try_from(len - 8).unwrap_or(u32::MAX);
    let data = u32::try_from(len - 44).unwrap_or(u32::MAX);
    f.seek(SeekFrom::Start(4))?;
    f.write_all(&riff.to_le_bytes())?;
    f.seek(SeekFrom::Start(40))?;
    f.write_all(&data.to_le_bytes())?;
    f.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each cap refuses just past its value and takes it (issue 69, R5-7 and R5-17).
    #[test]
    fn text_is_bounded_before_any_engine() {
        assert!(matches!(check_text(" ,. "), Err(TtsError::NoWords)));
        assert_eq!(check_text("Hello there.").unwrap(), 10);
        let words = |n: usize| vec!["a"; n].join(" ");
        check_text(&words(MAX_WORDS)).unwrap();
        assert!(matches!(check_text(&words(MAX_WORDS + 1)), Err(TtsError::TooLong { words: 1201 })));
        let letters = |n: usize| vec!["abcdefghij"; n / 10].join(" ");
        check_text(&letters(MAX_LETTERS)).unwrap();
        assert!(matches!(
            check_text(&letters(MAX_LETTERS + 10)),
            Err(TtsError::TooManyLetters { .. })
        ));
        check_text(&"a".repeat(MAX_WORD_LETTERS)).unwrap();
        assert!(matches!(
            check_text(&"a".repeat(MAX_WORD_LETTERS + 1)),
            Err(TtsError::WordTooLong { letters: 41 })
        ));
    }

    /// A WAV written to a pipe gets its true sizes.
    #[test]
    fn a_streamed_wav_header_is_closed() {
        let mut bytes = b"RIFF".to_vec();
        bytes.extend(0x7fff_f000u32.to_le_bytes());
        bytes.extend(b"WAVEfmt ");
        bytes.extend(16u32.to_le_bytes());
        bytes.extend([1, 0, 1, 0]);
        bytes.extend(16_000u32.to_le_bytes());
        bytes.extend(32_000u32.to_le_bytes());
        bytes.extend([2, 0, 16, 0]);
        bytes.extend(b"data");
        bytes.extend(0x7fff_f000u32.to_le_bytes());
        bytes.extend([0u8; 100]);
        let mut file = tempfile::tempfile().unwrap();
        file.write_all(&bytes).unwrap();
        close_streamed_wav(&file).unwrap();
        let mut back = Vec::new();
        file.seek(SeekFrom::Start(0)).unwrap();
        file.read_to_end(&mut back).unwrap();
        assert_eq!(u32::from_le_bytes(back[4..8].try_into().unwrap()), 136);
        assert_eq!(u32::from_le_bytes(back[40..44].try_into().unwrap()), 100);
    }
}
