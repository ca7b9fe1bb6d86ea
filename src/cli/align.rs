//! `facespace align`: a recording and its words → word and phone timings.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use facespace::align::{self, Aligner};
use facespace::audio;

#[derive(Args)]
pub struct AlignArgs {
    /// The recording: WAV, MP4/M4A (AAC), or any format a system ffmpeg reads.
    audio: PathBuf,
    /// The words spoken. Without them (and without --transcript) the phones are recognised
    /// from the sound alone: no word tier, and far less exact.
    #[arg(long, conflicts_with = "transcript")]
    text: Option<String>,
    /// A text file holding the words spoken.
    #[arg(long)]
    transcript: Option<PathBuf>,
    /// Output: `.TextGrid` (word and phone tiers), `.lab` (HTK phones) or `.tsv`.
    #[arg(short, long)]
    output: PathBuf,
    /// Extra pronunciations (`WORD  P H O N E S` lines), added to the CMU dictionary; may repeat.
    #[arg(long = "dict")]
    dicts: Vec<PathBuf>,
    /// Acoustic model folder [default: the committed CMU Sphinx en-us model, models/en-us].
    #[arg(long)]
    acoustic_model: Option<PathBuf>,
    /// The talker speaking, heard by its own ear (a classifier learnt with its sound-to-face
    /// map on its recordings): without words its phones are recognised far more exactly in the
    /// words its recordings hold (PER 8.3 % on GRID s1's talker against 64 % from the general
    /// acoustic model; on words it never heard, worse: 69 % against 54 %), with words their
    /// fit is judged by it and the general model together.
    #[arg(long, conflicts_with_all = ["acoustic_model", "dicts"])]
    talker: Option<PathBuf>,
}

pub fn run(a: AlignArgs) -> Result<()> {
    let mut inputs = vec![a.audio.as_path()];
    inputs.extend(a.transcript.as_deref());
    inputs.extend(a.dicts.iter().map(|d| d.as_path()));
    super::check_output(&a.output, &inputs)?;
    let text = match (&a.text, &a.transcript) {
        (Some(t), _) => Some(t.clone()),
        (None, Some(p)) => Some(
            facespace::safe_read::read_regular_string(p)
                .with_context(|| format!("reading the transcript {}", p.display()))?,
        ),
        (None, None) => None,
    };
    let started = Instant::now();
    let dir = a
        .acoustic_model
        .clone()
        .unwrap_or_else(align::default_model_dir);
    let aligner = Aligner::load(&dir, &a.dicts)?;
    let loaded = started.elapsed().as_secs_f64();
    let speech = audio::read(&a.audio, align::frontend::SAMPLE_RATE, align::MAX_SECONDS)?;
    let lm = aligner.phone_loop(align::PHONE_WEIGHT, align::PHONE_PENALTY);
    let talker = a.talker.as_deref().map(facespace::talker::Talker::load).transpose()?;
    let map = match &talker {
        Some(t) => t.sound_to_face()?,
        None => None,
    };
    let mut fit = None;
    let result = match &text {
        Some(text) => {
            let aligning = || format!("aligning {}", a.audio.display());
            let (samples, rate) = (&speech.samples, speech.rate);
            // The fit as the talker's ear hears it, where it has one: (fit, least, matches).
            // Only where the ear may judge these words, and finds a path through them (as
            // `say` decides: Talker::hear_words).
            let by_ear = match (&talker, map) {
                (Some(t), Some(map)) if Aligner::could_fit(text, speech.seconds()) && t.ear_judges(&aligner, text)? => {
                    match map.align_checked(&aligner, samples, rate, text) {
                        Err(align::AlignError::NoPath) => None,
                        found => found.with_context(aligning)?,
                    }
                }
                _ => None,
            };
            let (alignment, checked) = match by_ear {
                Some((alignment, f, general)) => {
                    let score = facespace::sound_to_face::ear_fit(&f, &general);
                    let matches = facespace::sound_to_face::ear_matches(&f, &general);
                    (alignment, (score, facespace::sound_to_face::LEAST_FIT, matches, f))
                }
                None => {
                    let (alignment, f) =
                        aligner.align_checked(samples, rate, text, &lm).with_context(aligning)?;
                    (alignment, (f.overall, align::LEAST_OVERALL_FIT, f.matches(), f))
                }
            };
            fit = Some(checked);
            alignment
        }
        None => {
            let recognising = || format!("recognising the phones of {}", a.audio.display());
            let phones = match &talker {
                Some(talker) => {
                    let phones = talker.recognise(&a.audio).with_context(recognising)?;
                    println!("no words given: {} (no word tier)", talker.heard_by()?);
                    phones
                }
                None => {
                    let phones = aligner
                        .recognise(&speech.samples, speech.rate, &lm)
                        .with_context(recognising)?;
                    println!("no words given: phones recognised from the sound alone (no word tier)");
                    phones
                }
            };
            align::Alignment {
                words: Vec::new(),
                frames: (speech.seconds() * 100.0).round() as usize,
                score_per_frame: f64::NAN,
                phones,
            }
        }
    };
    result
        .write(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    println!(
        "{} words, {} phones over {:.2} s → {} (model {:.0} ms, total {:.0} ms)",
        result.words.len(),
        result.phones.iter().filter(|p| p.phone != "SIL").count(),
        speech.seconds(),
        a.output.display(),
        loaded * 1e3,
        started.elapsed().as_secs_f64() * 1e3
    );
    for (k, w) in result.words.iter().enumerate() {
        let f = fit.as_ref().map_or(String::new(), |f| format!("  fit {:+.2}", f.3.words[k]));
        println!("  {:>7.2} {:>7.2}  {}{f}", w.start, w.end, w.word);
    }
    let ear = if map.is_some() { ", as the talker's own ear and the general model hear it" } else { "" };
    if let Some((score, least, matches, f)) = &fit {
        if *matches {
            println!("the words fit the speech (overall {score:+.2} nats/frame{ear})");
        } else {
            println!(
                "warning: these words may not be what was said (overall fit {score:+.2} nats/frame, least {least:.2}{ear}; worst: {}) — check the transcript, or leave out the words to recognise the phones",
                f.worst_words(&result.words, 3)
            );
        }
    }
    Ok(())
}
