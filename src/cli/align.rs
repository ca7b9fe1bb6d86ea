//! `facespace align`: a recording and its words → word and phone timings.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use facespace::align::{self, Aligner};
use facespace::audio;

#[derive(Args)]
pub struct AlignArgs {
    /// The recording: WAV, MP4/M4A (AAC), or any format a system ffmpeg reads.
    audio: PathBuf,
    /// The words spoken.
    #[arg(
        long,
        conflicts_with = "transcript",
        required_unless_present = "transcript"
    )]
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
}

pub fn run(a: AlignArgs) -> Result<()> {
    let mut inputs = vec![a.audio.as_path()];
    inputs.extend(a.transcript.as_deref());
    inputs.extend(a.dicts.iter().map(|d| d.as_path()));
    super::check_output(&a.output, &inputs)?;
    let text = match (&a.text, &a.transcript) {
        (Some(t), _) => t.clone(),
        (None, Some(p)) => facespace::manifest::read_regular_string(p)
            .with_context(|| format!("reading the transcript {}", p.display()))?,
        (None, None) => bail!("give the words with --text or --transcript"),
    };
    let started = Instant::now();
    let dir = a
        .acoustic_model
        .clone()
        .unwrap_or_else(align::default_model_dir);
    let aligner = Aligner::load(&dir, &a.dicts)?;
    let loaded = started.elapsed().as_secs_f64();
    let speech = audio::read(&a.audio, align::frontend::SAMPLE_RATE, align::MAX_SECONDS)?;
    let result = aligner
        .align(&speech.samples, speech.rate, &text)
        .with_context(|| format!("aligning {}", a.audio.display()))?;
    result
        .write(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    println!(
        "{} words, {} phones over {:.2} s → {} (model {:.0} ms, total {:.0} ms)",
        result.words.len(),
        result.phones.iter().filter(|p| p.word.is_some()).count(),
        speech.seconds(),
        a.output.display(),
        loaded * 1e3,
        started.elapsed().as_secs_f64() * 1e3
    );
    for w in &result.words {
        println!("  {:>7.2} {:>7.2}  {}", w.start, w.end, w.word);
    }
    Ok(())
}
