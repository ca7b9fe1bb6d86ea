//! `serve`: the live page (issue 35). A browser renders the talker's face itself (WebGL2):
//! the model — shape basis, appearance basis in the reference frame, mesh — and the living
//! frame's plan arrive once; then per frame only the face-space point travels (the talker's
//! layout in `f32`: 4 × (4 + shape + appearance) bytes, 268 for GRID s1), with the sound.
//!
//! A page opens a session and either types a sentence — spoken by the text-to-speech engine,
//! aligned, and sent back as sound and frames timed from the frame where the page will start
//! to play it — or streams its microphone, whose phones are recognised as they come
//! ([`crate::live::Session`]). Every frame is placed on the living frame ([`Stage`]), so the
//! page draws it over the footage frame of the same index, and while nothing is said the
//! footage plays as it is.
//!
//! The event loop is [`crate::http`]'s (loopback, Host/Origin rules, bounded connections and
//! bodies); speech from text runs on its workers. Sessions are bounded ([`MAX_SESSIONS`]: the
//! one used longest ago makes room) and each has its own lock, so a slow sentence never
//! holds another page's microphone.
//!
//! Frames go out as one binary packet per reply ([`packet`]): little-endian `u32`s magic
//! `FSPF`, first frame, count, dims, start frame of the sound (when it has one) and its byte
//! length; then one byte per frame (1 when a phone is spoken), padded to 4; the values as
//! `f32`; then the sound (a WAV file).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::Deserialize;
use serde_json::json;
use thiserror::Error;

use crate::http::{self, Answer, Reply, Request, Server};
use crate::live::{LiveError, LiveFrame, Session, Stage};
use crate::phonemes::Segment;
use crate::render::{DEFAULT_FEATHER, Edge};
use crate::talker::{Talker, TalkerError};

const PAGE: &str = include_str!("page.html");

/// Sessions held at once; a new one beyond this drops the one used longest ago.
pub const MAX_SESSIONS: usize = 1024;

/// Longest text a page may type, characters.
pub const MAX_TEXT: usize = 600;

/// Most sound one microphone request may carry, seconds.
pub const MAX_CHUNK_SECONDS: f64 = 2.0;

/// How far ahead of the page's clock a sentence's sound is placed, beyond the time its speech
/// took to make: the synthesis, the reply's way back and the page's decoding of the sound.
pub const SAY_LEAD: Duration = Duration::from_millis(250);

/// `FSPF`, the first word of a frame packet.
pub const MAGIC: u32 = u32::from_le_bytes(*b"FSPF");

/// What can go wrong starting the page.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ServeError {
    /// The address could not be used.
    #[error(transparent)]
    Http(#[from] http::HttpError),
    /// The living frame could not be planned, or the recogniser could not be loaded.
    #[error(transparent)]
    Live(#[from] LiveError),
    /// A footage clip could not be read.
    #[error("the talker's footage: {0}")]
    Footage(#[from] crate::video::VideoError),
    /// A footage frame could not be encoded for the page, or a file written.
    #[error("preparing the page: {0}")]
    Prepare(String),
    /// The call's recording could not be encoded.
    #[error("the call's recording: {0}")]
    Call(#[from] crate::codec::CodecError),
    /// The call's recording runs at another frame rate than the talker.
    #[error("{video}: {fps} fps; the call must run at the talker's {talker} fps")]
    CallRate {
        /// The recording.
        video: std::path::PathBuf,
        /// Its rate.
        fps: f64,
        /// The talker's.
        talker: f64,
    },
}

/// What happened, for the command line to report.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A page opened a session.
    Opened(String),
    /// A sentence was spoken: the session, frames, seconds from request to reply.
    Said(String, usize, f64),
    /// A request was refused: path and why.
    Refused(String, String),
    /// A notice from the event loop (connections refused for want of resources).
    Notice(String),
}

/// One page's session: the typed sentences' (phones given) and the microphone's (phones
/// heard), each on the same frame clock.
struct Client<'t> {
    typed: Session<'t>,
    heard: Option<Session<'t>>,
    /// A call in progress: the page frame where it starts, when it started, frames sent.
    call: Option<(usize, Instant, usize)>,
    used: Instant,
}

type Clients<'t> = Mutex<HashMap<String, Arc<Mutex<Client<'t>>>>>;

/// The live page's server on one talker.
pub struct LiveServer<'t> {
    server: Server,
    talker: &'t Talker,
    stage: Stage<'t>,
    clients: Clients<'t>,
    /// The model as the page takes it (`/api/model`, `/api/appearance`), made once.
    model: crate::http::Body,
    appearance: crate::http::Body,
    /// Every footage frame as JPEG, in footage order.
    footage: Vec<crate::http::Body>,
    ids: Mutex<crate::rng::Rng>,
    call: Option<Call>,
}

/// A recording streamed through face-space (`serve --call VIDEO`): tracked and projected
/// when the server starts, each frame quantised to 8 bits per value over the clip's range
/// (the codec's `--bits 8`), then released to a page at the recording's own pace, as a
/// camera would deliver it.
struct Call {
    /// Frames × dims codes.
    codes: Vec<u8>,
    quantisation: crate::codec::clip::Quantisation,
    frames: usize,
    dims: usize,
    /// The recording's sound as M4A (AAC copied from the MP4), if it has one.
    audio: Option<crate::http::Body>,
}

/// How far ahead of its frames a call's sound is placed on the page's clock, and how long
/// a released frame may wait on the page: the jitter buffer.
pub const CALL_LEAD: Duration = Duration::from_millis(500);

/// `FSPQ`, the first word of a packet of 8-bit frames (a call's).
pub const MAGIC_QUANTISED: u32 = u32::from_le_bytes(*b"FSPQ");

/// A request's refusal: status and why.
type Refusal = (u16, String);

fn bad(why: impl Into<String>) -> Refusal {
    (400, why.into())
}

impl<'t> LiveServer<'t> {
    /// Binds `addr` (loopback unless `allow_remote`) for `talker`'s page; plans its living
    /// frame, loads its recogniser and decodes its footage (as JPEG) now, so no page waits for
    /// them.
    pub fn bind(talker: &'t Talker, addr: &str, allow_remote: bool) -> Result<Self, ServeError> {
        let server = Server::bind(addr, allow_remote)?;
        let stage = Stage::new(talker, 0)?;
        talker
            .live_recogniser()
            .map_err(|e| ServeError::Live(e.into()))?;
        let seed = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64)
            ^ u64::from(std::process::id());
        Ok(LiveServer {
            server,
            talker,
            model: model_json(talker, &stage, None).to_string().into_bytes().into(),
            appearance: appearance_layers(talker).into(),
            stage,
            clients: Mutex::new(HashMap::new()),
            footage: footage_jpegs(&talker.footage)?.into_iter().map(Into::into).collect(),
            ids: Mutex::new(crate::rng::Rng::new(seed)),
            call: None,
        })
    }

    /// The same server offering a call: `video` (of the talker, at the talker's frame rate)
    /// tracked and projected through face-space now, streamed to a page that asks at 8 bits
    /// per value, with its sound.
    pub fn with_call(self, video: &std::path::Path) -> Result<Self, ServeError> {
        let options = crate::codec::EncodeOptions {
            bits: Some(8),
            ..Default::default()
        };
        let source = crate::video::Source::open(video)?;
        let fps = source.info().fps;
        if (fps - self.talker.footage.fps).abs() > 1e-3 {
            return Err(ServeError::CallRate {
                video: video.into(),
                fps,
                talker: self.talker.footage.fps,
            });
        }
        let encoded = crate::codec::encode(&self.talker.model, source, &options, crate::no_progress)?;
        let clip = encoded.clip;
        let quantisation = clip.quantisation.clone().ok_or_else(|| ServeError::Prepare("the call was not quantised".into()))?;
        let codes: Vec<u8> = quantisation
            .encode(clip.frames.as_slice())
            .into_iter()
            .map(|c| c.min(255) as u8)
            .collect();
        let staging = tempfile::tempdir().map_err(|e| ServeError::Prepare(e.to_string()))?;
        let m4a = staging.path().join("call.m4a");
        let audio = if crate::video::extract_audio(video, &m4a)? {
            Some(std::fs::read(&m4a).map_err(|e| ServeError::Prepare(e.to_string()))?.into())
        } else {
            None
        };
        let call = Call {
            codes,
            quantisation,
            frames: clip.frames.len(),
            dims: clip.frames.layout().dims(),
            audio,
        };
        Ok(LiveServer {
            model: model_json(self.talker, &self.stage, Some(&call)).to_string().into_bytes().into(),
            call: Some(call),
            ..self
        })
    }

    /// The same server holding to other limits.
    pub fn with_limits(self, limits: http::Limits) -> Self {
        LiveServer {
            server: self.server.with_limits(limits),
            ..self
        }
    }

    /// The page's address.
    pub fn url(&self) -> String {
        self.server.url()
    }

    /// Sessions held now.
    pub fn sessions(&self) -> usize {
        lock(&self.clients).len()
    }

    /// Serves the page until `stop` returns true, telling `on_event` what happens.
    pub fn run(&self, on_event: impl FnMut(Event) + Send, stop: impl Fn() -> bool) {
        let on_event = Mutex::new(on_event);
        let tell = |e: Event| (lock(&on_event))(e);
        self.server.serve(
            |request| {
                let refused = |(status, why): Refusal| {
                    tell(Event::Refused(request.path.clone(), why.clone()));
                    Answer::Now(Reply::error(status, why))
                };
                match self.answer(request, &tell) {
                    Ok(answer) => answer,
                    Err(r) => refused(r),
                }
            },
            stop,
            |notice| tell(Event::Notice(notice)),
        )
    }

    fn answer<'a>(
        &'a self,
        request: &Request,
        tell: &'a (impl Fn(Event) + Sync),
    ) -> Result<Answer<'a>, Refusal> {
        let ok = |r: Reply| Ok(Answer::Now(r));
        match (request.post, request.path.as_str()) {
            (false, "/") => ok(Reply::ok(PAGE.as_bytes(), "text/html; charset=utf-8")),
            (false, "/api/model") => ok(Reply::ok(self.model.clone(), "application/json")),
            (false, "/api/appearance") => {
                ok(Reply::ok(self.appearance.clone(), "application/octet-stream"))
            }
            (false, "/api/call/audio.m4a") => match self.call.as_ref().and_then(|c| c.audio.as_ref()) {
                Some(audio) => ok(Reply::ok(audio.clone(), "audio/mp4")),
                None => Err((404, "the call has no sound".into())),
            },
            (false, path) => {
                let jpeg = path
                    .strip_prefix("/footage/")
                    .and_then(|f| f.strip_suffix(".jpg"))
                    .and_then(|g| g.parse::<usize>().ok())
                    .and_then(|g| self.footage.get(g))
                    .ok_or((404, "not found".to_string()))?;
                ok(Reply::ok(jpeg.clone(), "image/jpeg"))
            }
            (true, "/api/session") => {
                let id = format!("{:016x}", lock(&self.ids).next_u64());
                self.open(&id);
                tell(Event::Opened(id.clone()));
                ok(Reply::json(json!({
                    "session": id,
                    "fps": self.talker.footage.fps,
                    "loop": self.stage.len(),
                })))
            }
            (true, "/api/say") => {
                let body: SayBody = parse(&request.body)?;
                if body.text.chars().count() > MAX_TEXT {
                    return Err(bad(format!("the text is longer than {MAX_TEXT} characters")));
                }
                frame_clock("now", body.now)?;
                let client = self.client(&body.session)?;
                // From the request's arrival: time waiting for a worker counts too.
                let started = Instant::now();
                Ok(Answer::Later(Box::new(move || {
                    match self.say(&client, &body, started) {
                        Ok((reply, frames)) => {
                            tell(Event::Said(body.session.clone(), frames, started.elapsed().as_secs_f64()));
                            reply
                        }
                        Err((status, why)) => {
                            tell(Event::Refused("/api/say".into(), why.clone()));
                            Reply::error(status, why)
                        }
                    }
                })))
            }
            (true, "/api/listen") => {
                let body: ListenBody = parse(&request.body)?;
                let client = self.client(&body.session)?;
                ok(self.listen(&client, &body)?)
            }
            (true, "/api/call") => {
                let body: CallBody = parse(&request.body)?;
                let call = self.call.as_ref().ok_or((404, "no call here: start the server with --call VIDEO".to_string()))?;
                frame_clock("now", body.now)?;
                let client = self.client(&body.session)?;
                let fps = self.talker.footage.fps;
                let at = (body.now + CALL_LEAD.as_secs_f64() * fps).ceil() as usize;
                lock(&client).call = Some((at, Instant::now(), 0));
                let q = &call.quantisation;
                ok(Reply::json(json!({
                    "at": at,
                    "frames": call.frames,
                    "dims": call.dims,
                    "min": q.min,
                    "max": q.max,
                    "sound": call.audio.is_some(),
                    "sound_bytes": call.audio.as_ref().map_or(0, |a| a.len()),
                })))
            }
            (true, "/api/call/frames") => {
                let body: SessionBody = parse(&request.body)?;
                let call = self.call.as_ref().ok_or((404, "no call here".to_string()))?;
                let client = self.client(&body.session)?;
                let mut c = lock(&client);
                let (at, started, sent) = c.call.ok_or((409, "no call in progress: POST /api/call first".to_string()))?;
                // Released as a camera delivers them: frame k once the recording's time k/fps has passed.
                let due = ((started.elapsed().as_secs_f64() * self.talker.footage.fps).floor() as usize + 1).min(call.frames);
                c.call = (due < call.frames).then_some((at, started, due));
                let (from, to) = (sent.min(due), due);
                ok(Reply::ok(
                    quantised_packet(at + from, to - from, call.dims, &call.codes[from * call.dims..to * call.dims]),
                    "application/octet-stream",
                ))
            }
            (true, "/api/clear") => {
                let body: SessionBody = parse(&request.body)?;
                let client = self.client(&body.session)?;
                let mut c = lock(&client);
                c.typed.clear();
                if let Some(h) = &mut c.heard {
                    h.clear();
                }
                ok(Reply::json(json!({"next": c.typed.next_frame()})))
            }
            (true, _) => Err((404, "not found".into())),
        }
    }

    /// A new session `id`, dropping the one used longest ago when full.
    fn open(&self, id: &str) {
        let mut clients = lock(&self.clients);
        if clients.len() >= MAX_SESSIONS {
            let oldest = clients
                .iter()
                .min_by_key(|(_, c)| lock(c).used)
                .map(|(k, _)| k.clone());
            if let Some(k) = oldest {
                clients.remove(&k);
            }
        }
        clients.insert(
            id.into(),
            Arc::new(Mutex::new(Client {
                typed: Session::with_given_phones(self.talker),
                heard: None,
                call: None,
                used: Instant::now(),
            })),
        );
    }

    fn client(&self, id: &str) -> Result<Arc<Mutex<Client<'t>>>, Refusal> {
        let client = lock(&self.clients)
            .get(id)
            .cloned()
            .ok_or((404, format!("no session {id:?} (it ended, or the server restarted): reload the page")))?;
        lock(&client).used = Instant::now();
        Ok(client)
    }

    /// A typed sentence: spoken, aligned, and its frames from the first frame the page can
    /// still start it at.
    fn say(
        &self,
        client: &Mutex<Client<'t>>,
        body: &SayBody,
        started: Instant,
    ) -> Result<(Reply, usize), Refusal> {
        // The speech lives in memory only: a server killed mid-sentence leaves neither the
        // words nor their sound on disk (issue 69, R5-9).
        let (phones, wav) = self.talker.speak_in_memory(&body.text).map_err(|e| {
            // The server's own failures (memory, the aligner) are 500; the text's, 422.
            let status = match e {
                TalkerError::Io { .. } | TalkerError::Align { .. } => 500,
                _ => 422,
            };
            (status, e.to_string())
        })?;
        let sound = crate::audio::read(wav.path(), crate::align::frontend::SAMPLE_RATE, crate::align::MAX_SECONDS)
            .map_err(|e| (500, e.to_string()))?;
        let bytes = std::fs::read(wav.path()).map_err(|e| (500, e.to_string()))?;
        let fps = self.talker.footage.fps;
        let lead = (started.elapsed() + SAY_LEAD).as_secs_f64();
        let mut c = lock(client);
        let at = ((body.now + lead * fps).ceil() as usize).max(c.typed.next_frame());
        let t0 = at as f64 / fps;
        c.typed.skip_to(t0);
        let shifted: Vec<Segment> = phones
            .iter()
            .map(|p| Segment {
                start: p.start + t0,
                end: p.end + t0,
                ..*p
            })
            .collect();
        let live = |e: LiveError| (422, e.to_string());
        c.typed.push_phones(&shifted).map_err(live)?;
        c.typed.push_audio(&sound.samples, sound.rate).map_err(live)?;
        let mut frames = c.typed.pull().map_err(live)?;
        frames.extend(c.typed.finish().map_err(live)?);
        drop(c);
        self.stage.place(&mut frames).map_err(live)?;
        let n = frames.len();
        Ok((Reply::ok(packet(&frames, Some((at, &bytes))), "application/octet-stream"), n))
    }

    /// A chunk of the microphone: its frames settled so far.
    fn listen(&self, client: &Mutex<Client<'t>>, body: &ListenBody) -> Result<Reply, Refusal> {
        if !crate::live::RATES.contains(&body.rate) {
            return Err(bad(LiveError::SampleRate(body.rate).to_string()));
        }
        if body.pcm.len() as f64 > MAX_CHUNK_SECONDS * f64::from(body.rate) {
            return Err(bad(format!("more than {MAX_CHUNK_SECONDS} s of sound in one chunk")));
        }
        if let Some(at) = body.at {
            frame_clock("at", at)?;
        }
        let samples: Vec<f32> = body.pcm.iter().map(|&s| f32::from(s) / 32768.0).collect();
        let fps = self.talker.footage.fps;
        let live = |e: LiveError| bad(e.to_string());
        let mut c = lock(client);
        let session = c.heard.get_or_insert_with(|| Session::new(self.talker));
        if let Some(at) = body.at {
            session.skip_to(at / fps);
        }
        session.push_audio(&samples, body.rate).map_err(live)?;
        let mut frames = session.pull().map_err(live)?;
        if body.end {
            frames.extend(session.finish().map_err(live)?);
        }
        drop(c);
        self.stage.place(&mut frames).map_err(live)?;
        Ok(Reply::ok(packet(&frames, None), "application/octet-stream"))
    }
}

/// Every footage frame as JPEG (quality 92), the clips decoded side by side.
fn footage_jpegs(footage: &crate::footage::Footage) -> Result<Vec<Vec<u8>>, ServeError> {
    use rayon::prelude::*;
    let clips: Vec<Vec<Vec<u8>>> = (0..footage.clips.len())
        .into_par_iter()
        .map(|c| {
            let path = footage.clip_path(c);
            let mut source = crate::video::Source::open(&path)?;
            let mut out = Vec::with_capacity(footage.clips[c].frames);
            while out.len() < footage.clips[c].frames {
                let frame = source
                    .next_frame()?
                    .ok_or_else(|| crate::video::VideoError::NoFrames(path.clone()))?;
                let mut jpeg = Vec::new();
                image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 92)
                    .encode_image(&frame)
                    .map_err(|e| ServeError::Prepare(e.to_string()))?;
                out.push(jpeg);
            }
            Ok(out)
        })
        .collect::<Result<_, ServeError>>()?;
    Ok(clips.concat())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SessionBody {
    session: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SayBody {
    session: String,
    text: String,
    /// The page's frame clock when it asked (frames since its session began).
    now: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CallBody {
    session: String,
    /// The page's frame clock when it asked.
    now: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ListenBody {
    session: String,
    /// Sample rate, Hz.
    rate: u32,
    /// Signed 16-bit samples.
    pcm: Vec<i16>,
    /// The frame clock at the first sample, when the microphone (re)starts.
    #[serde(default)]
    at: Option<f64>,
    /// The microphone stopped: give every frame.
    #[serde(default)]
    end: bool,
}

/// A page's frame clock (`now`, `at`): finite and ≥ 0.
/// The latest frame a page's clock may name: a week of frames at 60 fps (times stay exact to
/// well under a microsecond). `now` = 1e308 once left a session at a frame no phone could
/// reach, 0 frames an answer (issue 69, R5-15).
pub const MAX_FRAME_CLOCK: f64 = 7.0 * 86_400.0 * 60.0;

fn frame_clock(name: &str, value: f64) -> Result<(), Refusal> {
    if value.is_finite() && (0.0..=MAX_FRAME_CLOCK).contains(&value) {
        Ok(())
    } else {
        Err(bad(format!(
            "`{name}` must be the page's frame clock, from 0 to {MAX_FRAME_CLOCK}"
        )))
    }
}

fn parse<T: serde::de::DeserializeOwned>(body: &str) -> Result<T, Refusal> {
    serde_json::from_str(body).map_err(|e| bad(format!("the request: {e}")))
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Frames (and a sound starting at a frame) as the page takes them (module docs).
pub fn packet(frames: &[LiveFrame], sound: Option<(usize, &[u8])>) -> Vec<u8> {
    let dims = frames.first().map_or(0, |f| f.values.len());
    let first = frames.first().map_or(0, |f| f.index);
    let (at, audio) = sound.unwrap_or((0, &[]));
    let flags = frames.len().div_ceil(4) * 4;
    let mut out = Vec::with_capacity(24 + flags + frames.len() * dims * 4 + audio.len());
    for word in [MAGIC, first as u32, frames.len() as u32, dims as u32, at as u32, audio.len() as u32] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.extend(frames.iter().map(|f| u8::from(f.speaking)));
    out.resize(24 + flags, 0);
    for f in frames {
        for v in &f.values {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out.extend_from_slice(audio);
    out
}

/// 8-bit frames (a call's) as the page takes them: the frame packet's layout with `FSPQ`,
/// one byte per value, no sound.
fn quantised_packet(first: usize, count: usize, dims: usize, codes: &[u8]) -> Vec<u8> {
    let flags = count.div_ceil(4) * 4;
    let mut out = Vec::with_capacity(24 + flags + codes.len());
    for word in [MAGIC_QUANTISED, first as u32, count as u32, dims as u32, 0, 0] {
        out.extend_from_slice(&word.to_le_bytes());
    }
    out.resize(24 + flags, 1);
    out.extend_from_slice(codes);
    out
}

/// The model and living frame as the page takes them.
fn model_json(talker: &Talker, stage: &Stage<'_>, call: Option<&Call>) -> serde_json::Value {
    let model = &talker.model;
    let frame = &model.frame;
    let plan = stage.plan();
    json!({
        "fps": talker.footage.fps,
        "size": [talker.footage.size.0, talker.footage.size.1],
        "name": talker.manifest.name,
        "layout": {"shape": model.layout().shape, "appearance": model.layout().appearance},
        "reference": {
            "width": frame.width,
            "height": frame.height,
            "landmarks": frame.landmarks.iter().flatten().collect::<Vec<_>>(),
        },
        "triangles": frame.triangles.iter().flatten().collect::<Vec<_>>(),
        "hull": frame.hull_edges.iter().flatten().collect::<Vec<_>>(),
        "shape": {"mean": model.shape.pca.mean, "components": model.shape.pca.components},
        "call": call.map(|c| json!({"frames": c.frames, "sound": c.audio.is_some()})),
        "plan": {
            "frames": plan.frames,
            "mix": plan.mix.iter().map(|m| m.map(|(g, w)| json!([g, w]))).collect::<Vec<_>>(),
        },
    })
}

/// The appearance basis in the reference frame, as the page uploads it: `n + 1` layers of
/// `height × width` RGBA `f32` (layer 0 the mean with the face's alpha over footage —
/// feathered and faded away from the lips and chin, as `say` draws — layer `k + 1` component
/// `k`, layer 1's alpha the whole face's feathered alpha, for a call drawn on its own),
/// each reference pixel holding its mask pixel or the padding's, zero elsewhere.
fn appearance_layers(talker: &Talker) -> Vec<u8> {
    let model = &talker.model;
    let frame = &model.frame;
    let pca = &model.appearance.pca;
    let (w, h, dim) = (frame.width, frame.height, pca.dim());
    let alpha = Edge::Articulators(DEFAULT_FEATHER)
        .alpha(model)
        .unwrap_or_else(|| vec![1.0; frame.n_pixels()]);
    let whole = Edge::Feathered(DEFAULT_FEATHER)
        .alpha(model)
        .unwrap_or_else(|| vec![1.0; frame.n_pixels()]);
    let mut source = vec![-1i64; w * h];
    for (i, p) in frame.pixels.iter().enumerate() {
        source[p.y as usize * w + p.x as usize] = i as i64;
    }
    for &(dst, src) in &frame.padding {
        source[dst as usize] = i64::from(src);
    }
    let layers = pca.n_components() + 1;
    let mut out = Vec::with_capacity(layers * w * h * 16);
    for layer in 0..layers {
        let values = if layer == 0 {
            &pca.mean[..]
        } else {
            &pca.components[(layer - 1) * dim..layer * dim]
        };
        for &s in &source {
            let px = if s >= 0 {
                let s = s as usize;
                let a = match layer {
                    0 => alpha[s],
                    1 => whole[s],
                    _ => 0.0,
                };
                [values[3 * s], values[3 * s + 1], values[3 * s + 2], a]
            } else {
                [0.0; 4]
            };
            for v in px {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    out
}
