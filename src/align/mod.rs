//! Speech in: Viterbi forced alignment of a recording to its words, against the CMU Sphinx
//! en-us phonetically-tied-mixture acoustic model (DESIGN §6: phone timings).
//!
//! The recording goes through the Sphinx MFCC front end ([`frontend`]); the words become a
//! graph of triphone HMMs — every pronunciation the dictionary gives, cross-word contexts
//! exact, an optional silence before, between and after the words — and one Viterbi pass
//! finds the best path. Scores follow pocketsphinx: top-4 Gaussians per codebook and stream,
//! quantised mixture weights from `sendump`, the model's transition matrices, and a
//! silence insertion cost of `lw · (ln silprob + ln wip)` (6.5, 0.1, 0.65) against the
//! acoustic log-likelihood. Frame `t` starts at `t · 10 ms` (pocketsphinx's convention).

pub mod dict;
pub mod frontend;
pub mod model;
mod search;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use dict::Dictionary;
pub use model::AcousticModel;

use crate::phonemes::{Phone, Segment};

/// Feature frames per second: the one definition of the front end's 10 ms frame (times are
/// divided by it, so that times read back from files compare equal).
pub const FRAMES_PER_SECOND: f64 = 100.0;
/// Seconds per feature frame.
pub const FRAME_SECONDS: f64 = 1.0 / FRAMES_PER_SECOND;
/// The longest recording aligned in one piece: longer ones are refused before they are
/// decoded whole, so memory stays bounded.
pub const MAX_SECONDS: f64 = 600.0;

/// What can go wrong in alignment; every variant says what to do about it.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum AlignError {
    /// An acoustic-model file is missing or malformed.
    #[error("acoustic model {path}: {why}")]
    Model {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// A dictionary file is missing or malformed.
    #[error("dictionary {path}:{line}: {why}")]
    Dictionary {
        /// The file.
        path: PathBuf,
        /// The line (1-based; 0: the whole file).
        line: usize,
        /// What is wrong.
        why: String,
    },
    /// Words without a pronunciation.
    #[error("{}", out_of_dictionary(.0))]
    OutOfDictionary(Vec<String>),
    /// The transcript has no words.
    #[error("the transcript has no words")]
    NoWords,
    /// A sample is NaN or infinite.
    #[error("audio sample {index} is not finite")]
    NotFinite {
        /// The first such sample.
        index: usize,
    },
    /// The audio has no samples.
    #[error("the audio is empty ({samples} samples)")]
    EmptyAudio {
        /// Samples there are.
        samples: usize,
    },
    /// The audio is digital silence or nearly so.
    #[error("the audio is silent (peak {peak_dbfs:.0} dBFS): nothing to align")]
    Silent {
        /// The loudest sample, dB below full scale.
        peak_dbfs: f64,
    },
    /// Fewer frames than the words' phones need (three each).
    #[error(
        "the transcript is too long for the audio: its {phones} or more phones need at least {needed} frames ({:.2} s) but the audio has {frames} ({:.2} s)",
        *.needed as f64 * FRAME_SECONDS, *.frames as f64 * FRAME_SECONDS
    )]
    TranscriptTooLong {
        /// Phones of the shortest pronunciations.
        phones: usize,
        /// Frames they need.
        needed: usize,
        /// Frames the audio has.
        frames: usize,
    },
    /// The search found no path (the beam lost every hypothesis).
    #[error(
        "no alignment reaches the end of the words at the end of the audio: is this the right transcript?"
    )]
    NoPath,
    /// A transcript that does not fit its recording ([`WordFit::matches`]).
    #[error(
        "the words do not seem to be what is said, as {judge} hears them (fit {overall:+.2} nats/frame, least {least}; worst: {worst}) — fix the transcript, leave out the words to recognise the phones from the sound, or accept them anyway (--accept-mismatch)"
    )]
    WordsDoNotMatch {
        /// Which model judged: [`GENERAL_JUDGE`], or a talker's ear beside it.
        judge: &'static str,
        /// The whole recording's fit ([`WordFit::overall`], or a talker's ear's).
        overall: f64,
        /// The least a matching transcript has ([`LEAST_OVERALL_FIT`], or the ear's).
        least: f64,
        /// The worst-fitting words, worst first.
        worst: String,
    },
    /// The sound holds too little speech for lip sync: silence, noise, tones or music.
    #[error(
        "no speech found: speech sounds cover {:.0} % of the audio and noise or music {:.0} %; lip sync needs speech (is this the right file?)",
        100.0 * .speech, 100.0 * .noise
    )]
    NoSpeech {
        /// Fraction of the frames recognised as speech sounds.
        speech: f64,
        /// Fraction recognised as noise (the model's filler sounds).
        noise: f64,
    },
    /// Audio longer than [`MAX_SECONDS`].
    #[error(
        "the audio lasts {seconds:.0} s; at most {max:.0} s are aligned at once: split it at pauses"
    )]
    TooLong {
        /// Its duration (or as far as it was read), seconds.
        seconds: f64,
        /// The limit, seconds.
        max: f64,
    },
    /// The sound could not be read.
    #[error(transparent)]
    Audio(#[from] crate::audio::AudioError),
    /// The sample rate is not 16 kHz (resample first: [`crate::audio::resample`]).
    #[error("audio at {0} Hz: the acoustic model needs 16 000 Hz")]
    SampleRate(u32),
}

/// A word and its interval.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimedWord {
    /// The word (lower case).
    pub word: String,
    /// Which pronunciation (0 = the dictionary's first).
    pub pronunciation: usize,
    /// Start, seconds.
    pub start: f64,
    /// End, seconds.
    pub end: f64,
}

/// A phone (ARPAbet, `SIL` for silence) and its interval; `word` indexes [`Alignment::words`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimedPhone {
    /// ARPAbet, upper case; `SIL` for silence.
    pub phone: String,
    /// Start, seconds.
    pub start: f64,
    /// End, seconds.
    pub end: f64,
    /// The word it belongs to; `None` for silence.
    pub word: Option<usize>,
}

/// Words and phones with times, covering the whole recording.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Alignment {
    /// The words, in order.
    pub words: Vec<TimedWord>,
    /// The phones and silences, tiling the recording.
    pub phones: Vec<TimedPhone>,
    /// Feature frames (10 ms each).
    pub frames: usize,
    /// Log-likelihood of the best path, per frame.
    pub score_per_frame: f64,
}

impl Alignment {
    /// The phones as label segments (`SIL` → `sil`), for `.lab` and TextGrid files.
    pub fn segments(&self) -> Vec<Segment> {
        segments(&self.phones)
    }
}

/// The acoustic model and dictionary together: what [`align`] needs.
pub struct Aligner {
    /// The acoustic model.
    pub model: AcousticModel,
    /// Its pronouncing dictionary with the user's additions.
    pub dict: Dictionary,
    frontend: frontend::FrontEnd,
    /// The dictionary's phone bigram, `ln P(b | a)`, estimated when first needed
    /// ([`PhoneLoop::log_bigram`]): it depends on the dictionary alone, not on the weights.
    bigram: std::sync::OnceLock<Vec<Vec<f64>>>,
}

/// Environment variable naming the en-us model folder to use instead of the committed one:
/// a build that runs away from its source tree (a Python wheel) carries its own copy.
pub const MODEL_DIR_VAR: &str = "FACESPACE_ACOUSTIC_MODEL";

/// Who judges given words when no talker's ear may: the general acoustic model
/// ([`WordFit::matches`]).
pub const GENERAL_JUDGE: &str = "the general acoustic model";

/// A model folder's pronunciations that its (American) dictionary lacks, such as the letter Z
/// said "zed": read after the dictionary, as `--dict` files are.
pub const VARIANTS: &str = "variants.dict";

/// The en-us model folder: [`MODEL_DIR_VAR`]'s when set, else the committed one.
pub fn default_model_dir() -> PathBuf {
    match std::env::var_os(MODEL_DIR_VAR) {
        Some(dir) if !dir.is_empty() => PathBuf::from(dir),
        _ => Path::new(env!("CARGO_MANIFEST_DIR")).join("models/en-us"),
    }
}

/// [`AlignError::OutOfDictionary`]'s message: numbers need words, other words a `--dict`.
fn out_of_dictionary(missing: &[String]) -> String {
    let (numbers, words): (Vec<String>, Vec<String>) = missing
        .iter()
        .cloned()
        .partition(|w| w.chars().any(|c| c.is_ascii_digit()));
    let mut parts = Vec::new();
    if !words.is_empty() {
        parts.push(format!(
            "words not in the pronouncing dictionary: {}; add them with --dict FILE (lines like `WORD  W ER D`)",
            crate::options::clipped_list(&words)
        ));
    }
    if !numbers.is_empty() {
        parts.push(format!(
            "digits that are not a number, money, a percentage, an ordinal or a clock time: {}; write them in words (\"B2B\" as \"B to B\")",
            crate::options::clipped_list(&numbers)
        ));
    }
    parts.join("; ")
}

impl Aligner {
    /// Loads the model of `dir` and its dictionary (`cmudict-en-us.dict.gz` beside it, with
    /// the pronunciations of [`VARIANTS`] there when it exists), plus the pronunciations of
    /// `extra` dictionary files.
    pub fn load(dir: &Path, extra: &[PathBuf]) -> Result<Self, AlignError> {
        let model = AcousticModel::load(dir)?;
        let mut dict = Dictionary::load(&dir.join("cmudict-en-us.dict.gz"), &model)?;
        let variants = dir.join(VARIANTS);
        if variants.is_file() {
            dict.add_file(&variants, &model)?;
        }
        for path in extra {
            dict.add_file(path, &model)?;
        }
        Ok(Aligner {
            model,
            dict,
            frontend: frontend::FrontEnd::new(),
            bigram: std::sync::OnceLock::new(),
        })
    }

    /// The committed model with `extra` dictionaries.
    pub fn load_default(extra: &[PathBuf]) -> Result<Self, AlignError> {
        Self::load(&default_model_dir(), extra)
    }

    /// The phones `text` takes at the least (each word's shortest pronunciation), or why its
    /// words cannot be aligned (none, or some not in the dictionary): checked before a
    /// text-to-speech engine runs, so text that cannot be aligned never costs its speech.
    pub fn phone_count(&self, text: &str) -> Result<usize, AlignError> {
        Ok(self
            .pronunciations_of(text)?
            .iter()
            .map(|p| p.iter().map(Vec::len).min().unwrap_or(0))
            .sum())
    }

    /// Every pronunciation (CI phone ids) of each word of `text`, numbers written out.
    fn pronunciations_of(&self, text: &str) -> Result<Vec<Vec<Vec<u8>>>, AlignError> {
        let words = dict::words(&crate::phonemes::spoken::written_out(text));
        if words.is_empty() {
            return Err(AlignError::NoWords);
        }
        self.dict.pronunciations(&words, &self.model)
    }

    /// Whether `text`'s words could fit `seconds` of sound at all (every word at least one
    /// phone of three states, a frame each), counted without making them: a huge transcript
    /// is refused before anything is built from it (issue 69, R5-12).
    pub fn could_fit(text: &str, seconds: f64) -> bool {
        dict::word_count(text) * model::STATES <= (seconds * FRAMES_PER_SECOND).ceil() as usize
    }

    /// The phones of every pronunciation of `text`'s words (a word's variants all counted).
    pub fn phones_of(&self, text: &str) -> Result<Vec<crate::phonemes::Phone>, AlignError> {
        Ok(self
            .pronunciations_of(text)?
            .iter()
            .flatten()
            .flatten()
            .filter_map(|&ci| self.model.ci_names.get(usize::from(ci)))
            .filter_map(|name| crate::phonemes::Phone::parse(name))
            .collect())
    }

    /// Reads the sound of `path` (WAV, MP4/M4A, or through ffmpeg anything it reads) and
    /// aligns it to the words of `text`.
    pub fn align_file(&self, path: &Path, text: &str) -> Result<Alignment, AlignError> {
        let speech = crate::audio::read(path, frontend::SAMPLE_RATE, MAX_SECONDS)?;
        self.align(&speech.samples, speech.rate, text)
    }

    /// Aligns `samples` (mono, 16 kHz, −1…1) to the words of `text`.
    pub fn align(&self, samples: &[f32], rate: u32, text: &str) -> Result<Alignment, AlignError> {
        self.search_words(samples, rate, text).map(|w| w.alignment)
    }

    /// Aligns as [`Aligner::align`] and scores how well the words fit the sound
    /// ([`WordFit`]) against the free phone loop `lm` over the same features.
    pub fn align_checked(
        &self,
        samples: &[f32],
        rate: u32,
        text: &str,
        lm: &PhoneLoop,
    ) -> Result<(Alignment, WordFit), AlignError> {
        let words = self.search_words(samples, rate, text)?;
        let (_, free) = self.free_path(&words.feats, lm)?;
        let fit = word_fit(&words.alignment, &words.path, &free, words.feats.len());
        Ok((words.alignment, fit))
    }

    /// [`Self::align_checked`] with the fit scored by another ear as well: the words' graph
    /// and the free loop `ear_lm` are both searched over `ear`'s scores of each phone in each
    /// frame of the sound's [`Evidence`] (a talker's own classifier). Gives the ear's fit and
    /// the acoustic model's (against the free loop `lm`, as [`Self::align_checked`]); the
    /// alignment is the acoustic model's.
    pub fn align_checked_by(
        &self,
        samples: &[f32],
        rate: u32,
        text: &str,
        lm: &PhoneLoop,
        ear: impl FnOnce(&Evidence) -> Vec<Vec<f32>>,
        ear_lm: &PhoneLoop,
    ) -> Result<(Alignment, WordFit, WordFit), AlignError> {
        let words = self.search_words(samples, rate, text)?;
        let frames = words.feats.len();
        // One scoring of every phone's states serves the general loop and the ear's evidence.
        let states = search::ci_state_scores(&self.model, &words.feats);
        let (_, free) = self.loop_path(&states, lm)?;
        let general = word_fit(&words.alignment, &words.path, &free, frames);
        let scores = ear(&self.evidence_from(&words.feats, &states));
        let forced = search::viterbi_scored(&self.model, &words.graph, &scores).ok_or(AlignError::NoPath)?;
        let loop_graph = search::Graph::phone_loop(&self.model, &ear_lm.transition);
        let free = search::viterbi_scored(&self.model, &loop_graph, &scores).ok_or(AlignError::NoPath)?;
        let fit = word_fit(&words.alignment, &forced, &free, frames);
        Ok((words.alignment, fit, general))
    }

    /// The phones of a recording, the way every command takes one: with `words`, aligned to
    /// them and — unless `accept_mismatch` — refused when they do not fit the sound
    /// ([`AlignError::WordsDoNotMatch`] naming the worst words); without, recognised from the
    /// sound alone ([`Aligner::recognise`]).
    pub fn hear(
        &self,
        samples: &[f32],
        rate: u32,
        words: Option<&str>,
        accept_mismatch: bool,
    ) -> Result<Vec<TimedPhone>, AlignError> {
        let lm = || self.phone_loop(PHONE_WEIGHT, PHONE_PENALTY);
        let Some(words) = words else {
            return self.recognise(samples, rate, &lm());
        };
        if accept_mismatch {
            return Ok(self.align(samples, rate, words)?.phones);
        }
        let (alignment, fit) = self.align_checked(samples, rate, words, &lm())?;
        if !fit.matches() {
            return Err(AlignError::WordsDoNotMatch {
                judge: GENERAL_JUDGE,
                overall: fit.overall,
                least: LEAST_OVERALL_FIT,
                worst: fit.worst_words(&alignment.words, 3),
            });
        }
        Ok(alignment.phones)
    }

    /// The words' search ([`WordSearch`]).
    fn search_words(
        &self,
        samples: &[f32],
        rate: u32,
        text: &str,
    ) -> Result<WordSearch, AlignError> {
        if rate != frontend::SAMPLE_RATE {
            return Err(AlignError::SampleRate(rate));
        }
        // `word_count` is the number of `dict::words` (tested), found without making them.
        let count = dict::word_count(text);
        if count == 0 {
            return Err(AlignError::NoWords);
        }
        let feats = self.features(samples, rate)?;
        // Every word is at least one phone of three states, a frame each: judged from the
        // count before any word or pronunciation is made (issue 69, R5-12).
        if count * model::STATES > feats.len() {
            return Err(AlignError::TranscriptTooLong {
                phones: count,
                needed: count * model::STATES,
                frames: feats.len(),
            });
        }
        // Numbers, money and times as they are spoken (after the count: a huge transcript is
        // refused before anything is made of it).
        let text = &crate::phonemes::spoken::written_out(text);
        let words = dict::words(text);
        let prons = self.dict.pronunciations(&words, &self.model)?;
        let phones: usize = prons
            .iter()
            .map(|p| p.iter().map(Vec::len).min().unwrap_or(0))
            .sum();
        let prons: Vec<&[Vec<u8>]> = prons.iter().map(Vec::as_slice).collect();
        let needed = phones * model::STATES;
        if feats.len() < needed {
            return Err(AlignError::TranscriptTooLong {
                phones,
                needed,
                frames: feats.len(),
            });
        }
        let graph = search::Graph::build(&self.model, &words, &prons);
        let path = search::viterbi(&self.model, &graph, &feats).ok_or(AlignError::NoPath)?;
        let alignment = graph.alignment(&self.model, &words, &path, feats.len());
        Ok(WordSearch {
            alignment,
            path,
            feats,
            graph,
        })
    }

    /// The checks every search needs: 16 kHz, at most [`MAX_SECONDS`], finite, long enough,
    /// not silent; gives the peak in dB below full scale.
    fn check_sound(&self, samples: &[f32], rate: u32) -> Result<f64, AlignError> {
        if rate != frontend::SAMPLE_RATE {
            return Err(AlignError::SampleRate(rate));
        }
        let seconds = samples.len() as f64 / rate as f64;
        if seconds > MAX_SECONDS {
            return Err(AlignError::TooLong {
                seconds,
                max: MAX_SECONDS,
            });
        }
        if let Some(index) = samples.iter().position(|x| !x.is_finite()) {
            return Err(AlignError::NotFinite { index });
        }
        if samples.len() < frontend::FRAME_SIZE {
            return Err(AlignError::EmptyAudio {
                samples: samples.len(),
            });
        }
        let peak = samples.iter().fold(0f32, |m, &x| m.max(x.abs()));
        let peak_dbfs = 20.0 * (peak.max(1e-10) as f64).log10();
        if peak_dbfs < -60.0 {
            return Err(AlignError::Silent { peak_dbfs });
        }
        Ok(peak_dbfs)
    }

    /// The front end's features of `samples`, after [`Self::check_sound`].
    fn features(
        &self,
        samples: &[f32],
        rate: u32,
    ) -> Result<Vec<[f32; frontend::FEATURE_DIM]>, AlignError> {
        let peak_dbfs = self.check_sound(samples, rate)?;
        // The front end works in int16 units, as pocketsphinx receives them.
        let pcm: Vec<f32> = samples
            .iter()
            .map(|&x| f32::from(crate::audio::to_pcm16(x)))
            .collect();
        let mut cep = self.frontend.cepstra_warm(&pcm);
        if frontend::cmn(&mut cep).is_none() {
            return Err(AlignError::Silent { peak_dbfs });
        }
        Ok(frontend::features(&cep))
    }

    /// Phone recognition without words: the best path through a loop of the acoustic model's
    /// context-independent phones weighted by `lm` (pocketsphinx's allphone search) — the
    /// mouth needs the right shapes, not the right words. Silences and noises come out as
    /// `SIL`; sound with too little speech ([`LEAST_SPEECH`], [`MOST_NOISE_PER_SPEECH`]) is
    /// refused.
    pub fn recognise(
        &self,
        samples: &[f32],
        rate: u32,
        lm: &PhoneLoop,
    ) -> Result<Vec<TimedPhone>, AlignError> {
        self.recognise_features(&self.features(samples, rate)?, lm)
    }

    /// [`Self::recognise`] of front-end features.
    fn recognise_features(
        &self,
        feats: &[[f32; frontend::FEATURE_DIM]],
        lm: &PhoneLoop,
    ) -> Result<Vec<TimedPhone>, AlignError> {
        let (graph, path) = self.free_path(feats, lm)?;
        self.check_speech(&graph, &path, feats.len())?;
        Ok(merge_pieces(graph.phones(&self.model, &path, feats.len())))
    }

    /// Refuses a phone loop's `path` over `frames` frames that holds too little speech
    /// ([`LEAST_SPEECH`], [`MOST_NOISE_PER_SPEECH`]).
    fn check_speech(&self, graph: &search::Graph, path: &search::Path, frames: usize) -> Result<(), AlignError> {
        let (mut speech, mut noise) = (0u32, 0u32);
        for (phone, start, end) in graph.phone_spans(path, frames) {
            if usize::from(phone) == self.model.sil {
                continue;
            }
            if self.model.is_filler(phone.into()) {
                noise += end - start;
            } else {
                speech += end - start;
            }
        }
        let frames = frames as f64;
        let (speech, noise) = (f64::from(speech) / frames, f64::from(noise) / frames);
        if speech < LEAST_SPEECH || noise > MOST_NOISE_PER_SPEECH * speech {
            return Err(AlignError::NoSpeech { speech, noise });
        }
        Ok(())
    }

    /// Phones heard by another ear: sound that [`Self::recognise`] refuses (through `lm`) is
    /// refused, then `ear` scores each phone in each frame of the sound's [`Evidence`]
    /// (scaled log-likelihoods: a talker's own classifier) and the best path of the loop
    /// `ear_lm` through those scores is the answer, given with the evidence it was heard by
    /// (a talker's map draws the lips from the same: computed once).
    pub fn recognise_by(
        &self,
        samples: &[f32],
        rate: u32,
        lm: &PhoneLoop,
        ear: impl FnOnce(&Evidence) -> Vec<Vec<f32>>,
        ear_lm: &PhoneLoop,
    ) -> Result<(Vec<TimedPhone>, Evidence), AlignError> {
        let feats = self.features(samples, rate)?;
        // One scoring of every phone's states serves the refusal's search and the evidence.
        let states = self.every_other_state_scores(&feats);
        let (free, path) = self.loop_path(&states, lm)?;
        self.check_speech(&free, &path, feats.len())?;
        let heard = self.evidence_from(&feats, &states);
        let scores = ear(&heard);
        let graph = search::Graph::phone_loop(&self.model, &ear_lm.transition);
        let path = search::viterbi_scored(&self.model, &graph, &scores).ok_or(AlignError::NoPath)?;
        Ok((merge_pieces(graph.phones(&self.model, &path, scores.len())), heard))
    }

    /// Every context-independent phone's state scores in each frame of `feats`, scored at
    /// every other frame, the frames between taken midway (pocketsphinx's `-ds 2`).
    fn every_other_state_scores(&self, feats: &[[f32; frontend::FEATURE_DIM]]) -> Vec<Vec<[f32; model::STATES]>> {
        let even: Vec<_> = feats.iter().step_by(2).copied().collect();
        every_other(search::ci_state_scores(&self.model, &even), feats.len(), |a, b| {
            a.iter().zip(b).map(|(x, y)| std::array::from_fn(|s| 0.5 * (x[s] + y[s]))).collect()
        })
    }

    /// The best path of the phone loop `lm` over `feats`, and the loop's graph: every phone's
    /// states scored first, codebook by codebook over blocks of frames ([`search::ci_state_scores`];
    /// the same scores as frame by frame, a quarter of the time less).
    fn free_path(
        &self,
        feats: &[[f32; frontend::FEATURE_DIM]],
        lm: &PhoneLoop,
    ) -> Result<(search::Graph, search::Path), AlignError> {
        self.loop_path(&search::ci_state_scores(&self.model, feats), lm)
    }

    /// The best path of the phone loop `lm` over every phone's state scores in each frame
    /// (`states`, [`search::ci_state_scores`]), and the loop's graph.
    fn loop_path(
        &self,
        states: &[Vec<[f32; model::STATES]>],
        lm: &PhoneLoop,
    ) -> Result<(search::Graph, search::Path), AlignError> {
        let graph = search::Graph::phone_loop(&self.model, &lm.transition);
        let path = search::viterbi_states(&self.model, &graph, states).ok_or(AlignError::NoPath)?;
        Ok((graph, path))
    }

    /// What the acoustic model hears in each 10 ms frame of `samples`, before any search:
    /// the cepstra and every context-independent phone's score ([`Evidence`]).
    pub fn acoustic_evidence(&self, samples: &[f32], rate: u32) -> Result<Evidence, AlignError> {
        Ok(self.evidence_of(&self.features(samples, rate)?))
    }

    /// [`Self::acoustic_evidence`] of front-end features (a live [`Recogniser`]'s).
    pub fn evidence_of(&self, feats: &[[f32; frontend::FEATURE_DIM]]) -> Evidence {
        self.evidence_from(feats, &search::ci_state_scores(&self.model, feats))
    }

    /// [`Self::evidence_of`] with the phones' state scores already computed.
    fn evidence_from(
        &self,
        feats: &[[f32; frontend::FEATURE_DIM]],
        states: &[Vec<[f32; model::STATES]>],
    ) -> Evidence {
        let mut scores = search::phone_scores(states);
        for row in &mut scores {
            let best = row.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            row.iter_mut().for_each(|v| *v -= best);
        }
        let cepstra = feats
            .iter()
            .map(|f| std::array::from_fn(|k| f[k]))
            .collect();
        Evidence { cepstra, scores }
    }

    /// A live phone recogniser over the loop `lm`: samples in as they arrive, phones out
    /// [`STREAM_LAG_FRAMES`] after they end ([`Recogniser`]).
    pub fn recogniser(&self, rate: u32, lm: &PhoneLoop) -> Result<Recogniser<'_>, AlignError> {
        if rate != frontend::SAMPLE_RATE {
            return Err(AlignError::SampleRate(rate));
        }
        let graph = search::Graph::phone_loop(&self.model, &lm.transition);
        Ok(Recogniser {
            model: &self.model,
            decoder: search::Decoder::new(&self.model, &graph),
            graph,
            stream: frontend::Stream::new(&self.frontend),
            committed: 0,
            samples: 0,
            lag: STREAM_LAG_FRAMES,
            least_piece: STREAM_LEAST_PIECE,
            sounding: None,
            features: Vec::new(),
        })
    }

    /// A phone loop weighted by the phone bigram of this aligner's dictionary
    /// ([`PhoneLoop::log_bigram`], estimated once per aligner).
    pub fn phone_loop(&self, weight: f64, penalty: f64) -> PhoneLoop {
        let bigram = self.bigram.get_or_init(|| {
            PhoneLoop::log_bigram(
                &self.dict.every_pronunciation(&self.model),
                self.model.ci_names.len(),
                self.model.sil,
            )
        });
        PhoneLoop::weighted(bigram, weight, penalty)
    }
}

/// Frames a live [`Recogniser`] waits after a phone's end before giving it out, so that the
/// next frames can still change it (chosen on GRID s1's validation split with
/// [`STREAM_LEAST_PIECE`], BENCHMARKS "Phones without words": a frame waits 130 ms for its
/// phone at the median, counting the features' 3-frame look-ahead and the 25.6 ms window).
pub const STREAM_LAG_FRAMES: usize = 5;

/// Frames a phone still sounding must have lasted before a piece of it is given out, so that
/// long phones and pauses do not hold the stream back (shorter pieces are mostly guesses
/// the next frames revise; as [`STREAM_LAG_FRAMES`]).
pub const STREAM_LEAST_PIECE: usize = 15;

/// Phone recognition as the sound arrives (the phone loop of [`Aligner::recognise`], a
/// running CMN, fixed-lag decisions): each chunk in returns the phones of the best path so
/// far that ended [`STREAM_LAG_FRAMES`] ago, which tile the stream from its start without
/// gaps or overlaps; [`Recogniser::finish`] the rest. A phone still sounding then that has
/// lasted [`STREAM_LEAST_PIECE`] frames comes in pieces: [`merge_pieces`] joins them.
pub struct Recogniser<'a> {
    model: &'a AcousticModel,
    graph: search::Graph,
    decoder: search::Decoder<'a>,
    stream: frontend::Stream<'a>,
    /// Frames given out: the phones so far cover `0..committed`.
    committed: u32,
    /// Samples taken.
    samples: usize,
    /// Frames between a phone's end and its release.
    lag: usize,
    /// Frames a phone must have lasted before a piece of it is given out.
    least_piece: usize,
    /// The phone after the ones given out, as the best path has it now.
    sounding: Option<TimedPhone>,
    /// Features made since [`Recogniser::take_features`] last took them.
    features: Vec<[f32; frontend::FEATURE_DIM]>,
}

impl Recogniser<'_> {
    /// Takes the next `samples` (mono, 16 kHz, −1…1) and returns the phones settled by them.
    pub fn push(&mut self, samples: &[f32]) -> Result<Vec<TimedPhone>, AlignError> {
        if let Some(k) = samples.iter().position(|x| !x.is_finite()) {
            return Err(AlignError::NotFinite {
                index: self.samples + k,
            });
        }
        self.samples += samples.len();
        let pcm: Vec<f32> = samples
            .iter()
            .map(|&x| f32::from(crate::audio::to_pcm16(x)))
            .collect();
        let feats = self.stream.push(&pcm);
        for states in search::ci_state_scores(self.model, &feats) {
            self.decoder.step_states(&self.graph, &states).ok_or(AlignError::NoPath)?;
        }
        self.features.extend(feats);
        let settled = self.decoder.frames.saturating_sub(self.lag) as u32;
        let path = self.decoder.partial();
        Ok(self.commit(&path, settled))
    }

    /// Ends the stream: the phones not given out yet.
    pub fn finish(mut self) -> Result<Vec<TimedPhone>, AlignError> {
        for states in search::ci_state_scores(self.model, &self.stream.finish()) {
            self.decoder.step_states(&self.graph, &states).ok_or(AlignError::NoPath)?;
        }
        if self.decoder.frames == 0 {
            return Err(AlignError::EmptyAudio {
                samples: self.samples,
            });
        }
        let path = self.decoder.finish(&self.graph).ok_or(AlignError::NoPath)?;
        Ok(self.commit(&path, self.decoder.frames as u32))
    }

    /// Waits `frames` (instead of [`STREAM_LAG_FRAMES`]) after a phone's end before giving
    /// it out, and gives pieces of phones that lasted `least_piece` frames (instead of
    /// [`STREAM_LEAST_PIECE`]): fewer answer sooner, more change their minds less.
    pub fn with_lag(mut self, frames: usize, least_piece: usize) -> Self {
        self.lag = frames;
        self.least_piece = least_piece;
        self
    }

    /// The front end's features made since the last call, in order from the stream's start
    /// (10 ms each): what a live sound-to-face map hears.
    pub fn take_features(&mut self) -> Vec<[f32; frontend::FEATURE_DIM]> {
        std::mem::take(&mut self.features)
    }

    /// Seconds of sound taken so far.
    pub fn seconds(&self) -> f64 {
        self.samples as f64 / f64::from(frontend::SAMPLE_RATE)
    }

    /// Gives out the phones of `path` from where the last ones ended up to frame `until`;
    /// a phone still sounding there is given up to `until` and its rest later, as a piece of
    /// the same phone starting where the first ended.
    fn commit(&mut self, path: &search::Path, until: u32) -> Vec<TimedPhone> {
        let mut out = Vec::new();
        self.sounding = None;
        let frames = self.decoder.frames as u32;
        for (phone, start, end) in self.graph.phone_spans(path, self.decoder.frames) {
            let young = end > until && start + self.least_piece as u32 > until;
            let (start, end) = (start.max(self.committed), end.min(until));
            if start < end && !young {
                out.push(search::timed_phone(self.model, phone, start, end));
                self.committed = end;
            } else if self.sounding.is_none() && end > self.committed.max(start) {
                let start = start.max(self.committed);
                self.sounding = Some(search::timed_phone(self.model, phone, start, frames.max(start + 1)));
            }
        }
        out
    }

    /// The phone the best path now has after the ones given out, from where they end to the
    /// frames decoded: a guess the next frames may change (what a live synthesis reads as
    /// the last phone's right context). `None` before the first push or after the end.
    pub fn sounding(&self) -> Option<&TimedPhone> {
        self.sounding.as_ref()
    }
}

/// Per 10 ms frame: the 13 mean-normalised cepstra, and each context-independent phone's
/// best state log-likelihood less the frame's best (the acoustic model's `ci_names` order).
#[derive(Clone, Debug)]
pub struct Evidence {
    /// The cepstra, as the searches see them.
    pub cepstra: Vec<[f32; frontend::N_CEP]>,
    /// The phones' scores, 0 for the best.
    pub scores: Vec<Vec<f32>>,
}

/// `rows` of the even frames of `n` spread over all `n`: each odd frame `mid` of its two
/// neighbours (the last one, without a next, its previous).
pub fn every_other<R: Clone>(rows: Vec<R>, n: usize, mid: impl Fn(&R, &R) -> R) -> Vec<R> {
    let mut out = Vec::with_capacity(n);
    for (k, row) in rows.iter().enumerate() {
        if k > 0 {
            out.push(mid(&rows[k - 1], row));
        }
        out.push(row.clone());
    }
    if let Some(last) = rows.last()
        && out.len() < n
    {
        out.push(last.clone());
    }
    out
}

/// Joins contiguous pieces of the same phone (as a live [`Recogniser`] gives them).
pub fn merge_pieces(phones: Vec<TimedPhone>) -> Vec<TimedPhone> {
    let mut out: Vec<TimedPhone> = Vec::with_capacity(phones.len());
    for p in phones {
        match out.last_mut() {
            Some(last) if last.phone == p.phone && last.end == p.start && last.word == p.word => {
                last.end = p.end;
            }
            _ => out.push(p),
        }
    }
    out
}

/// Timed phones as label segments (`SIL` → `sil`).
pub fn segments(phones: &[TimedPhone]) -> Vec<Segment> {
    phones
        .iter()
        .map(|p| Segment {
            start: p.start,
            end: p.end,
            phone: Phone::parse(&p.phone).unwrap_or(Phone::SIL),
        })
        .collect()
}

/// A words' search ([`Aligner::search_words`]): the alignment, its best path, the features it
/// ran over and its graph.
struct WordSearch {
    alignment: Alignment,
    path: search::Path,
    feats: Vec<[f32; frontend::FEATURE_DIM]>,
    graph: search::Graph,
}

/// The fit of `alignment`'s words: the `forced` path's log-likelihood over each word's frames
/// less the `free` loop's, per frame ([`WordFit`]); `frames` in all.
fn word_fit(alignment: &Alignment, forced: &search::Path, free: &search::Path, frames: usize) -> WordFit {
    let per_frame = |start: f64, end: f64| {
        let (a, b) = (start * 100.0, end * 100.0);
        let forced = forced.up_to(b, frames) - forced.up_to(a, frames);
        let free = free.up_to(b, frames) - free.up_to(a, frames);
        (forced - free) / (b - a).max(1.0)
    };
    let words = alignment
        .words
        .iter()
        .map(|w| per_frame(w.start, w.end))
        .collect();
    let overall = per_frame(0.0, frames as f64 / FRAMES_PER_SECOND);
    WordFit { words, overall }
}

/// How well words fit their sound (goodness of pronunciation): per word, the forced
/// alignment's log-likelihood over the word's frames minus the free phone loop's over the
/// same frames, per frame (nats). Near 0 when the words were said — the loop can only do a
/// little better than the right phones — and far below when they were not.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WordFit {
    /// Per aligned word, in order.
    pub words: Vec<f64>,
    /// Over the whole recording.
    pub overall: f64,
}

/// Least [`WordFit::overall`] of words that match their sound, nats per frame (chosen on GRID
/// s1's validation split: BENCHMARKS "Do the words match the speech?").
pub const LEAST_OVERALL_FIT: f64 = 0.35;

/// Least fit of any one word of a matching transcript, nats per frame (as
/// [`LEAST_OVERALL_FIT`]).
pub const LEAST_WORD_FIT: f64 = -12.5;

impl WordFit {
    /// Whether the words match the sound: the whole at least [`LEAST_OVERALL_FIT`] and no
    /// word below [`LEAST_WORD_FIT`].
    pub fn matches(&self) -> bool {
        self.overall >= LEAST_OVERALL_FIT && self.words.iter().all(|&w| w >= LEAST_WORD_FIT)
    }

    /// The indices of the `n` worst-fitting words, worst first.
    pub fn worst(&self, n: usize) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.words.len()).collect();
        order.sort_by(|&a, &b| self.words[a].total_cmp(&self.words[b]));
        order.truncate(n);
        order
    }

    /// The `n` worst-fitting of the aligned `words`, worst first, as a list to show.
    pub fn worst_words(&self, words: &[TimedWord], n: usize) -> String {
        let worst: Vec<&str> = self.worst(n).iter().map(|&k| words[k].word.as_str()).collect();
        worst.join(", ")
    }
}

/// Least fraction of a recording's frames recognised as speech sounds (not silence or noise)
/// for [`Aligner::recognise`] to go on: stationary noise and drums come out as silence
/// (BENCHMARKS "Phones without words": GRID clips 0.4–0.6, with noise added 0.34).
pub const LEAST_SPEECH: f64 = 0.1;

/// Most frames of noise (the model's filler sounds, which take tones and chords) per frame of
/// speech sounds in a recording [`Aligner::recognise`] takes: speech has little, music much
/// (plucked notes 0.49, chords far more). 0.25 refused one of GRID s1's 900 clips (bgbu2n,
/// 0.26: a breathy take).
pub const MOST_NOISE_PER_SPEECH: f64 = 0.3;

/// Language weight of the phone bigram in [`Aligner::recognise`] (chosen on GRID s1's
/// validation split, BENCHMARKS "Phones without words").
pub const PHONE_WEIGHT: f64 = 6.5;

/// Log phone insertion penalty of [`Aligner::recognise`] (as [`PHONE_WEIGHT`]).
pub const PHONE_PENALTY: f64 = -2.0;

/// The transition costs of a phone loop: `weight · ln P(b | a) + penalty` for phone `b` after
/// phone `a`.
#[derive(Clone, Debug)]
pub struct PhoneLoop {
    /// `[a][b]`, by CI phone id.
    pub transition: Vec<Vec<f32>>,
}

impl PhoneLoop {
    /// The phone bigram `ln P(b | a)` of a pronouncing dictionary, each pronunciation once:
    /// counts within words, silence before the first and after the last phone, and — for
    /// words spoken without a pause between them — each word-final phone followed by the
    /// distribution of word-initial ones (weighted as much as the pauses); add-one smoothed.
    pub fn log_bigram(prons: &[Vec<u8>], phones: usize, sil: usize) -> Vec<Vec<f64>> {
        let mut counts = vec![vec![1.0f64; phones]; phones];
        let (mut first, mut last) = (vec![0.0f64; phones], vec![0.0f64; phones]);
        for p in prons.iter().filter(|p| !p.is_empty()) {
            let p: Vec<usize> = p.iter().map(|&c| c as usize).collect();
            counts[sil][p[0]] += 1.0;
            counts[p[p.len() - 1]][sil] += 1.0;
            for w in p.windows(2) {
                counts[w[0]][w[1]] += 1.0;
            }
            first[p[0]] += 1.0;
            last[p[p.len() - 1]] += 1.0;
        }
        let starts: f64 = first.iter().sum::<f64>().max(1.0);
        for a in 0..phones {
            for b in 0..phones {
                counts[a][b] += last[a] * first[b] / starts;
            }
        }
        counts
            .iter()
            .map(|row| {
                let total: f64 = row.iter().sum();
                row.iter().map(|&c| (c / total).ln()).collect()
            })
            .collect()
    }

    /// The loop's costs from a bigram: `weight · ln P(b | a) + penalty`.
    pub fn weighted(log_bigram: &[Vec<f64>], weight: f64, penalty: f64) -> Self {
        let transition = log_bigram
            .iter()
            .map(|row| row.iter().map(|&l| (weight * l + penalty) as f32).collect())
            .collect();
        PhoneLoop { transition }
    }
}

impl Alignment {
    /// Praat TextGrid with a `words` and a `phones` tier, silence as empty intervals (the
    /// Montreal Forced Aligner's layout).
    pub fn textgrid(&self) -> String {
        use crate::phonemes::{Tier, format_textgrid};
        let words = Tier {
            name: "words",
            intervals: self
                .words
                .iter()
                .map(|w| (w.start, w.end, w.word.clone()))
                .collect(),
        };
        let phones = Tier {
            name: "phones",
            intervals: self
                .phones
                .iter()
                .filter(|p| p.word.is_some())
                .map(|p| (p.start, p.end, p.phone.clone()))
                .collect(),
        };
        format_textgrid(&[words, phones], self.frames as f64 * FRAME_SECONDS)
    }

    /// Writes the alignment by extension: `.TextGrid` (words and phones), else phone labels
    /// (`.lab` HTK, `.tsv`), atomically.
    pub fn write(&self, path: &Path) -> Result<(), crate::phonemes::PhonemeError> {
        let is_textgrid = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("textgrid"));
        if is_textgrid {
            crate::atomic::write_file(path, self.textgrid().as_bytes()).map_err(|source| {
                crate::phonemes::PhonemeError::Io {
                    path: path.into(),
                    source,
                }
            })
        } else {
            crate::phonemes::write_labels(path, &self.segments())
        }
    }
}
