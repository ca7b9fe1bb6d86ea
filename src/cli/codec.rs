//! `facespace encode | decode | codec-report`: video through face-space (DESIGN §1, §9, §11).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use facespace::codec::{self, Background, Clip};
use facespace::model::FaceModel;
use facespace::render::{Compositor, DEFAULT_FEATHER};
use facespace::video::{Sink, Source};
use facespace::{eval, plot, video};
use image::{Rgb, RgbImage};
use rayon::prelude::*;
use serde::Serialize;

use super::track::{TrackingArgs, summary};

const DEFAULT_MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model");

#[derive(Args)]
pub struct EncodeArgs {
    #[arg(long, default_value = DEFAULT_MODEL)]
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
    #[arg(long, default_value = DEFAULT_MODEL)]
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
    /// Output: .mp4, .y4m, a folder of PNGs (no extension), or what a system ffmpeg writes.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct ReportArgs {
    #[arg(long, default_value = DEFAULT_MODEL)]
    model: PathBuf,
    /// The video that was encoded.
    input: PathBuf,
    /// Its clip folder.
    clip: PathBuf,
    /// JSON report; a plot is written beside it (same name, .png).
    #[arg(short, long, default_value = "codec-report.json")]
    output: PathBuf,
}

fn load_model(path: &Path) -> Result<FaceModel> {
    FaceModel::load(path).with_context(|| format!("loading model {}", path.display()))
}

/// Bytes per frame of the input: its file size, or a frame folder's total.
fn input_bytes(input: &Path) -> Result<u64> {
    Ok(if input.is_dir() {
        video::frame_files(input)?
            .iter()
            .map(|f| f.metadata().map(|m| m.len()).unwrap_or(0))
            .sum()
    } else {
        input
            .metadata()
            .with_context(|| format!("reading {}", input.display()))?
            .len()
    })
}

pub fn encode(a: EncodeArgs) -> Result<()> {
    let model = load_model(&a.model)?;
    let options = a.tracking.options(&model)?;
    let mut source = Source::open(&a.input)?;
    if let Some(fps) = a.fps {
        if !(fps.is_finite() && fps > 0.0) {
            bail!("--fps {fps}: must be positive");
        }
        source.set_fps(fps);
    }
    let (bar, progress) = super::progress_bar();
    let clock = std::time::Instant::now();
    let mut clip = codec::encode(&model, source, &options, progress)
        .with_context(|| format!("encoding {}", a.input.display()))?;
    bar.finish_and_clear();
    let seconds = clock.elapsed().as_secs_f64();
    let exact = clip.clone();
    if let Some(bits) = a.bits {
        clip = clip.quantised(bits)?;
    }
    clip.save(&a.output, Some(&a.input))
        .with_context(|| format!("writing {}", a.output.display()))?;
    let frames = clip.meta.frames.max(1) as f64;
    println!("encoded {}", summary(&clip.meta.tracking, seconds));
    println!(
        "parameter stream {:.0} bytes/frame ({} values{}) vs input {:.0} bytes/frame",
        clip.stream_bytes() as f64 / frames,
        clip.dims(),
        match a.bits {
            Some(b) => format!(
                " at {b} bits; max quantisation error {:.2e} σ",
                max_error_sd(&model, &exact, &clip)
            ),
            None => " as float32".into(),
        },
        input_bytes(&a.input)? as f64 / frames,
    );
    if a.output.join("audio.m4a").is_file() {
        println!("audio kept → {}", a.output.join("audio.m4a").display());
    }
    println!("→ {}", a.output.display());
    Ok(())
}

/// Largest difference between two clips' shape/appearance parameters, in standard deviations.
pub fn max_error_sd(model: &FaceModel, a: &Clip, b: &Clip) -> f64 {
    let sd = model.standard_deviations();
    let dims = a.dims();
    a.params
        .iter()
        .zip(&b.params)
        .enumerate()
        .filter(|(i, _)| i % dims >= 4)
        .map(|(i, (x, y))| ((x - y) as f64).abs() / sd[i % dims - 4])
        .fold(0.0, f64::max)
}

pub fn decode(a: DecodeArgs) -> Result<()> {
    let model = load_model(&a.model)?;
    let clip = Clip::load(&a.clip, &model)
        .with_context(|| format!("loading clip {}", a.clip.display()))?;
    let background = match &a.background {
        Some(p) => Background::Frames(
            Box::new(Source::open(p)?),
            Compositor::new(&model, a.feather),
        ),
        None => Background::Plain,
    };
    let audio = clip.audio_path(&a.clip).filter(|_| !a.no_audio);
    let m = &clip.meta;
    let mut sink = Sink::create(&a.output, m.width, m.height, m.fps, audio.as_deref())?;
    if audio.is_some() && !sink.carries_audio() {
        eprintln!(
            "note: {} carries no sound; the clip's audio is left out",
            a.output.display()
        );
    }
    let (bar, progress) = super::progress_bar();
    let clock = std::time::Instant::now();
    codec::decode(&model, &clip, background, &mut sink, progress)
        .with_context(|| format!("decoding {}", a.clip.display()))?;
    let frames = sink.finish()?;
    bar.finish_and_clear();
    let seconds = clock.elapsed().as_secs_f64();
    println!(
        "decoded {frames} frames in {seconds:.2} s ({:.0} fps) → {}",
        frames as f64 / seconds,
        a.output.display()
    );
    Ok(())
}

#[derive(Serialize)]
struct Stat {
    mean: f64,
    min: f64,
    per_frame: Vec<f64>,
}

impl Stat {
    fn of(values: Vec<f64>) -> Self {
        Stat {
            mean: values.iter().sum::<f64>() / values.len().max(1) as f64,
            min: values.iter().cloned().fold(f64::INFINITY, f64::min),
            per_frame: values,
        }
    }
}

#[derive(Serialize)]
struct Report {
    input: String,
    clip: String,
    frames: usize,
    width: u32,
    height: u32,
    /// PSNR (dB) inside the face mask, decoded face (no compositing) against the input.
    psnr: Stat,
    /// SSIM inside the face mask (scikit-image conventions).
    ssim: Stat,
    params_bytes_per_frame: f64,
    input_bytes_per_frame: f64,
    compression_ratio: f64,
}

pub fn report(a: ReportArgs) -> Result<()> {
    let model = load_model(&a.model)?;
    let clip = Clip::load(&a.clip, &model)
        .with_context(|| format!("loading clip {}", a.clip.display()))?;
    let mut source = Source::open(&a.input)?;
    let (w, h) = (clip.meta.width, clip.meta.height);
    if (source.info().width, source.info().height) != (w, h) {
        bail!(
            "{} is {}×{}, the clip {w}×{h}",
            a.input.display(),
            source.info().width,
            source.info().height
        );
    }
    let (bar, mut progress) = super::progress_bar();
    let (mut psnr, mut ssim) = (Vec::new(), Vec::new());
    let n = clip.meta.frames;
    while psnr.len() < n {
        let batch: Vec<RgbImage> = (0..64.min(n - psnr.len()))
            .map(|_| {
                source.next_frame()?.with_context(|| {
                    format!("{} has fewer frames than the clip", a.input.display())
                })
            })
            .collect::<Result<_>>()?;
        let start = psnr.len();
        let scores: Vec<(f64, f64)> = batch
            .par_iter()
            .enumerate()
            .map(|(k, input)| {
                let params = model.params_from_vector(clip.frame(start + k))?;
                let mut decoded = RgbImage::from_pixel(w, h, Rgb([0, 0, 0]));
                let r = model.render_into(&params, &mut decoded)?;
                let mask = eval::face_mask(&model, &r.landmarks.points, w, h);
                Ok((
                    eval::psnr_masked(input, &decoded, &mask),
                    eval::ssim_masked(input, &decoded, &mask),
                ))
            })
            .collect::<Result<_>>()?;
        for (p, s) in scores {
            psnr.push(p);
            ssim.push(s);
        }
        progress(facespace::Progress {
            stage: "scoring",
            done: psnr.len(),
            total: n,
        });
    }
    bar.finish_and_clear();
    let frames = n.max(1) as f64;
    let (params_bpf, input_bpf) = (
        clip.stream_bytes() as f64 / frames,
        input_bytes(&a.input)? as f64 / frames,
    );
    let report = Report {
        input: a.input.display().to_string(),
        clip: a.clip.display().to_string(),
        frames: n,
        width: w,
        height: h,
        psnr: Stat::of(psnr),
        ssim: Stat::of(ssim),
        params_bytes_per_frame: params_bpf,
        input_bytes_per_frame: input_bpf,
        compression_ratio: input_bpf / params_bpf,
    };
    facespace::atomic::write_file(&a.output, &serde_json::to_vec_pretty(&report)?)
        .with_context(|| format!("writing {}", a.output.display()))?;
    let png = a.output.with_extension("png");
    video::write_png(&png, &report_plot(&report, clip.meta.fps))?;
    println!(
        "{n} frames: PSNR mean {:.2} dB (min {:.2}), SSIM mean {:.4} (min {:.4}) inside the face; {params_bpf:.0} bytes/frame of parameters vs {input_bpf:.0} of input ({:.1}×) → {}, {}",
        report.psnr.mean,
        report.psnr.min,
        report.ssim.mean,
        report.ssim.min,
        report.compression_ratio,
        a.output.display(),
        png.display()
    );
    Ok(())
}

fn report_plot(r: &Report, fps: f64) -> RgbImage {
    let t: Vec<f64> = (0..r.frames).map(|i| i as f64 / fps).collect();
    let panel = |title: &str, label: &str, y: &[f64], i: usize| {
        plot::line_plot(
            title,
            "time (s)",
            &[plot::Series {
                label,
                x: &t,
                y,
                color: plot::PALETTE[i],
            }],
            &[],
            900,
            260,
        )
    };
    let mut out = RgbImage::new(900, 520);
    let top = panel(
        "PSNR inside the face mask",
        "PSNR (dB)",
        &r.psnr.per_frame,
        0,
    );
    let bottom = panel("SSIM inside the face mask", "SSIM", &r.ssim.per_frame, 1);
    image::imageops::replace(&mut out, &top, 0, 0);
    image::imageops::replace(&mut out, &bottom, 0, 260);
    out
}
