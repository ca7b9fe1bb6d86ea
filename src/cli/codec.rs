//! `facespace encode | decode | codec-report`: video through face-space (DESIGN §1, §9, §12).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::codec::{self, Clip, TrackingSummary};
use facespace::render::{Background, DEFAULT_FEATHER};
use facespace::video::{Sink, Source};

use super::{RendererArg, TrackingArgs, load_model, progress_bar, tracking_line};

#[derive(Args)]
pub struct EncodeArgs {
    /// The face model the video is tracked and encoded with.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// An MP4, Y4M, folder of frames, or any video a system ffmpeg reads.
    input: PathBuf,
    #[command(flatten)]
    tracking: TrackingArgs,
    /// Quantise the parameters to 8 or 16 bits per value (over each column's range).
    #[arg(long)]
    bits: Option<u32>,
    /// Frame rate of a frame folder (containers state their own).
    #[arg(long)]
    fps: Option<f64>,
    /// The clip folder to write (e.g. clip.fsp).
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct DecodeArgs {
    /// The face model the clip was encoded with.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// A clip folder written by `encode`.
    clip: PathBuf,
    /// Composite onto these frames (normally the original video) with a feathered edge.
    #[arg(long)]
    background: Option<PathBuf>,
    /// Width of the feathered edge, in reference-frame pixels.
    #[arg(long, default_value_t = DEFAULT_FEATHER)]
    feather: f64,
    /// Leave the clip's audio out.
    #[arg(long)]
    no_audio: bool,
    /// Which renderer draws the faces.
    #[arg(long, value_enum, default_value_t)]
    renderer: RendererArg,
    /// Output: .mp4, .y4m, a folder of PNGs (no extension), or what a system ffmpeg writes.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct ReportArgs {
    /// The face model the clip is encoded with.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// The video that was encoded.
    input: PathBuf,
    /// Its clip folder.
    clip: PathBuf,
    /// JSON report; a plot is written beside it (same name, .png).
    #[arg(short, long, default_value = "codec-report.json")]
    output: PathBuf,
}

pub fn encode(a: EncodeArgs) -> Result<()> {
    let mut inputs = vec![a.input.as_path(), a.model.as_path()];
    inputs.extend(a.tracking.init.as_deref());
    super::check_output(&a.output, &inputs)?;
    let model = load_model(&a.model)?;
    let options = a.tracking.options(a.bits)?;
    options.validate(&model)?;
    let mut source = Source::open(&a.input)?;
    if let Some(fps) = a.fps {
        source.set_fps(fps)?;
    }
    let (bar, progress) = progress_bar();
    let clock = std::time::Instant::now();
    let encoded = codec::encode(&model, source, &options, progress).map_err(|e| {
        super::tracking_context("encoding", &a.input, super::TRACKING_REMEDY)(e.into())
    })?;
    bar.finish_and_clear();
    let seconds = clock.elapsed().as_secs_f64();
    let clip = &encoded.clip;
    clip.save(&a.output, Some(&a.input))
        .with_context(|| format!("writing {}", a.output.display()))?;
    let frames = clip.frames.len().max(1) as f64;
    println!(
        "encoded {}",
        tracking_line(&TrackingSummary::of(&clip.tracking), seconds)
    );
    let (on_disk, input) = (
        Clip::disk_bytes(&a.output)? as f64 / frames,
        codec::score::input_bytes(&a.input)? as f64 / frames,
    );
    println!(
        "clip on disk {on_disk:.0} bytes/frame (parameter stream {:.0}: {} values{}; tracking record, manifests{}) vs input {input:.0} bytes/frame: {:.1}× smaller",
        clip.stream_bytes() as f64 / frames,
        clip.frames.layout().dims(),
        match (&clip.quantisation, encoded.quantisation_error_sd) {
            (Some(q), Some(e)) => format!(" at {} bits; max quantisation error {e:.2e} σ", q.bits),
            _ => " as float32".into(),
        },
        if clip.audio.is_some() { ", audio" } else { "" },
        input / on_disk,
    );
    if let Some(audio) = clip.audio_path(&a.output).filter(|p| p.is_file()) {
        println!("audio kept → {}", audio.display());
    }
    println!("→ {}", a.output.display());
    Ok(())
}

pub fn decode(a: DecodeArgs) -> Result<()> {
    // Checked even without --background: a nonsense value is an error, not silently unused.
    facespace::options::in_range("--feather", a.feather, 0.0, 1000.0)?;
    let mut inputs = vec![a.clip.as_path(), a.model.as_path()];
    inputs.extend(a.background.as_deref());
    super::check_output(&a.output, &inputs)?;
    facespace::video::check_destination(&a.output)?;
    let model = load_model(&a.model)?;
    let clip = Clip::load(&a.clip, &model)
        .with_context(|| format!("loading clip {}", a.clip.display()))?;
    let (background, feather) = match &a.background {
        Some(p) => (
            Background::Video(Box::new(Source::open(p)?)),
            Some(a.feather),
        ),
        None => (
            Background::Plain {
                width: clip.width,
                height: clip.height,
            },
            None,
        ),
    };
    let renderer = a.renderer.make(&model, feather)?;
    let audio = clip.audio_path(&a.clip).filter(|_| !a.no_audio);
    let fps = clip.frames.fps();
    let mut sink = Sink::create(&a.output, clip.width, clip.height, fps, audio.as_deref())?;
    if audio.is_some() && !sink.carries_audio() {
        eprintln!(
            "note: {} carries no sound; the clip's audio is left out",
            a.output.display()
        );
    }
    let (bar, progress) = progress_bar();
    bar.set_prefix(format!("{} · ", renderer.describe()));
    let clock = std::time::Instant::now();
    codec::decode(renderer.as_ref(), &clip, background, &mut sink, progress)
        .with_context(|| format!("decoding {}", a.clip.display()))?;
    let frames = sink.finish()?;
    bar.finish_and_clear();
    let seconds = clock.elapsed().as_secs_f64();
    println!(
        "decoded {frames} frames in {seconds:.2} s ({:.0} fps, {}) → {}",
        frames as f64 / seconds,
        renderer.describe(),
        a.output.display()
    );
    Ok(())
}

pub fn report(a: ReportArgs) -> Result<()> {
    let inputs = [a.input.as_path(), a.clip.as_path(), a.model.as_path()];
    super::check_output(&a.output, &inputs)?;
    super::check_output(&a.output.with_extension("png"), &inputs)?;
    let model = load_model(&a.model)?;
    let clip = Clip::load(&a.clip, &model)
        .with_context(|| format!("loading clip {}", a.clip.display()))?;
    let (bar, progress) = progress_bar();
    let report = codec::score::score(&model, &a.input, &clip, &a.clip, progress)?;
    bar.finish_and_clear();
    report
        .write(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    println!(
        "{} frames: PSNR mean {:.2} dB (min {:.2}), SSIM mean {:.4} (min {:.4}) inside the face; the clip on disk {:.0} bytes/frame ({:.0} of them parameters) vs {:.0} of input ({:.1}× smaller) → {}, {}",
        report.frames,
        report.psnr.mean,
        report.psnr.min,
        report.ssim.mean,
        report.ssim.min,
        report.clip_bytes_per_frame,
        report.params_bytes_per_frame,
        report.input_bytes_per_frame,
        report.compression_ratio,
        a.output.display(),
        a.output.with_extension("png").display()
    );
    Ok(())
}
