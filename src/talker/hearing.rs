//! How a talker hears speech: words aligned and judged, phones recognised by its own ear,
//! text spoken in its voice.

use std::path::{Path, PathBuf};

use super::{SayRequest, Speech, Talker, TalkerError};
use crate::align::Evidence;
use crate::phonemes::Segment;

/// The sound of the recording `audio` as the aligner hears it (16 kHz, at most
/// [`crate::align::MAX_SECONDS`]).
fn speech_sound(audio: &Path) -> Result<crate::audio::Audio, TalkerError> {
    crate::audio::read(audio, crate::align::frontend::SAMPLE_RATE, crate::align::MAX_SECONDS)
        .map_err(|e| TalkerError::Align {
            path: audio.to_path_buf(),
            source: Box::new(e.into()),
        })
}

/// The phones of a request's speech, its words when there were words, the sound to put
/// under the video, and what the talker's own ear heard in it when it recognised the phones.
type Heard = (Vec<Segment>, Option<String>, Option<PathBuf>, Option<Evidence>);

impl Talker {
    /// The phones of the recording `audio`, its words unknown: heard by the talker's own ear
    /// (its sound-to-face map's [`crate::sound_to_face::PhoneClassifier`]) where it has one,
    /// else by the acoustic model's phone loop. Sound that is not speech is refused.
    pub fn recognise(&self, audio: &Path) -> Result<Vec<crate::align::TimedPhone>, TalkerError> {
        Ok(self.hear_sound(audio)?.0)
    }

    /// [`Self::recognise`], with the evidence the talker's own ear heard the phones by
    /// (`None` when the acoustic model's phone loop heard them).
    fn hear_sound(&self, audio: &Path) -> Result<(Vec<crate::align::TimedPhone>, Option<Evidence>), TalkerError> {
        let sound = speech_sound(audio)?;
        let failed = |e| TalkerError::Align {
            path: audio.to_path_buf(),
            source: Box::new(e),
        };
        let aligner = self.default_aligner().map_err(failed)?;
        let (samples, rate) = (&sound.samples, sound.rate);
        if let Some(map) = self.sound_to_face()?
            && let Some((phones, heard)) = map.recognise(aligner, samples, rate).map_err(failed)?
        {
            return Ok((phones, Some(heard)));
        }
        let lm = aligner.phone_loop(crate::align::PHONE_WEIGHT, crate::align::PHONE_PENALTY);
        Ok((aligner.recognise(samples, rate, &lm).map_err(failed)?, None))
    }

    /// The phones of the recording `audio` aligned to its `words` by `aligner` (the talker's
    /// own: [`Self::aligner`]; always the general acoustic model's alignment), refused —
    /// unless `accept_mismatch` — when the words do not fit the sound. The talker's own ear
    /// judges beside the general model (far surer on its own voice and words, BENCHMARKS "The
    /// talker's own ear") only where it can: every phone of the words has at least
    /// [`crate::sound_to_face::EAR_LEAST_EXAMPLES`] examples in its recordings, and the ear
    /// finds a path through them; otherwise the general model's rule decides (issue 66: an
    /// ear learnt on one talker's few words refused true transcripts of other words). The
    /// refusal names which judged.
    pub fn hear_words(
        &self,
        aligner: &crate::align::Aligner,
        audio: &Path,
        words: &str,
        accept_mismatch: bool,
    ) -> Result<Vec<crate::align::TimedPhone>, TalkerError> {
        let sound = speech_sound(audio)?;
        let failed = |e| TalkerError::Align {
            path: audio.to_path_buf(),
            source: Box::new(e),
        };
        let (samples, rate) = (&sound.samples, sound.rate);
        // (Words that cannot fit the sound are refused by the general model from their count.)
        if let Some(map) = self.sound_to_face()?.filter(|_| !accept_mismatch)
            && crate::align::Aligner::could_fit(words, sound.seconds())
            && self.ear_judges(aligner, words)?
        {
            match map.hear_words(aligner, samples, rate, words) {
                Ok(Some(phones)) => return Ok(phones),
                // The ear found no path through words it has too little of: the general
                // model's rule decides.
                Ok(None) | Err(crate::align::AlignError::NoPath) => {}
                Err(e) => return Err(failed(e)),
            }
        }
        aligner
            .hear(samples, rate, Some(words), accept_mismatch)
            .map_err(failed)
    }

    /// Whether the talker's own ear may judge `words` beside the general model: it has an
    /// ear, and has heard enough of every phone of the words
    /// ([`crate::sound_to_face::EAR_LEAST_EXAMPLES`] examples each in its codebook).
    pub fn ear_judges(&self, aligner: &crate::align::Aligner, words: &str) -> Result<bool, TalkerError> {
        if !self.sound_to_face()?.is_some_and(|m| m.hears_phones()) {
            return Ok(false);
        }
        let least = crate::sound_to_face::EAR_LEAST_EXAMPLES;
        Ok(aligner.phones_of(words).is_ok_and(|phones| {
            phones.iter().all(|p| {
                *p == crate::phonemes::Phone::SIL || self.codebook.occurrences.get(p.index()).is_some_and(|o| o.len() >= least)
            })
        }))
    }

    /// The talker's own aligner (the committed dictionary), loaded on first use and kept.
    pub fn aligner(&self) -> Result<&crate::align::Aligner, TalkerError> {
        self.default_aligner().map_err(|e| TalkerError::Align {
            path: self.dir.clone(),
            source: Box::new(e),
        })
    }

    /// How [`Self::recognise`] hears phones, for a note to the user.
    pub fn heard_by(&self) -> Result<&'static str, TalkerError> {
        Ok(match self.sound_to_face()? {
            Some(map) if map.hears_phones() => {
                "the phones were heard by the talker's own ear (a classifier learnt on its recordings)"
            }
            _ => "the phones were recognised by the general acoustic model (far less exact)",
        })
    }

    /// A live phone recogniser on the talker's kept aligner (16 kHz sound).
    pub fn live_recogniser(&self) -> Result<crate::align::Recogniser<'_>, crate::align::AlignError> {
        let aligner = self.default_aligner()?;
        let lm = aligner.phone_loop(crate::align::PHONE_WEIGHT, crate::align::PHONE_PENALTY);
        aligner.recogniser(crate::align::frontend::SAMPLE_RATE, &lm)
    }

    /// [`Talker::speak`] in the talker's own voice into a WAV that lives in memory only
    /// ([`crate::atomic::MemoryFile`]): nothing of the words or their sound reaches the disk,
    /// whenever the process is killed (the live page's typed sentences, the Python package).
    pub fn speak_in_memory(
        &self,
        text: &str,
    ) -> Result<(Vec<Segment>, crate::atomic::MemoryFile), TalkerError> {
        let wav = crate::atomic::MemoryFile::new("facespace-speech.wav").map_err(|source| {
            TalkerError::Io {
                path: "a file in memory".into(),
                source,
            }
        })?;
        let (phones, _) = self.speak(text, None, self.aligner()?, wav.path())?;
        Ok((phones, wav))
    }

    /// `text` spoken in the talker's voice (or `voice`) into the WAV `wav`, and its phones
    /// aligned to that sound; with notes for the user (a voice that was missing). Numbers,
    /// money, ordinals, clock times and years are written out in words first
    /// ([`crate::phonemes::spoken`]). The text is checked first — its length ([`crate::tts::check_text`]) and that the aligner knows
    /// every word — so text that cannot be timed never runs an engine.
    pub fn speak(
        &self,
        text: &str,
        voice: Option<&str>,
        aligner: &crate::align::Aligner,
        wav: &Path,
    ) -> Result<(Vec<Segment>, Vec<String>), TalkerError> {
        let words = |source| TalkerError::Words {
            source: Box::new(source),
        };
        // Numbers, money and times written out, so the engine and the aligner say the same
        // words (issue 66); checked before and after (the first bounds the writing out).
        crate::tts::check_text(text)?;
        let text = &crate::phonemes::spoken::written_out(text);
        crate::tts::check_text(text)?;
        aligner.phone_count(text).map_err(words)?;
        let voice = voice.or(self.manifest.voice.as_ref().map(|v| v.festival.as_str()));
        let spoken = crate::tts::speak_as(text, wav, voice)?;
        let mut notes = vec![format!(
            "the text was spoken by {} in the voice {}",
            spoken.engine.name(),
            spoken.voice
        )];
        if let Some(note) = spoken.note {
            let hint = self
                .manifest
                .voice
                .as_ref()
                .filter(|v| Some(v.festival.as_str()) == voice)
                .map(|v| format!(" (`apt-get install {}`)", v.package))
                .unwrap_or_default();
            notes.push(format!("{note}{hint}"));
        }
        let phones = aligner.align_file(wav, text).map_err(|source| TalkerError::Spoken {
            engine: spoken.engine.name(),
            source: Box::new(source),
        })?;
        Ok((phones.segments(), notes))
    }

    /// The phones of `speech` and the sound to put under them, made in `staging` when the
    /// speech is text.
    pub(super) fn phones(
        &self,
        request: &SayRequest,
        staging: &Path,
        notes: &mut Vec<String>,
    ) -> Result<Heard, TalkerError> {
        // The talker's kept aligner, or one with the request's extra dictionaries.
        let extra = std::cell::OnceCell::new();
        let aligner = || -> Result<&crate::align::Aligner, crate::align::AlignError> {
            if request.dicts.is_empty() {
                return self.default_aligner();
            }
            if let Some(a) = extra.get() {
                return Ok(a);
            }
            let loaded = crate::align::Aligner::load_default(&request.dicts)?;
            Ok(extra.get_or_init(|| loaded))
        };
        let hear = |audio: &Path, words: &str| {
            let aligner = aligner().map_err(|e| TalkerError::Align {
                path: audio.to_path_buf(),
                source: Box::new(e),
            })?;
            let phones = self.hear_words(aligner, audio, words, request.accept_mismatch)?;
            Ok::<_, TalkerError>(crate::align::segments(&phones))
        };
        Ok(match &request.speech {
            Speech::Text(text) => {
                let wav = staging.join("speech.wav");
                let aligner = aligner().map_err(|e| TalkerError::Align {
                    path: self.dir.clone(),
                    source: Box::new(e),
                })?;
                let (phones, said) = self.speak(text, request.voice.as_deref(), aligner, &wav)?;
                notes.extend(said);
                (phones, Some(text.clone()), Some(wav), None)
            }
            Speech::Recording { audio, words } => {
                (hear(audio, words)?, Some(words.clone()), Some(audio.clone()), None)
            }
            // (`perform` says how the lips were drawn: by the talker's map, or these phones.)
            Speech::Sound(audio) => {
                let (phones, heard) = self.hear_sound(audio)?;
                (crate::align::segments(&phones), None, Some(audio.clone()), heard)
            }
            Speech::Labels {
                labels,
                tier,
                map,
                audio,
            } => (
                crate::phonemes::read_labels(labels, tier.as_deref(), map)?,
                None,
                audio.clone(),
                None,
            ),
            Speech::Phones { phones, audio } => (phones.clone(), None, audio.clone(), None),
        })
    }

    /// Replaces the synthesised shape and appearance of `utterance` (both variants) by
    /// what `map` predicts from the recording `audio` (from `heard`, its evidence, when the
    /// talker's ear has computed it already); the poses stay.
    pub(super) fn face_from_sound(
        &self,
        map: &crate::sound_to_face::SoundToFace,
        audio: &Path,
        heard: Option<Evidence>,
        utterance: &mut crate::synth::Utterance,
    ) -> Result<(), TalkerError> {
        let heard = match heard {
            Some(heard) => heard,
            None => {
                let sound = speech_sound(audio)?;
                self.default_aligner()
                    .and_then(|a| a.acoustic_evidence(&sound.samples, sound.rate))
                    .map_err(|e| TalkerError::Align {
                        path: audio.to_path_buf(),
                        source: Box::new(e),
                    })?
            }
        };
        // One prediction for both variants (they share the frame grid).
        let raw = &utterance.synthesis.frames;
        let face = map.predict_utterance(&heard, raw.len(), raw.fps());
        let frames = std::iter::once(&mut utterance.synthesis.frames).chain(utterance.smoothed.as_mut());
        for f in frames {
            map.apply(&face, f, &utterance.target);
        }
        let (sentences, _) = map.learnt_from();
        utterance.method = if map.hears_phones() {
            format!(
                "lips from the sound: the talker's map learnt on {sentences} sentences, {:.0} % of the face, the rest from the phones its ear heard",
                100.0 * crate::sound_to_face::MAP_SHARE
            )
        } else {
            format!("lips from the sound: the talker's map learnt on {sentences} sentences")
        };
        Ok(())
    }
}
