//! `facespace._facespace`: the library to Python (issue 36) — a talker, its live session
//! drawn on the CPU (`live::Screen`), and `say` to a file. The Python side
//! (`facespace/__init__.py`) turns arrays into bytes and pictures into numpy arrays. Errors
//! arrive as `facespace.FacespaceError` carrying the library's message; the GIL is released
//! while the library works.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Mutex, OnceLock};

use facespace::live::{Screen, Session, Stage};
use facespace::phonemes::{Phone, Segment};
use facespace::render::scale::Fit;
use facespace::talker::{SayRequest, Speech};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

create_exception!(_facespace, FacespaceError, pyo3::exceptions::PyException);

fn error(e: impl std::fmt::Display) -> PyErr {
    FacespaceError::new_err(e.to_string())
}

/// A loaded talker and its stage. Loaded once per folder and kept for the life of the
/// interpreter (a talker is what a process serves; 100–200 MB).
struct Loaded {
    talker: &'static facespace::talker::Talker,
    stage: &'static Stage<'static>,
}

/// The process in which a talker was first loaded, and so the library's worker threads (the
/// rayon pool, locks they may hold) started: 0 before. A child forked from it (`os.fork`,
/// `multiprocessing`'s fork start method) has none of those threads, and work handed to them
/// would wait forever (issue 69, R5-10): it is refused instead, saying what to do.
static STARTED_IN: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

/// Refuses a call in a child forked after a talker was loaded (see [`STARTED_IN`]).
fn not_forked() -> PyResult<()> {
    let started = STARTED_IN.load(std::sync::atomic::Ordering::Relaxed);
    if started == 0 || started == std::process::id() {
        Ok(())
    } else {
        Err(error(format!(
            "facespace cannot work in a process forked from one that had loaded a talker (process {started}): its worker threads are not copied by fork; use multiprocessing's \"spawn\" or \"forkserver\" start method, or load talkers only in the child"
        )))
    }
}

fn load(path: &std::path::Path) -> Result<&'static Loaded, String> {
    let _ = STARTED_IN.compare_exchange(
        0,
        std::process::id(),
        std::sync::atomic::Ordering::Relaxed,
        std::sync::atomic::Ordering::Relaxed,
    );
    static LOADED: OnceLock<Mutex<HashMap<PathBuf, &'static Loaded>>> = OnceLock::new();
    let key = std::fs::canonicalize(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut loaded = LOADED
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(l) = loaded.get(&key) {
        return Ok(l);
    }
    let talker: &'static _ =
        Box::leak(Box::new(facespace::talker::Talker::load(&key).map_err(|e| e.to_string())?));
    let stage: &'static _ = Box::leak(Box::new(Stage::new(talker, 0).map_err(|e| e.to_string())?));
    // Decoded now, with the talker, so a session's first picture does not wait for them.
    talker.mouths().map_err(|e| e.to_string())?;
    let l: &'static Loaded = Box::leak(Box::new(Loaded { talker, stage }));
    loaded.insert(key, l);
    Ok(l)
}

/// A talker folder (`facespace talker build`).
#[pyclass(frozen, module = "facespace._facespace")]
struct Talker {
    loaded: &'static Loaded,
}

#[pymethods]
impl Talker {
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        not_forked()?;
        let loaded = py.allow_threads(|| load(&path)).map_err(error)?;
        Ok(Talker { loaded })
    }

    /// Frames per second of the talker's video.
    #[getter]
    fn fps(&self) -> f64 {
        self.loaded.talker.footage.fps
    }

    /// (width, height) of its frames.
    #[getter]
    fn size(&self) -> (u32, u32) {
        self.loaded.talker.footage.size
    }

    /// Its name.
    #[getter]
    fn name(&self) -> String {
        self.loaded.talker.manifest.name.clone()
    }

    /// Says `text` (text-to-speech in the talker's voice), or the recording `audio` (with its
    /// `words`, or recognised without them), into the MP4 `out`; returns the report as a dict
    /// of its JSON.
    #[pyo3(signature = (out, text=None, audio=None, words=None))]
    fn say(
        &self,
        py: Python<'_>,
        out: PathBuf,
        text: Option<String>,
        audio: Option<PathBuf>,
        words: Option<String>,
    ) -> PyResult<String> {
        not_forked()?;
        let speech = match (text, audio, words) {
            (Some(t), None, None) => Speech::Text(t),
            (None, Some(a), Some(w)) => Speech::Recording { audio: a, words: w },
            (None, Some(a), None) => Speech::Sound(a),
            _ => return Err(error("say: give text, or audio (with its words or without)")),
        };
        let talker = self.loaded.talker;
        let report = py
            .allow_threads(|| talker.say(&SayRequest::new(speech), &out, |_| {}).map_err(Box::new))
            .map_err(error)?;
        serde_json::to_string(&report).map_err(error)
    }

    /// `text` spoken in the talker's voice: its sound as int16 bytes at 16 kHz, and its
    /// phones (ARPAbet, start, end in seconds) aligned to that sound — what a session given
    /// phones takes.
    fn speak(&self, py: Python<'_>, text: String) -> PyResult<Spoken> {
        not_forked()?;
        let talker = self.loaded.talker;
        let (phones, sound) = py
            .allow_threads(|| -> Result<_, String> {
                let (phones, wav) = talker.speak_in_memory(&text).map_err(|e| e.to_string())?;
                let rate = facespace::align::frontend::SAMPLE_RATE;
                let sound = facespace::audio::read(wav.path(), rate, facespace::align::MAX_SECONDS)
                    .map_err(|e| e.to_string())?;
                Ok((phones, sound))
            })
            .map_err(error)?;
        let pcm: Vec<u8> = sound
            .samples
            .iter()
            .flat_map(|&x| facespace::audio::to_pcm16(x).to_le_bytes())
            .collect();
        let phones = phones
            .iter()
            .map(|p| (p.phone.name().to_ascii_uppercase(), p.start, p.end))
            .collect();
        Ok((PyBytes::new(py, &pcm).unbind(), sound.rate, phones))
    }

    /// A live session: phones recognised from its sound, or given ("phones"), or aligned to
    /// words given with their start times ("words"); pictures of `size` (width, height) fitted
    /// by `fit` ("contain" or "cover"), the footage's own size by default.
    #[pyo3(signature = (given="sound", size=None, fit="contain"))]
    fn session(&self, given: &str, size: Option<(u32, u32)>, fit: &str) -> PyResult<LiveSession> {
        not_forked()?;
        let talker = self.loaded.talker;
        let session = match given {
            "sound" => Session::new(talker),
            "phones" => Session::with_given_phones(talker),
            "words" => Session::with_given_words(talker),
            _ => return Err(error(format!("given {given:?}: \"sound\", \"phones\" or \"words\""))),
        };
        let fit: Fit = fit.parse().map_err(error)?;
        let size = size.unwrap_or(talker.footage.size);
        if size.0 == 0 || size.1 == 0 || size.0 > MAX_SIDE || size.1 > MAX_SIDE {
            return Err(error(format!("size {size:?}: each side 1 to {MAX_SIDE} pixels")));
        }
        let screen = Screen::with_size(session, self.loaded.stage, size, fit).map_err(error)?;
        Ok(LiveSession {
            size: screen.size(),
            screen: Some(screen),
            fps: talker.footage.fps,
        })
    }
}

/// A live session drawn on the CPU: push sound (and phones), take pictures.
#[pyclass(module = "facespace._facespace")]
struct LiveSession {
    screen: Option<Screen<'static, 'static>>,
    size: (u32, u32),
    fps: f64,
}

/// The longest side of a picture a session draws (8K).
const MAX_SIDE: u32 = 7680;

/// Speech made from text: int16 bytes, their rate, and the phones (ARPAbet, start, end).
type Spoken = (Py<PyBytes>, u32, Vec<(String, f64, f64)>);

/// A picture: (index, time, RGB bytes, landmarks as float32 x, y bytes, face drawn, speaking).
type PictureTuple = (usize, f64, Py<PyBytes>, Py<PyBytes>, bool, bool);

impl LiveSession {
    fn screen(&mut self) -> PyResult<&mut Screen<'static, 'static>> {
        not_forked()?;
        self.screen
            .as_mut()
            .ok_or_else(|| error("this session is closed"))
    }

    /// Runs `step` (the screen's pull, finish or idle_until) with the GIL released; the
    /// pictures it made ready are drawn one by one by `next_picture`. Returns how many.
    fn settle(
        &mut self,
        py: Python<'_>,
        step: impl FnOnce(&mut Screen<'static, 'static>) -> Result<(), facespace::live::LiveError> + Send,
    ) -> PyResult<usize> {
        let screen = self.screen()?;
        py.allow_threads(|| step(screen).map(|()| screen.ready()))
            .map_err(error)
    }

    fn picture(py: Python<'_>, p: facespace::live::Picture) -> PictureTuple {
        let bytes = PyBytes::new(py, p.image.as_raw()).unbind();
        let points: Vec<u8> = p
            .landmarks
            .iter()
            .flat_map(|q| [q[0] as f32, q[1] as f32])
            .flat_map(f32::to_le_bytes)
            .collect();
        let points = PyBytes::new(py, &points).unbind();
        (p.index, p.time, bytes, points, p.face, p.speaking)
    }
}

#[pymethods]
impl LiveSession {
    /// Frames per second.
    #[getter]
    fn fps(&self) -> f64 {
        self.fps
    }

    /// (width, height) of every picture.
    #[getter]
    fn size(&self) -> (u32, u32) {
        self.size
    }

    /// Seconds of sound taken (session time: where the next chunk starts).
    #[getter]
    fn seconds(&mut self) -> PyResult<f64> {
        Ok(self.screen()?.session().seconds())
    }

    /// Takes sound: `samples` as little-endian float32 bytes (mono, −1…1) at `rate` Hz.
    fn push_f32(&mut self, py: Python<'_>, samples: &[u8], rate: u32) -> PyResult<()> {
        if !samples.len().is_multiple_of(4) {
            return Err(error("float32 samples: the byte count must be a multiple of 4"));
        }
        // Judged before the samples are copied (the session judges it again).
        let seconds = samples.len() as f64 / 4.0 / f64::from(rate.max(1));
        if seconds > facespace::live::MAX_CHUNK_SECONDS {
            return Err(error(facespace::live::LiveError::ChunkTooLong { seconds }));
        }
        let x: Vec<f32> = samples
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let screen = self.screen()?;
        py.allow_threads(|| screen.session().push_audio(&x, rate))
            .map_err(error)
    }

    /// Phones with their times (session seconds): a list of (ARPAbet phone, start, end).
    fn push_phones(&mut self, phones: Vec<(String, f64, f64)>) -> PyResult<()> {
        let segments = phones
            .iter()
            .map(|(p, start, end)| {
                let phone = Phone::parse(p).ok_or_else(|| error(format!("unknown phone {p:?}")))?;
                Ok(Segment {
                    start: *start,
                    end: *end,
                    phone,
                })
            })
            .collect::<PyResult<Vec<_>>>()?;
        self.screen()?.session().push_phones(&segments).map_err(error)
    }

    /// Words with their start times (session seconds): a list of (word, start), in order.
    fn push_words(&mut self, py: Python<'_>, words: Vec<(String, f64)>) -> PyResult<()> {
        let screen = self.screen()?;
        py.allow_threads(|| screen.session().push_words(&words))
            .map_err(error)
    }

    /// Takes the frames settled so far; returns how many pictures are ready to draw
    /// (`next_picture`).
    fn pull(&mut self, py: Python<'_>) -> PyResult<usize> {
        self.settle(py, |s| s.pull().map(drop))
    }

    /// [`pull`], and the footage as it is up to frame `until` while nothing is said.
    fn idle_until(&mut self, py: Python<'_>, until: usize) -> PyResult<usize> {
        self.settle(py, |s| s.idle_until(until).map(drop))
    }

    /// Ends the utterance: every picture of it is ready.
    fn finish(&mut self, py: Python<'_>) -> PyResult<usize> {
        self.settle(py, |s| s.finish().map(drop))
    }

    /// Draws the next picture ready (see `Picture`), or None.
    fn next_picture(&mut self, py: Python<'_>) -> PyResult<Option<PictureTuple>> {
        let screen = self.screen()?;
        let p = py.allow_threads(|| screen.next_picture()).map_err(error)?;
        Ok(p.map(|p| Self::picture(py, p)))
    }

    /// An interruption: the next picture is the footage's own face.
    fn clear(&mut self) -> PyResult<()> {
        self.screen()?.clear();
        Ok(())
    }

    /// The next frame index a picture will have.
    #[getter]
    fn next_frame(&mut self) -> PyResult<usize> {
        Ok(self.screen()?.session().next_frame())
    }

    /// Ends the session; any later call raises.
    fn close(&mut self) {
        self.screen = None;
    }
}

#[pymodule]
fn _facespace(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FacespaceError", m.py().get_type::<FacespaceError>())?;
    // The checkout the package was built from: its committed GRID s1 talker is the default
    // where it still exists.
    m.add("BUILT_FROM", concat!(env!("CARGO_MANIFEST_DIR"), "/.."))?;
    m.add_class::<Talker>()?;
    m.add_class::<LiveSession>()?;
    Ok(())
}
