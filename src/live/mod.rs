//! Live synthesis (issue 35): a session on a talker takes speech as it arrives — sound a chunk
//! at a time, and the phones with their times when a text-to-speech engine supplies them —
//! and gives out face-space frames at the video rate as soon as they are settled.
//!
//! The phones are recognised from the sound as it comes ([`crate::align::Recogniser`]) unless
//! they are given. A frame is settled once the phone after its own is known (the blend's
//! right context, C = 1, needs that phone — the recogniser's guess at the phone now sounding
//! stands in for it; wider contexts wait for more), or in a pause as far as the pause is heard
//! (as if the speech had ended there, so the face rests without waiting for the next word),
//! or at the latest [`LATEST`] after its sound (from the phone as far as it is heard),
//! and it is made by the
//! same synthesis as an offline utterance ([`crate::synth::synthesise`] with the talker's
//! settings) run over a window of the latest phones: the smoothing spline over the window is
//! the fixed-lag smoother, the frames near its end leave before later speech can pull them.
//! A batch's first frame takes half the difference between the last frame shown and the
//! batch's own at that frame, so that batches join without a jump.
//!
//! ```no_run
//! use facespace::live::Session;
//! use facespace::talker::Talker;
//!
//! let talker = Talker::load("models/grid".as_ref())?;
//! let mut session = Session::new(&talker);
//! # let microphone: Vec<Vec<f32>> = Vec::new();
//! for chunk in microphone {
//!     session.push_audio(&chunk, 48_000)?;
//!     for frame in session.pull()? {
//!         // frame.time (s), frame.values: pose ‖ shape ‖ appearance of the talker's model
//!     }
//! }
//! session.finish()?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use thiserror::Error;

use crate::align::{AlignError, Recogniser, TimedPhone};
use crate::audio::Resampler;
use crate::facespace::Frames;
use crate::phonemes::{Phone, Segment};
use crate::synth::{Request, SynthError, Synthesiser, Smoothing};
use crate::talker::Talker;

mod screen;
mod stage;

pub use screen::{Drawing, Picture, Screen};
pub use stage::{STAGE_SECONDS, Shown, Stage};

/// Seconds of sound under which an utterance the recogniser finds no path through is
/// silence rather than an error: a phone's three states need 30 ms, and a stretch this short
/// holds no mouth movement a frame would show.
const SHORTEST_UTTERANCE: f64 = 0.1;

/// Seconds of settled phones before the next frame that each synthesis window reaches back
/// over, so that the spline and the blend's left context see what came before.
pub const WINDOW_BEFORE: f64 = 1.0;

/// Seconds of known phones after the last frame wanted that a synthesis window reaches
/// forward over: phones given far ahead (a text-to-speech engine's whole sentence) would
/// otherwise make every window as long as the rest of the sentence.
pub const WINDOW_AFTER: f64 = 1.0;

/// Seconds of sound a frame from a recognised phone waits at most for that phone to end
/// (with the recogniser's lag): past it the frame is made from the phone as far as it is
/// heard, with no right context. Chosen on 30 of GRID s1's validation clips (BENCHMARKS
/// "Live"): 0.12 / 0.15 / 0.17 / no limit gave 95 % sound-to-frame waits of 162 / 179 /
/// 200 / 275 ms and mouth r_pca 0.450 / 0.463 / 0.465 / 0.474.
pub const LATEST: f64 = 0.15;

/// Sample rates a session takes, Hz (the sound is resampled to the recogniser's 16 kHz).
pub const RATES: [u32; 5] = [8_000, 16_000, 22_050, 24_000, 48_000];

/// What can go wrong in a live session.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum LiveError {
    /// A sample rate the session does not take.
    #[error("audio at {0} Hz: a live session takes 8 000, 16 000, 22 050, 24 000 or 48 000 Hz")]
    SampleRate(u32),
    /// More sound in one chunk than live audio comes in.
    #[error(
        "{seconds:.1} s of sound in one chunk: a live session takes at most {MAX_CHUNK_SECONDS} s at a time (push it in smaller chunks as it plays)"
    )]
    ChunkTooLong {
        /// The chunk's length, seconds.
        seconds: f64,
    },
    /// A chunk of sound could not be used (NaN samples, say).
    #[error(transparent)]
    Speech(#[from] AlignError),
    /// Given phones that overlap or go back in time.
    #[error("phone {index} ({phone}) starts at {start:.3} s, before the {previous:.3} s where the last one ended")]
    PhonesOutOfOrder {
        /// Its place among the phones given in that call.
        index: usize,
        /// The phone.
        phone: Phone,
        /// Its start, session seconds.
        start: f64,
        /// Where the session's phones had reached.
        previous: f64,
    },
    /// Words given to a session that was not made for them.
    #[error("words given to a session that takes sound or phones (make it with_given_words)")]
    NotReading,
    /// Given words that go back in time.
    #[error("word {index} ({word:?}) starts at {start:.3} s, before the {previous:.3} s of the last one")]
    WordsOutOfOrder {
        /// Its place among the words given in that call.
        index: usize,
        /// The word.
        word: String,
        /// Its start, session seconds.
        start: f64,
        /// Where the session's words had reached.
        previous: f64,
    },
    /// The synthesis failed.
    #[error(transparent)]
    Synth(#[from] SynthError),
    /// Values that do not fit the talker's layout.
    #[error(transparent)]
    Layout(#[from] crate::facespace::FacespaceError),
    /// A frame could not be placed on the talker's face.
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    /// A frame could not be drawn.
    #[error(transparent)]
    Render(#[from] crate::render::RenderError),
    /// The talker's footage could not be read.
    #[error("the talker's footage: {0}")]
    Footage(#[from] crate::video::VideoError),
    /// A part of the talker (its recorded mouths, its sound-to-face map) could not be read.
    #[error(transparent)]
    Talker(#[from] Box<crate::talker::TalkerError>),
}

/// One frame of a live session: face-space values in the talker model's layout
/// (pose ‖ shape ‖ appearance, the pose the codebook's median) and when it is shown.
#[derive(Clone, Debug, PartialEq)]
pub struct LiveFrame {
    /// Frame number since the session began; shown at `index / fps` seconds of its sound.
    pub index: usize,
    /// Its presentation time, seconds of the session's sound.
    pub time: f64,
    /// The face-space point.
    pub values: Vec<f32>,
    /// Whether a phone (not silence) is spoken at it.
    pub speaking: bool,
}

/// Where a session's phones come from.
enum Phones<'t> {
    /// Recognised from the sound; the recogniser starts at `offset` session seconds;
    /// `sounding` is its guess at the phone after the ones it gave out (session seconds).
    Heard {
        recogniser: Option<Box<Recogniser<'t>>>,
        offset: f64,
        sounding: Option<Segment>,
    },
    /// Given with their times (a text-to-speech engine's).
    Given,
    /// Words given with their start times (a text-to-speech engine's word timestamps), each
    /// aligned to its stretch of the sound ([`Session::push_words`]).
    Read(Box<Reading>),
}

/// A session's given words and the sound they are aligned to.
#[derive(Default)]
struct Reading {
    /// Words given and not yet aligned: (word, start in session seconds, the first phone of
    /// its dictionary pronunciation — the right context of the word before it).
    waiting: std::collections::VecDeque<(String, f64, Option<Phone>)>,
    /// The last words aligned, the left context of the next alignment.
    aligned: std::collections::VecDeque<(String, f64)>,
    /// The sound at 16 kHz from `sound_start` session seconds.
    sound: Vec<f32>,
    sound_start: f64,
}

impl Reading {
    /// The sample of `sound` at `t` session seconds (clamped to it).
    fn at(&self, t: f64) -> usize {
        let rate = f64::from(crate::align::frontend::SAMPLE_RATE);
        (((t - self.sound_start) * rate).round().max(0.0) as usize).min(self.sound.len())
    }

    /// Drops the sound before `t` session seconds.
    fn drop_before(&mut self, t: f64) {
        let cut = self.at(t);
        self.sound.drain(..cut);
        self.sound_start += cut as f64 / f64::from(crate::align::frontend::SAMPLE_RATE);
    }
}

/// A gap shorter than this between a word's phones and the next word's start is the
/// timestamps' rounding, not a pause (seconds).
const SLIVER: f64 = 0.05;

/// The most sound one [`Session::push_audio`] takes, seconds: live sound arrives in chunks
/// of milliseconds, a TTS's sentence in seconds; one hour in one call cost 1.5 GB and 34 s
/// (issue 69, R5-11), a minute costs a few seconds of work.
pub const MAX_CHUNK_SECONDS: f64 = 60.0;

/// Seconds of sound a session of given words keeps while no word comes for it.
pub const MAX_UNREAD: f64 = 30.0;

/// Seconds of sound, at least, that a given word is aligned within (the words before it
/// give the rest): the front end's mean normalisation needs more than one short word.
pub const WORD_WINDOW: f64 = 1.0;

/// A live session on a talker (module docs).
pub struct Session<'t> {
    talker: &'t Talker,
    synthesiser: Box<dyn Synthesiser>,
    fps: f64,
    source: Phones<'t>,
    /// The sound's rate and its resampler to 16 kHz.
    resampler: Option<(u32, Resampler)>,
    /// Seconds of sound taken.
    heard: f64,
    /// The phones so far since `origin`, session seconds, contiguous.
    phones: Vec<Segment>,
    /// Where the phones begin: the session's start or its last [`Session::clear`] (on the
    /// frame grid; no synthesis window reaches before it).
    origin: f64,
    /// Frames given out.
    given: usize,
    /// The last frame given out, while speech goes on (what the next batch continues from).
    shown: Option<Vec<f32>>,
    /// What the talker's sound-to-face map hears of the sound recognised, when the talker
    /// has one.
    hearing: Option<Hearing>,
}

/// The evidence of the sound heard so far for a live sound-to-face map.
struct Hearing {
    /// Session seconds at which the current recogniser's stream (its evidence frame 0) starts.
    start: f64,
    /// Evidence frames dropped from the front (no window reaches them any more).
    dropped: usize,
    /// The evidence rows since then ([`crate::sound_to_face::evidence_rows`]).
    rows: Vec<Vec<f32>>,
    /// The codebook's mean shape ‖ appearance, about which the map's motion is scaled.
    mean: Vec<f32>,
}

impl<'t> Session<'t> {
    /// A session whose phones are recognised from its sound.
    pub fn new(talker: &'t Talker) -> Self {
        Self::with_source(
            talker,
            Phones::Heard {
                recogniser: None,
                offset: 0.0,
                sounding: None,
            },
        )
    }

    /// A session whose phones are given ([`Session::push_phones`]); its sound only keeps time.
    pub fn with_given_phones(talker: &'t Talker) -> Self {
        Self::with_source(talker, Phones::Given)
    }

    /// A session whose words are given with their start times ([`Session::push_words`]), as
    /// text-to-speech engines with word timestamps give them: each word's phones are aligned
    /// to its stretch of the sound as soon as the sound reaches the next word, so the lips
    /// close where the sound's /p b m/ are, not where a recogniser guesses them. Sound that
    /// no word covers has its phones recognised at [`Session::finish`].
    pub fn with_given_words(talker: &'t Talker) -> Self {
        Self::with_source(talker, Phones::Read(Box::default()))
    }

    fn with_source(talker: &'t Talker, source: Phones<'t>) -> Self {
        Session {
            talker,
            synthesiser: talker.manifest.settings.synthesiser(),
            fps: talker.footage.fps,
            source,
            resampler: None,
            heard: 0.0,
            phones: Vec::new(),
            origin: 0.0,
            given: 0,
            shown: None,
            hearing: None,
        }
    }

    /// The session's hearing for the talker's sound-to-face map (`None` without one), begun
    /// anew when a fresh recogniser starts at `start` session seconds.
    fn hearing<'h>(
        talker: &Talker,
        hearing: &'h mut Option<Hearing>,
        fresh: bool,
        start: f64,
    ) -> Result<Option<&'h mut Hearing>, LiveError> {
        if talker.sound_to_face().map_err(Box::new)?.is_none() {
            return Ok(None);
        }
        if fresh || hearing.is_none() {
            let mean = match hearing.take() {
                Some(h) => h.mean,
                None => {
                    let params = talker.codebook.layout.params_range();
                    talker.codebook.mean()[params].iter().map(|&v| v as f32).collect()
                }
            };
            *hearing = Some(Hearing {
                start,
                dropped: 0,
                rows: Vec::new(),
                mean,
            });
        }
        Ok(hearing.as_mut())
    }

    /// Frames per second of the session's video.
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// Seconds of sound taken.
    pub fn seconds(&self) -> f64 {
        self.heard
    }

    /// Takes the next chunk of sound (mono, −1…1, at `rate` — the same rate every call).
    pub fn push_audio(&mut self, samples: &[f32], rate: u32) -> Result<(), LiveError> {
        if !RATES.contains(&rate) || self.resampler.as_ref().is_some_and(|(r, _)| *r != rate) {
            return Err(LiveError::SampleRate(rate));
        }
        let seconds = samples.len() as f64 / f64::from(rate);
        if seconds > MAX_CHUNK_SECONDS {
            return Err(LiveError::ChunkTooLong { seconds });
        }
        if let Some(index) = samples.iter().position(|x| !x.is_finite()) {
            return Err(AlignError::NotFinite { index }.into());
        }
        let (_, resampler) = self
            .resampler
            .get_or_insert_with(|| (rate, Resampler::new(rate, crate::align::frontend::SAMPLE_RATE)));
        let speech = resampler.push(samples);
        self.heard += samples.len() as f64 / f64::from(rate);
        match &mut self.source {
            Phones::Heard {
                recogniser,
                offset,
                sounding,
            } => {
                let fresh = recogniser.is_none();
                let recogniser = match recogniser {
                    Some(r) => r,
                    None => recogniser.insert(Box::new(self.talker.live_recogniser()?)),
                };
                let heard = recogniser.push(&speech)?;
                if let Some(hearing) = Self::hearing(self.talker, &mut self.hearing, fresh, *offset)? {
                    let feats = recogniser.take_features();
                    let evidence = self.talker.default_aligner()?.evidence_of(&feats);
                    hearing.rows.extend(crate::sound_to_face::evidence_rows(&evidence));
                }
                let offset = *offset;
                *sounding = recogniser
                    .sounding()
                    .and_then(|p| shifted(std::slice::from_ref(p), offset).pop());
                self.extend(&heard, offset);
            }
            Phones::Read(reading) => {
                reading.sound.extend_from_slice(&speech);
                // Sound no word comes for is kept for a while, then dropped (it stays silent).
                reading.drop_before(self.heard - MAX_UNREAD);
                self.read(false)?;
            }
            // Sound beyond the given phones is silence: the face rests while it plays.
            Phones::Given => {
                let end = self.phones.last().map_or(self.origin, |p| p.end);
                if end < self.heard {
                    self.append(Segment {
                        start: end,
                        end: self.heard,
                        phone: Phone::SIL,
                    });
                }
            }
        }
        Ok(())
    }

    /// Takes phones with their times (session seconds), in order from where the last ended;
    /// they must come before their sound (sound beyond the phones is taken as silence).
    pub fn push_phones(&mut self, phones: &[Segment]) -> Result<(), LiveError> {
        let mut end = self.phones.last().map_or(self.origin, |p| p.end);
        for (index, p) in phones.iter().enumerate() {
            if !(p.start.is_finite() && p.end.is_finite()) || p.start < end - 1e-6 || p.end < p.start {
                return Err(LiveError::PhonesOutOfOrder {
                    index,
                    phone: p.phone,
                    start: p.start,
                    previous: end,
                });
            }
            end = p.end;
        }
        for p in phones {
            self.append(*p);
        }
        Ok(())
    }

    /// Takes words with their start times (session seconds), in order, after the words
    /// already given (a session made by [`Session::with_given_words`]). A word's stretch of
    /// sound runs to the next word's start (the last: to [`Session::finish`]).
    pub fn push_words(&mut self, words: &[(String, f64)]) -> Result<(), LiveError> {
        let Phones::Read(reading) = &mut self.source else {
            return Err(LiveError::NotReading);
        };
        let mut previous = reading
            .waiting
            .back()
            .map(|w| w.1)
            .or(reading.aligned.back().map(|w| w.1))
            .unwrap_or(self.origin)
            .max(self.phones.last().map_or(self.origin, |p| p.end));
        for (index, (word, start)) in words.iter().enumerate() {
            if !start.is_finite() || *start < previous - 1e-6 {
                return Err(LiveError::WordsOutOfOrder {
                    index,
                    word: word.clone(),
                    start: *start,
                    previous,
                });
            }
            previous = *start;
        }
        let aligner = self.talker.default_aligner()?;
        for (word, start) in words {
            // Punctuation alone is no word; what a word carries around it is dropped.
            let spoken = crate::align::dict::words(word);
            if let Some(first) = spoken.first() {
                let phone = first_phone(aligner, first);
                reading.waiting.push_back((spoken.join(" "), *start, phone));
            }
        }
        self.read(false)
    }

    /// Aligns every waiting word whose stretch of sound is heard (`to_end`: all of them, the
    /// last to the end of the sound), and adds its phones.
    fn read(&mut self, to_end: bool) -> Result<(), LiveError> {
        let Phones::Read(reading) = &mut self.source else {
            return Ok(());
        };
        let aligner = self.talker.default_aligner()?;
        let mut phones = Vec::new();
        while let Some((word, start, _)) = reading.waiting.front().cloned() {
            let end = match reading.waiting.get(1) {
                Some(next) if next.1 <= self.heard => next.1,
                _ if to_end => self.heard,
                _ => break,
            };
            reading.waiting.pop_front();
            // The window: this word and the ones before it within WORD_WINDOW.
            let context: Vec<&(String, f64)> = reading
                .aligned
                .iter()
                .filter(|w| w.1 >= end - WORD_WINDOW)
                .collect();
            // The session's first word (or the first after a clear) takes the silence before it.
            let lead = if reading.aligned.is_empty() { start - WORD_WINDOW } else { start };
            let from = context.first().map_or(lead, |w| w.1).max(reading.sound_start);
            let samples = &reading.sound[reading.at(from)..reading.at(end)];
            let text: Vec<&str> = context.iter().map(|w| w.0.as_str()).chain([word.as_str()]).collect();
            let ours = context.len();
            let aligned = aligner
                .align(samples, crate::align::frontend::SAMPLE_RATE, &text.join(" "))
                .ok()
                .and_then(|alignment| {
                    // This word's phones and the silence after it.
                    let first = alignment.phones.iter().position(|p| p.word.is_some_and(|w| w >= ours))?;
                    Some(shifted(&alignment.phones[first..], from))
                });
            // A word the dictionary lacks, or a stretch too short for it: its phones heard.
            let found = aligned.unwrap_or_else(|| recognised(aligner, &reading.sound[reading.at(start)..reading.at(end)], start));
            phones.extend(found.into_iter().filter(|p| p.end > start));
            // The stretch ends at the next word: a sliver left by the timestamps' rounding
            // goes to the last phone, a real gap becomes silence.
            match phones.last_mut() {
                Some(last) if last.end < end && end - last.end < SLIVER => last.end = end,
                _ => phones.push(Segment {
                    start: end,
                    end,
                    phone: Phone::SIL,
                }),
            }
            reading.aligned.push_back((word, start));
            while reading.aligned.len() > 8 {
                reading.aligned.pop_front();
            }
            // Sound no later window reaches is dropped.
            reading.drop_before(end - WORD_WINDOW);
        }
        if to_end && reading.waiting.is_empty() {
            // Sound after the last word's stretch (or with no words at all): its phones heard.
            let end = phones.last().map_or(self.phones.last().map_or(self.origin, |p| p.end), |p| p.end);
            if self.heard > end + 0.1 {
                let samples = &reading.sound[reading.at(end)..];
                phones.extend(recognised(aligner, samples, end));
            }
            // Silence to the end of the sound where nothing more is heard.
            phones.push(Segment {
                start: self.heard,
                end: self.heard,
                phone: Phone::SIL,
            });
        }
        for p in phones {
            self.append(p);
        }
        Ok(())
    }

    /// For given words: the first phone of the first word waiting, as a segment after the
    /// phones (a guess at its length), when the dictionary knows the word.
    fn next_word_phone(&self) -> Option<Segment> {
        let Phones::Read(reading) = &self.source else {
            return None;
        };
        let (_, start, phone) = reading.waiting.front()?;
        let last = self.phones.last()?;
        if (last.end - start).abs() > SLIVER {
            return None;
        }
        Some(Segment {
            start: last.end,
            end: last.end + 0.08,
            phone: (*phone)?,
        })
    }

    /// The recognised phones `heard` (recogniser seconds, from `offset`) added to the phones.
    fn extend(&mut self, heard: &[TimedPhone], offset: f64) {
        for p in shifted(heard, offset) {
            self.append(p);
        }
    }

    /// Adds a phone, joining it to the last when it continues it; a gap becomes silence.
    fn append(&mut self, p: Segment) {
        let end = self.phones.last().map_or(self.origin, |l| l.end);
        if p.start > end + 1e-6 {
            self.append(Segment {
                start: end,
                end: p.start,
                phone: Phone::SIL,
            });
        }
        let p = Segment {
            start: p.start.max(end),
            ..p
        };
        match self.phones.last_mut() {
            Some(last) if last.phone == p.phone => last.end = last.end.max(p.end),
            _ if p.end > p.start => self.phones.push(p),
            _ => {}
        }
    }

    /// The frames settled since the last call, in order.
    pub fn pull(&mut self) -> Result<Vec<LiveFrame>, LiveError> {
        let context = self.talker.manifest.settings.context.max(1);
        // The recogniser's guess at the next phone is the last one's right context when it is
        // another phone (the last has ended); a guess that continues the last leaves it open.
        let next = match &self.source {
            Phones::Heard {
                sounding: Some(s), ..
            } if self.phones.last().is_some_and(|l| l.phone != s.phone && (l.end - s.start).abs() < 1e-6) => {
                Some(*s)
            }
            _ => None,
        };
        // Given words: the first phone of the next word (its dictionary's first pronunciation)
        // is the right context of the last word aligned, so that word's frames need not wait
        // for the next word's own alignment.
        let next = next.or_else(|| self.next_word_phone());
        let known = self.phones.len() + usize::from(next.is_some());
        // A pause still going on is given out as far as it is heard, as if speech ended there
        // (its right context silence): the face rests during it instead of waiting for its end.
        let pausing = next.is_none()
            && matches!(self.source, Phones::Heard { .. })
            && self.phones.last().is_some_and(|l| l.phone == Phone::SIL);
        let settled = match known.checked_sub(1 + context) {
            _ if pausing => self.phones[self.phones.len() - 1].end,
            Some(k) => self.phones[k].end,
            None => self.origin,
        };
        // Never ahead of the sound: an interruption takes back nothing already shown.
        let mut frames = self.frames_until(settled.min(self.heard), next, None)?;
        // A frame waits at most LATEST for its phone's end: past it, the phone still sounding
        // is taken to last as far as it is heard, with nothing after it.
        // (Before any phone is settled, the one sounding is all there is.)
        let deadline = self.heard - LATEST;
        if let Phones::Heard { sounding, .. } = self.source
            && deadline > settled
        {
            let open = if self.phones.is_empty() { sounding } else { next };
            frames.extend(self.frames_until(deadline, open, Some(self.heard))?);
        }
        Ok(frames)
    }

    /// Ends the speech: every frame up to the end of the phones (with no right context
    /// beyond them), and the recogniser's last phones.
    pub fn finish(&mut self) -> Result<Vec<LiveFrame>, LiveError> {
        if let Phones::Heard {
            recogniser,
            offset,
            sounding,
        } = &mut self.source
        {
            let start = *offset;
            let tail = self.resampler.take().map(|(_, mut r)| r.finish()).unwrap_or_default();
            // Sound after this is another utterance: its recogniser starts where this ends.
            *offset = self.heard;
            *sounding = None;
            if let Some(mut r) = recogniser.take() {
                let mut heard = r.push(&tail)?;
                let short = r.seconds() < SHORTEST_UTTERANCE;
                match r.finish() {
                    Ok(rest) => heard.extend(rest),
                    // Too short for any phone's states (a speech engine's last few ms):
                    // silence, not a lost path.
                    Err(AlignError::NoPath | AlignError::EmptyAudio { .. }) if short => {}
                    Err(e) => return Err(e.into()),
                }
                self.extend(&heard, start);
            }
        }
        self.read(true)?;
        let end = self.phones.last().map_or(self.origin, |p| p.end);
        self.frames_until(end, None, None)
    }

    /// Drops what is being said (an interruption): the next frame is the idle face, and the
    /// phones start again from it.
    pub fn clear(&mut self) {
        self.origin = self.given as f64 / self.fps;
        self.phones.clear();
        self.shown = None;
        // The sound said before the interruption draws no more lips.
        self.hearing = None;
        if let Phones::Heard {
            recogniser,
            offset,
            sounding,
        } = &mut self.source
        {
            *recogniser = None;
            *sounding = None;
            *offset = self.heard;
            self.resampler = None;
        }
        if let Phones::Read(reading) = &mut self.source {
            **reading = Reading {
                sound_start: self.heard,
                ..Reading::default()
            };
            self.resampler = None;
        }
        if self.origin < self.heard {
            // Until new speech arrives, silence from the interruption.
            self.phones.push(Segment {
                start: self.origin,
                end: self.heard,
                phone: Phone::SIL,
            });
        }
    }

    /// Moves the session on to `time` (session seconds, rounded up to the frame grid) with
    /// nothing said: dropped as by [`Session::clear`], and no frames made for the stretch
    /// skipped — a listener's silence or the wait for a text-to-speech engine's next turn
    /// costs nothing however long. A time already passed changes nothing but the clear.
    pub fn skip_to(&mut self, time: f64) {
        let frame = (time * self.fps - 1e-6).ceil().max(0.0) as usize;
        if frame > self.given {
            self.given = frame;
            self.heard = self.heard.max(frame as f64 / self.fps);
        }
        self.clear();
    }

    /// Whether nothing is being said: every phone known has been given out as frames and no
    /// sound waits in a recogniser (after [`Session::finish`], [`Session::clear`], or before
    /// any speech).
    pub fn is_quiet(&self) -> bool {
        let end = self.phones.last().map_or(self.origin, |p| p.end);
        let waiting = match &self.source {
            Phones::Heard { recogniser, .. } => recogniser.is_some(),
            Phones::Read(reading) => !reading.waiting.is_empty() || self.heard > end + 1e-6,
            Phones::Given => false,
        };
        !waiting && end * self.fps <= self.given as f64 + 1e-6
    }

    /// The phones known so far since the session's start or its last clear, session seconds.
    pub fn phones(&self) -> &[Segment] {
        &self.phones
    }

    /// The next frame this session gives out.
    pub fn next_frame(&self) -> usize {
        self.given
    }

    /// The frames from the next one up to (not including) time `until`, synthesised over a
    /// window of the phones (and the `next` one guessed after them) that reaches
    /// [`WINDOW_BEFORE`] before the first of them and [`WINDOW_AFTER`] beyond the last; the
    /// window's last phone lasts at least to `stretch` (a phone still sounding).
    fn frames_until(
        &mut self,
        until: f64,
        next: Option<Segment>,
        stretch: Option<f64>,
    ) -> Result<Vec<LiveFrame>, LiveError> {
        let first_time = self.given as f64 / self.fps;
        let last = ((until * self.fps) - 1e-6).ceil() as usize;
        if last <= self.given {
            return Ok(Vec::new());
        }
        let reach = (first_time - WINDOW_BEFORE).max(self.origin);
        let w0 = self.phones.iter().rposition(|p| p.start <= reach).unwrap_or(0);
        let w1 = self
            .phones
            .iter()
            .position(|p| p.start >= until + WINDOW_AFTER)
            .unwrap_or(self.phones.len())
            .max((w0 + 1).min(self.phones.len()));
        let next = next.filter(|_| w1 == self.phones.len());
        let Some(first) = self.phones.get(w0).or(next.as_ref()) else {
            return Ok(Vec::new());
        };
        // The window starts on the frame grid, at or before its first phone.
        let start = ((first.start * self.fps) + 1e-6).floor() / self.fps;
        let mut target: Vec<Segment> = self.phones[w0..w1]
            .iter()
            .chain(&next)
            .map(|p| Segment {
                start: p.start - start,
                end: p.end - start,
                phone: p.phone,
            })
            .collect();
        target[0].start = 0.0;
        if let (Some(end), Some(open)) = (stretch, target.last_mut()) {
            open.end = open.end.max(end - start);
        }
        let smoothing = Smoothing::On(self.talker.manifest.settings.smoothing);
        let utterance = crate::synth::synthesise(
            self.synthesiser.as_ref(),
            &self.talker.codebook,
            // The codebook's median pose, which the talker keeps (found anew, it would read
            // every frame of the codebook for every batch).
            Request {
                pose: crate::synth::Pose::Hold(self.talker.median_pose()),
                ..Request::new(target.clone(), self.fps, smoothing)
            },
        )?;
        // The variant shown (the smoothed one), taken out of the utterance, not copied.
        let mut frames: Frames = utterance.smoothed.unwrap_or(utterance.synthesis.frames);
        let offset = (start * self.fps).round() as usize;
        // Phones heard and a map: the lips of the frames given out (and of the one before
        // them, which a batch joins from) from the sound itself.
        // (Only a session hearing phones has a hearing, made once the map loaded.)
        if let Some(hearing) = &mut self.hearing
            && let Some(map) = self.talker.sound_to_face().map_err(Box::new)?
        {
            let from = self.given.saturating_sub(1).max(offset);
            let wanted: Vec<usize> = (from..last)
                .filter(|&index| index - offset < frames.len() && index as f64 / self.fps >= hearing.start)
                .collect();
            let centres: Vec<i64> = wanted
                .iter()
                .map(|&index| {
                    ((index as f64 / self.fps - hearing.start) * 100.0).round() as i64 - hearing.dropped as i64
                })
                .collect();
            let faces = map.predict_centred(&hearing.rows, &centres, &hearing.mean);
            let params = frames.layout().params_range();
            let mut values = frames.values_mut();
            for (&index, face) in wanted.iter().zip(&faces) {
                let keep = crate::sound_to_face::closure_weight(&target, index as f64 / self.fps - start, self.fps);
                for (j, p) in params.clone().enumerate() {
                    let own = values[(index - offset, p)];
                    values[(index - offset, p)] = keep * own + (1.0 - keep) * face[j];
                }
            }
            // No later window reaches back past the last frame given out's.
            let keep_from = centres.last().map_or(0, |&c| (c - 2 * crate::sound_to_face::HALF_WINDOW).max(0) as usize);
            let drop = keep_from.min(hearing.rows.len());
            hearing.rows.drain(..drop);
            hearing.dropped += drop;
        }
        let frames = &frames;
        let mut out = Vec::with_capacity(last - self.given);
        for index in self.given..last {
            let Some(i) = index.checked_sub(offset).filter(|&i| i < frames.len()) else {
                break;
            };
            let time = index as f64 / self.fps;
            let speaking = target
                .iter()
                .find(|p| time - start < p.end)
                .is_some_and(|p| p.phone != Phone::SIL);
            let mut values = frames.row(i).to_vec();
            // The batch's first frame takes half the difference between the last frame shown
            // and this batch's own at that frame, so that a batch that disagrees with the last
            // (a phone recognised anew, a frame made before its phone ended) joins it without
            // a jump.
            if let (true, Some(shown), Some(before)) = (index == self.given, &self.shown, i.checked_sub(1)) {
                let own = frames.row(before);
                values.iter_mut().zip(shown.iter().zip(own)).for_each(|(v, (s, o))| *v += 0.5 * (s - o));
            }
            out.push(LiveFrame {
                index,
                time,
                values,
                speaking,
            });
        }
        self.given += out.len();
        if let Some(f) = out.last() {
            self.shown = Some(f.values.clone());
        }
        Ok(out)
    }
}

/// The first phone of `word`'s first pronunciation in `aligner`'s dictionary, if it has one.
fn first_phone(aligner: &crate::align::Aligner, word: &str) -> Option<Phone> {
    let prons = aligner.dict.pronunciations(&[word.to_string()], &aligner.model).ok()?;
    let ci = *prons.first()?.first()?.first()?;
    Phone::parse(aligner.model.ci_names.get(usize::from(ci))?)
}

/// The phones recognised in `samples` (16 kHz) that start at `start` session seconds; none
/// where nothing is heard (too little speech, too short).
fn recognised(aligner: &crate::align::Aligner, samples: &[f32], start: f64) -> Vec<Segment> {
    let lm = aligner.phone_loop(crate::align::PHONE_WEIGHT, crate::align::PHONE_PENALTY);
    aligner
        .recognise(samples, crate::align::frontend::SAMPLE_RATE, &lm)
        .map(|heard| shifted(&heard, start))
        .unwrap_or_default()
}

/// Recognised phones as segments in session seconds (the recogniser started at `offset`).
fn shifted(heard: &[TimedPhone], offset: f64) -> Vec<Segment> {
    crate::align::segments(heard)
        .into_iter()
        .map(|p| Segment {
            start: p.start + offset,
            end: p.end + offset,
            ..p
        })
        .collect()
}
