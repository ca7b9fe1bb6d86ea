//! `facespace visemes`: speech → a mouth-shape track for 2D rigs in Rhubarb Lip Sync's
//! formats (TSV, JSON, Moho `.dat`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use facespace::phonemes::{PhoneMap, read_labels};
use facespace::visemes::{self, Extended};
use facespace::{align, atomic, audio};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// `start<TAB>shape` lines, then the end with the closed mouth.
    Tsv,
    /// `metadata` (soundFile, duration) and `mouthCues` (start, end, value).
    Json,
    /// Moho / OpenToonz switch data (`MohoSwitch1`, `frame shape` lines).
    Dat,
}

#[derive(Args)]
pub struct VisemesArgs {
    /// The recording (WAV, MP4/M4A, or what a system ffmpeg reads).
    audio: PathBuf,
    /// The words spoken (aligned to the recording). Without words or --labels the phones are
    /// recognised from the sound alone (far less exact).
    #[arg(long, conflicts_with_all = ["transcript", "labels"])]
    text: Option<String>,
    /// A text file holding the words spoken.
    #[arg(long, conflicts_with = "labels")]
    transcript: Option<PathBuf>,
    /// Phone timings of the recording instead of words (.lab, .TextGrid, .tsv).
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Use the words even when they do not seem to be what is said.
    #[arg(long)]
    accept_mismatch: bool,
    /// A talker folder: its face, synthesised for this speech (without words, from the sound
    /// by its sound-to-face map), chooses how far each open shape opens (B, C or D by the
    /// nearest of its typical /iy/, /eh/, /aa/ openings); without words its own ear hears
    /// the phones.
    #[arg(long)]
    talker: Option<PathBuf>,
    /// Output format.
    #[arg(short = 'f', long, value_enum, default_value_t = Format::Tsv)]
    format: Format,
    /// The extended shapes the rig has (Rhubarb's `--extendedShapes`): any of G, H, X.
    #[arg(long, default_value = "GHX")]
    extended_shapes: String,
    /// Frame rate of a `.dat` file (24–100).
    #[arg(long, default_value_t = 24.0)]
    dat_frame_rate: f64,
    /// Preston Blair shape names in a `.dat` file (MBP, etc, E, AI, O, U, FV, L, rest).
    #[arg(long)]
    dat_preston_blair: bool,
    /// Where to write the track (default: standard output).
    #[arg(short, long)]
    output: Option<PathBuf>,
}

pub fn run(a: VisemesArgs) -> Result<()> {
    let extended = Extended::parse(&a.extended_shapes)?;
    if let Some(out) = &a.output {
        let mut inputs = vec![a.audio.as_path()];
        for p in [&a.transcript, &a.labels, &a.talker] {
            inputs.extend(p.as_deref());
        }
        super::check_output(out, &inputs)?;
    }
    let speech = audio::read(&a.audio, align::frontend::SAMPLE_RATE, align::MAX_SECONDS)
        .with_context(|| format!("reading {}", a.audio.display()))?;
    let words = match (&a.text, &a.transcript) {
        (Some(t), _) => Some(t.clone()),
        (None, Some(p)) => Some(
            facespace::safe_read::read_regular_string(p)
                .with_context(|| format!("reading the transcript {}", p.display()))?,
        ),
        (None, None) => None,
    };
    let talker = a
        .talker
        .as_deref()
        .map(facespace::talker::Talker::load)
        .transpose()?;
    // The speech is a recording or phones, never text: nothing is staged (no folder made).
    let perform = |talker: &facespace::talker::Talker, speech| {
        let request = facespace::talker::SayRequest::new(speech);
        anyhow::Ok(talker.perform(&request, std::path::Path::new("."))?)
    };
    // Without words, a talker performs from the sound itself, as `say` does: its own ear
    // hears the phones (its map's classifier, where it has one), and its sound-to-face map
    // opens the mouth as the recording did from the same hearing (B/C/D as the real face
    // chooses them: 75 % of the time on GRID s1's test split, against 71 % when the talker
    // performs the ear's phones and 42 % the general model's; BENCHMARKS "The talker's own
    // ear").
    let mut performed = None;
    let segments = match (&words, &a.labels, &talker) {
        (None, Some(l), _) => read_labels(l, None, &PhoneMap::default())
            .with_context(|| format!("reading {}", l.display()))?,
        (None, None, Some(talker)) => {
            let p = perform(talker, facespace::talker::Speech::Sound(a.audio.clone()))
                .with_context(|| format!("the speech {}", a.audio.display()))?;
            eprintln!("no words given: {}", talker.heard_by()?);
            performed.insert(p).target.clone()
        }
        (Some(words), None, Some(talker)) => align::segments(
            &talker
                .hear_words(talker.aligner()?, &a.audio, words, a.accept_mismatch)
                .with_context(|| format!("the speech {}", a.audio.display()))?,
        ),
        (words, _, _) => {
            let phones = align::Aligner::load_default(&[])?
                .hear(&speech.samples, speech.rate, words.as_deref(), a.accept_mismatch)
                .with_context(|| format!("the speech {}", a.audio.display()))?;
            if words.is_none() {
                eprintln!(
                    "no words given: phones recognised from the sound alone (about 1 in 3 right on GRID s1; give --text or --transcript for aligned phones)"
                );
            }
            align::segments(&phones)
        }
    };
    let mut cues = visemes::cues(&segments, speech.seconds(), extended)?;
    if let (Some(dir), Some(talker)) = (&a.talker, &talker) {
        let levels = visemes::face_levels(&talker.model, &talker.codebook).with_context(|| {
            format!(
                "{}: its codebook lacks /iy/, /eh/ or /aa/, or its face is not a 68-point one",
                dir.display()
            )
        })?;
        // With words or labels the talker performs from the same phones, written as labels.
        let p = match performed {
            Some(p) => p,
            None => perform(
                talker,
                facespace::talker::Speech::Phones {
                    phones: segments.clone(),
                    audio: None,
                },
            )?,
        };
        let frames = p.utterance.variants()[0].1.clone();
        let opening = visemes::openings(&talker.model, &frames);
        let fps = frames.fps();
        cues = visemes::open_by_face(&cues, levels, |s, e| {
            visemes::mean_opening(&opening, fps, s, e)
        });
    }
    let cues = visemes::hold(&cues, extended);
    let text = match a.format {
        Format::Tsv => visemes::tsv(&cues, extended),
        Format::Json => visemes::json(&cues, &a.audio.to_string_lossy()),
        Format::Dat => visemes::dat(&cues, a.dat_frame_rate, a.dat_preston_blair, extended)?,
    };
    match &a.output {
        Some(out) => atomic::write_file(out, text.as_bytes())
            .with_context(|| format!("writing {}", out.display()))?,
        None => print!("{text}"),
    }
    Ok(())
}
