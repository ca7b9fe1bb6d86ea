//! `facespace say`: a talker speaks text, a recording or phone labels → one MP4 with sound.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::talker::{SayRequest, Talker};

use super::{RendererArg, progress_bar};

/// The committed default talker (GRID s1).
pub const DEFAULT_TALKER: &str = "models/grid";

#[derive(Args)]
#[command(
    after_help = "Example: facespace say \"Please call me tomorrow morning about the shipment.\" -o out/say.mp4\n    also: facespace say --audio models/grid/demo/bbbf9a.mp4 --transcript models/grid/demo/bbbf9a.txt -o out/bbbf9a.mp4"
)]
pub struct SayArgs {
    /// Text to speak (text-to-speech in the talker's voice); with --audio, the words of that
    /// recording.
    text: Option<String>,
    /// The talker folder (`talker build`; default: GRID s1, models/grid).
    #[arg(long, default_value = DEFAULT_TALKER, value_parser = super::committed_path)]
    talker: PathBuf,
    /// A recording to speak instead of text-to-speech (WAV or MP4/M4A): aligned to its words
    /// (the text, or --transcript) and put under the video; without words its phones are
    /// recognised from the sound alone (a looser lip sync, with a note).
    #[arg(long)]
    audio: Option<PathBuf>,
    /// A text file with the words of --audio.
    #[arg(long, requires = "audio", conflicts_with_all = ["text", "labels"])]
    transcript: Option<PathBuf>,
    /// Phone timings (.lab, .TextGrid, .tsv) instead of text; with --audio, that sound goes
    /// under the video.
    #[arg(long, conflicts_with = "text")]
    labels: Option<PathBuf>,
    /// TextGrid tier of --labels.
    #[arg(long, requires = "labels")]
    tier: Option<String>,
    /// Two-column file mapping another phone set's labels (of --labels) to ARPAbet.
    #[arg(long, requires = "labels")]
    phone_map: Option<PathBuf>,
    /// A Festival voice instead of the talker's (e.g. cmu_us_slt_arctic_hts, kal_diphone).
    #[arg(long)]
    voice: Option<String>,
    /// Extra pronunciations for the aligner (`WORD  P H O N E S` lines); may repeat.
    #[arg(long = "dict")]
    dicts: Vec<PathBuf>,
    /// Use the words of --audio even when they do not seem to be what is said (by default
    /// such a request is refused, naming the worst words).
    #[arg(long)]
    accept_mismatch: bool,
    /// Draw the appearance model's mouth even when the talker keeps recorded mouths (for A/B
    /// comparisons; `talker mouths` keeps them).
    #[arg(long)]
    model_mouth: bool,
    /// Which of the living frames that join best (they open on different takes).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Also write the folder of parts here: trajectory, frames, plot, report.
    #[arg(long)]
    parts: Option<PathBuf>,
    /// Which renderer draws.
    #[arg(long, value_enum, default_value_t)]
    renderer: RendererArg,
    /// The video to write (MP4).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: SayArgs) -> Result<()> {
    let mut inputs = vec![a.talker.as_path()];
    for p in [&a.audio, &a.transcript, &a.labels, &a.phone_map] {
        inputs.extend(p.as_deref());
    }
    inputs.extend(a.dicts.iter().map(|d| d.as_path()));
    super::check_output(&a.output, &inputs)?;
    if let Some(parts) = &a.parts {
        super::check_output(parts, &inputs)?;
    }
    let speech = super::speech_of(
        a.labels.as_deref(),
        a.tier.as_deref(),
        a.phone_map.as_deref(),
        a.audio.as_deref(),
        a.text.as_deref(),
        a.transcript.as_deref(),
    )?
    .context("say what? give text, --audio with its words, or --labels")?;
    let clock = std::time::Instant::now();
    let talker = Talker::load(&a.talker)
        .with_context(|| format!("loading the talker {}", super::shown(&a.talker)))?;
    let loaded = clock.elapsed().as_secs_f64();
    let request = SayRequest {
        voice: a.voice.clone(),
        dicts: a.dicts.clone(),
        renderer: a.renderer.choice(),
        seed: a.seed,
        parts: a.parts.clone(),
        accept_mismatch: a.accept_mismatch,
        model_mouth: a.model_mouth,
        ..SayRequest::new(speech)
    };
    let (bar, progress) = progress_bar();
    let r = talker
        .say(&request, &a.output, progress)
        .with_context(|| format!("{} saying it", talker.manifest.name))?;
    bar.finish_and_clear();
    for note in &r.notes {
        println!("note: {note}");
    }
    let joins = if r.joins.is_empty() {
        "one stretch of footage".to_owned()
    } else {
        let worst = r.join_costs.iter().copied().fold(0f32, f32::max);
        let at: Vec<String> = r.joins.iter().map(|j| j.to_string()).collect();
        format!(
            "footage joined at frames {} (worst {:.2}× the footage's median step)",
            at.join(", "),
            worst / r.median_step.max(1e-6)
        )
    };
    println!(
        "{}: {} phones, {} frames at {} fps, {}×{}{} ({}; {joins}; {}) in {:.1} s (talker loaded in {:.2} s)",
        talker.manifest.name,
        r.phones,
        r.frames,
        r.fps,
        r.size.0,
        r.size.1,
        if r.sound { ", with sound" } else { ", silent" },
        r.method,
        r.renderer,
        clock.elapsed().as_secs_f64(),
        loaded
    );
    println!("wrote {}", a.output.display());
    if let Some(p) = &a.parts {
        println!("parts in {}", p.display());
    }
    Ok(())
}
