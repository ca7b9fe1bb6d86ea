//! `facespace synth` (blend synthesis, smoothing A/B) and `facespace eval`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use facespace::codebook::{Codebook, Layout};
use facespace::eval::{self, Scores};
use facespace::model::FaceModel;
use facespace::phonemes::{self, PhoneMap, Segment};
use facespace::render::{Compositor, DEFAULT_FEATHER, Renderer, plain_background};
use facespace::rng::Rng;
use facespace::synth::blend::{self, BlendOptions, Synthesis};
use facespace::synth::smooth::SmoothingSpline;
use facespace::{atomic, npy, plot, video};
use image::RgbImage;

/// Default smoothing weight λ (seconds³ per parameter unit²): chosen on the demo held-out
/// sentences with `facespace eval --lambda-grid` (see BENCHMARKS.md).
pub const DEFAULT_LAMBDA: f64 = 1e-5;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Smooth {
    On,
    Off,
    /// Both, plus a blind side-by-side and a comparison plot.
    Ab,
}

#[derive(Args)]
pub struct SynthArgs {
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model"))]
    pub model: PathBuf,
    #[arg(long)]
    pub codebook: PathBuf,
    /// Phone timings (.lab, .TextGrid, .tsv).
    #[arg(long, conflicts_with = "text", required_unless_present = "text")]
    pub labels: Option<PathBuf>,
    /// Text to speak (CMU dictionary; durations from the codebook).
    #[arg(long)]
    pub text: Option<String>,
    #[arg(long)]
    pub tier: Option<String>,
    #[arg(long)]
    pub phone_map: Option<PathBuf>,
    /// Context width C.
    #[arg(long, default_value_t = 1)]
    pub context: usize,
    /// Examples blended per phone, N.
    #[arg(long, default_value_t = 3)]
    pub top_n: usize,
    #[arg(long, value_enum, default_value_t = Smooth::On)]
    pub smooth: Smooth,
    /// Smoothing weight λ of the cubic smoothing spline.
    #[arg(long, default_value_t = DEFAULT_LAMBDA)]
    pub smoothing: f64,
    #[arg(long, default_value_t = 25.0)]
    pub fps: f64,
    /// Background frame to draw the face on (default: plain grey).
    #[arg(long)]
    pub background: Option<PathBuf>,
    /// A real trajectory (.npy) of the same utterance, plotted against the synthesis.
    #[arg(long)]
    pub real: Option<PathBuf>,
    /// Seed of the blind A/B order.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Sound to mux into the MP4s: an MP4/M4A with AAC as is, or (with a system ffmpeg) any
    /// audio file, e.g. WAV.
    #[arg(long)]
    pub audio: Option<PathBuf>,
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn load_pair(model: &Path, codebook: &Path) -> Result<(FaceModel, Codebook)> {
    let m = FaceModel::load(model).with_context(|| format!("loading model {}", model.display()))?;
    let cb = Codebook::load(codebook)
        .with_context(|| format!("loading codebook {}", codebook.display()))?;
    if let Some(h) = &cb.model_hash
        && *h != m.hash()
    {
        bail!(
            "codebook {} was built with model {h}, but {} is model {}",
            codebook.display(),
            model.display(),
            m.hash()
        );
    }
    if cb.layout != Layout::of(&m) {
        bail!(
            "codebook layout {:?} does not match the model's {:?}",
            cb.layout,
            Layout::of(&m)
        );
    }
    Ok((m, cb))
}

/// Smooths every dimension of a synthesis with the cubic smoothing spline.
pub fn smoothed(s: &Synthesis, lambda: f64) -> Result<Vec<f64>> {
    let mut frames = s.frames.clone();
    if s.n_frames() >= 3 {
        SmoothingSpline::new(&s.times(), None, lambda)?.smooth_rows(&mut frames, s.dims)?;
    }
    Ok(frames)
}

/// Writes `dir/stem.mp4` (H.264, with `audio` muxed), or `stem.y4m` when a frame side is odd.
pub fn write_video(
    dir: &Path,
    stem: &str,
    frames: &[RgbImage],
    fps: f64,
    audio: Option<&Path>,
) -> Result<PathBuf> {
    let (w, h) = frames.first().map_or((0, 0), |f| f.dimensions());
    let path = dir.join(if w % 2 == 0 && h % 2 == 0 {
        format!("{stem}.mp4")
    } else {
        format!("{stem}.y4m")
    });
    let mut sink = video::Sink::create(&path, w, h, fps, audio)?;
    for f in frames {
        sink.write(f)?;
    }
    sink.finish()?;
    Ok(path)
}

/// Writes one variant: trajectory.npy, landmarks.npy, frames/, video.mp4. Returns the frames.
pub fn write_variant(
    dir: &Path,
    model: &FaceModel,
    layout: &Layout,
    frames: &[f64],
    fps: f64,
    background: &RgbImage,
    audio: Option<&Path>,
) -> Result<Vec<RgbImage>> {
    let dims = layout.dims();
    let n = frames.len() / dims;
    let f32s: Vec<f32> = frames.iter().map(|&v| v as f32).collect();
    npy::write(&dir.join("trajectory.npy"), &[n, dims], &f32s)?;
    let lm = eval::landmarks(model, frames, layout);
    let flat: Vec<f32> = lm
        .iter()
        .flatten()
        .flat_map(|p| [p[0] as f32, p[1] as f32])
        .collect();
    npy::write(
        &dir.join("landmarks.npy"),
        &[n, model.shape.n_landmarks(), 2],
        &flat,
    )?;
    // Feathered onto the background, so no seam shows where the face meets it.
    let images = Compositor::new(model, DEFAULT_FEATHER).render(model, frames, background)?;
    video::write_png_frames(&dir.join("frames"), &images)?;
    write_video(dir, "video", &images, fps, audio)?;
    Ok(images)
}

/// First shape and first appearance parameter of each series over time, with the phones.
pub fn parameter_plot(
    layout: &Layout,
    fps: f64,
    series: &[(&str, &[f64])],
    target: &[Segment],
) -> RgbImage {
    let dims = layout.dims();
    let spans: Vec<(f64, f64, &str)> = target
        .iter()
        .map(|s| (s.start, s.end, s.phone.name()))
        .collect();
    let mut panels = Vec::new();
    for (title, k) in [
        ("first shape parameter", layout.pose),
        ("first appearance parameter", layout.pose + layout.shape),
    ] {
        let cols: Vec<(Vec<f64>, Vec<f64>)> = series
            .iter()
            .map(|(_, m)| {
                let rows: Vec<&[f64]> = m.chunks_exact(dims).collect();
                (
                    (0..rows.len()).map(|i| i as f64 / fps).collect(),
                    rows.iter().map(|r| r[k]).collect(),
                )
            })
            .collect();
        let s: Vec<plot::Series> = series
            .iter()
            .zip(&cols)
            .enumerate()
            .map(|(i, ((label, _), (x, y)))| plot::Series {
                label,
                x,
                y,
                color: plot::PALETTE[i % plot::PALETTE.len()],
            })
            .collect();
        panels.push(plot::line_plot(title, "time (s)", &s, &spans, 900, 260));
    }
    let mut out = RgbImage::new(900, 520);
    image::imageops::replace(&mut out, &panels[0], 0, 0);
    image::imageops::replace(&mut out, &panels[1], 0, 260);
    out
}

/// The two variants of one synthesis, for an A/B comparison.
pub struct Ab<'a> {
    pub smoothed: &'a [f64],
    pub unsmoothed: &'a [f64],
    /// The real trajectory, when the target is a recorded sentence.
    pub real: Option<&'a [f64]>,
    pub target: &'a [Segment],
    pub fps: f64,
    /// Seed of the blind order.
    pub seed: u64,
    /// Sound muxed into every MP4.
    pub audio: Option<&'a Path>,
}

/// Writes both variants (`smoothed/`, `unsmoothed/`), a blind `side_by_side.mp4` whose order
/// a seeded coin decides, its `key.json`, and `plot.png` of both (and of the real
/// trajectory). Returns the key.
pub fn write_ab(
    dir: &Path,
    model: &FaceModel,
    layout: &Layout,
    ab: &Ab,
    background: &RgbImage,
) -> Result<serde_json::Value> {
    let sm = write_variant(
        &dir.join("smoothed"),
        model,
        layout,
        ab.smoothed,
        ab.fps,
        background,
        ab.audio,
    )?;
    let un = write_variant(
        &dir.join("unsmoothed"),
        model,
        layout,
        ab.unsmoothed,
        ab.fps,
        background,
        ab.audio,
    )?;
    let smoothed_left = Rng::new(ab.seed).uniform() < 0.5;
    let (l, r) = if smoothed_left {
        (&sm, &un)
    } else {
        (&un, &sm)
    };
    write_video(
        dir,
        "side_by_side",
        &video::side_by_side(l, r),
        ab.fps,
        ab.audio,
    )?;
    let (left, right) = if smoothed_left {
        ("smoothed", "unsmoothed")
    } else {
        ("unsmoothed", "smoothed")
    };
    let key = serde_json::json!({ "left": left, "right": right, "seed": ab.seed });
    atomic::write_file(
        &dir.join("key.json"),
        serde_json::to_string_pretty(&key)?.as_bytes(),
    )?;
    let mut series = vec![("smoothed", ab.smoothed), ("unsmoothed", ab.unsmoothed)];
    if let Some(r) = ab.real {
        series.push(("real", r));
    }
    super::model::save_png(
        &parameter_plot(layout, ab.fps, &series, ab.target),
        &dir.join("plot.png"),
    )?;
    Ok(key)
}

pub fn target_segments(
    cb: &Codebook,
    labels: Option<&Path>,
    text: Option<&str>,
    tier: Option<&str>,
    map: Option<&Path>,
) -> Result<Vec<Segment>> {
    match (labels, text) {
        (Some(path), _) => {
            let map = match map {
                Some(p) => PhoneMap::read(p)?,
                None => PhoneMap::default(),
            };
            Ok(phonemes::read_labels(path, tier, &map)?)
        }
        (None, Some(text)) => Ok(phonemes::text_to_segments(text, &cb.mean_durations())?),
        (None, None) => bail!("give --labels or --text"),
    }
}

pub fn synth(a: SynthArgs) -> Result<()> {
    let (model, cb) = load_pair(&a.model, &a.codebook)?;
    let target = target_segments(
        &cb,
        a.labels.as_deref(),
        a.text.as_deref(),
        a.tier.as_deref(),
        a.phone_map.as_deref(),
    )?;
    let options = BlendOptions {
        context: a.context,
        top_n: a.top_n,
        fps: a.fps,
    };
    let start = std::time::Instant::now();
    let s = blend::blend(&cb, &target, &options)?;
    let smooth = smoothed(&s, a.smoothing)?;
    let synth_ms = start.elapsed().as_secs_f64() * 1e3;
    let layout = cb.layout;
    let background = match &a.background {
        Some(p) => image::open(p)
            .with_context(|| format!("reading background {}", p.display()))?
            .to_rgb8(),
        None => plain_background(&model, &s.frames),
    };
    let real = match &a.real {
        Some(p) => Some(
            npy::read::<f32>(p)?
                .data
                .iter()
                .map(|&v| v as f64)
                .collect::<Vec<f64>>(),
        ),
        None => None,
    };
    let mut report = serde_json::json!({
        "options": options, "smooth": format!("{:?}", a.smooth).to_lowercase(), "smoothing_lambda": a.smoothing,
        "frames": s.n_frames(), "synthesis_ms": synth_ms, "phones": s.phones, "warnings": s.warnings,
    });
    match a.smooth {
        Smooth::On | Smooth::Off => {
            let frames = if a.smooth == Smooth::On {
                &smooth
            } else {
                &s.frames
            };
            write_variant(
                &a.output,
                &model,
                &layout,
                frames,
                a.fps,
                &background,
                a.audio.as_deref(),
            )?;
            let mut series = vec![(
                if a.smooth == Smooth::On {
                    "smoothed"
                } else {
                    "unsmoothed"
                },
                frames.as_slice(),
            )];
            if let Some(r) = &real {
                series.push(("real", r));
            }
            super::model::save_png(
                &parameter_plot(&layout, a.fps, &series, &target),
                &a.output.join("plot.png"),
            )?;
        }
        Smooth::Ab => {
            let ab = Ab {
                smoothed: &smooth,
                unsmoothed: &s.frames,
                real: real.as_deref(),
                target: &target,
                fps: a.fps,
                seed: a.seed,
                audio: a.audio.as_deref(),
            };
            report["ab_key"] = write_ab(&a.output, &model, &layout, &ab, &background)?;
        }
    }
    atomic::write_file(
        &a.output.join("report.json"),
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )?;
    println!(
        "synthesised {} phones, {} frames at {} fps in {synth_ms:.1} ms → {}",
        target.len(),
        s.n_frames(),
        a.fps,
        a.output.display()
    );
    for w in &s.warnings {
        println!("  warning: {w}");
    }
    Ok(())
}

#[derive(Args)]
pub struct EvalArgs {
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model"))]
    pub model: PathBuf,
    #[arg(long)]
    pub codebook: PathBuf,
    /// Held-out sentences: NAME.npy (real trajectory) with NAME.lab.
    #[arg(long)]
    pub heldout: PathBuf,
    #[arg(long, default_value_t = DEFAULT_LAMBDA)]
    pub smoothing: f64,
    /// Also report blend + smoothing over a grid of λ.
    #[arg(long)]
    pub lambda_grid: bool,
    /// Write the table as JSON here.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// Mean scores of one system over the held-out sentences.
fn mean(scores: &[Scores]) -> Scores {
    let n = scores.len() as f64;
    let avg = |f: fn(&Scores) -> f64| scores.iter().map(f).sum::<f64>() / n;
    Scores {
        r_pca: avg(|s| s.r_pca),
        r_h: avg(|s| s.r_h),
        rmse_px: avg(|s| s.rmse_px),
        dtw: avg(|s| s.dtw),
        mouth_sd_px: avg(|s| s.mouth_sd_px),
    }
}

pub fn evaluate(a: EvalArgs) -> Result<()> {
    let (model, cb) = load_pair(&a.model, &a.codebook)?;
    let sentences =
        facespace::codebook::load_corpus(&a.heldout, cb.fps, cb.dims(), None, &PhoneMap::default())
            .with_context(|| format!("reading held-out sentences {}", a.heldout.display()))?;
    let fps = cb.fps;
    type System = (String, BlendOptions, Option<f64>);
    let blend_opts = BlendOptions {
        context: 1,
        top_n: 3,
        fps,
    };
    let mut systems: Vec<System> = vec![
        (
            format!("blend C=1 N=3, smoothed λ={}", a.smoothing),
            blend_opts,
            Some(a.smoothing),
        ),
        ("blend C=1 N=3, unsmoothed".into(), blend_opts, None),
        (
            "baseline: N=1, unsmoothed".into(),
            BlendOptions {
                top_n: 1,
                ..blend_opts
            },
            None,
        ),
        (
            "baseline: per-phoneme mean".into(),
            BlendOptions {
                context: 0,
                top_n: usize::MAX,
                fps,
            },
            None,
        ),
    ];
    if a.lambda_grid {
        for l in [1e-6, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 1e-2] {
            systems.push((format!("blend C=1 N=3, λ={l:e}"), blend_opts, Some(l)));
        }
    }
    let real: Vec<Vec<f64>> = sentences
        .iter()
        .map(|s| s.frames.iter().map(|&v| v as f64).collect())
        .collect();
    println!(
        "{} held-out sentences; mean over sentences",
        sentences.len()
    );
    println!(
        "{:<36} {:>7} {:>7} {:>9} {:>8} {:>12}",
        "system", "r_pca", "r_h", "RMSE px", "DTW", "mouth sd px"
    );
    let real_sd = mean(
        &real
            .iter()
            .map(|r| eval::score(&model, &cb.layout, r, r))
            .collect::<Vec<_>>(),
    )
    .mouth_sd_px;
    let mut table = Vec::new();
    for (name, opts, lambda) in &systems {
        let mut scores = Vec::new();
        for (s, r) in sentences.iter().zip(&real) {
            let syn = blend::blend(&cb, &s.segments, opts)?;
            let frames = match lambda {
                Some(l) => smoothed(&syn, *l)?,
                None => syn.frames.clone(),
            };
            scores.push(eval::score(&model, &cb.layout, &frames, r));
        }
        let m = mean(&scores);
        println!(
            "{name:<36} {:>7.3} {:>7.3} {:>9.3} {:>8.3} {:>12.3}",
            m.r_pca, m.r_h, m.rmse_px, m.dtw, m.mouth_sd_px
        );
        table.push(serde_json::json!({ "system": name, "mean": m, "per_sentence": scores }));
    }
    println!(
        "{:<36} {:>7} {:>7} {:>9} {:>8} {:>12.3}",
        "real (reference)", "", "", "", "", real_sd
    );
    if let Some(out) = &a.output {
        atomic::write_file(out, serde_json::to_string_pretty(&table)?.as_bytes())?;
    }
    Ok(())
}
