//! Writing an utterance: for each variant `trajectory.npy` (frames × face-space),
//! `landmarks.npy` (frames × landmarks × 2), `frames/` (PNG) and `video.mp4` (`.y4m` when a
//! side is odd); for an A/B comparison both variants in `smoothed/` and `unsmoothed/`, a blind
//! `side_by_side.mp4` whose order a seeded coin decides, and its `key.json`; on request
//! `beside_background.mp4`, the background as recorded (left) beside the synthesis drawn on
//! it (right, the smoothed variant when there is one); then `plot.png`, `report.json` and
//! `utterance.lab` (the target phone timings, HTK). Frames are rendered and written batch by batch (memory does not grow
//! with the utterance).

use std::path::{Path, PathBuf};

use image::RgbImage;
use ndarray::Array3;
use serde::Serialize;
use thiserror::Error;

use super::{PhoneReport, Smoothing, Utterance};
use crate::facespace::Frames;
use crate::model::ModelError;
use crate::npy::{self, NpyError};
use crate::render::{Background, RenderError, Renderer, pipeline};
use crate::rng::Rng;
use crate::video::{self, Sink, VideoError};
use crate::{Progress, atomic, plot};

/// What can go wrong writing an utterance.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum OutputError {
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// A video or image could not be written.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// An array could not be written.
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// Frames that do not fit the renderer's model.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The phone timings could not be written.
    #[error(transparent)]
    Labels(#[from] crate::phonemes::PhonemeError),
    /// Sound far longer than the video it would go under (labels of 3 s over an hour's
    /// recording), or sound that cannot be read.
    #[error(
        "{path}: {reason}; the sound must be the utterance's own (labels of the whole recording, or the recording cut to them)"
    )]
    Sound {
        /// The sound file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// Seconds the sound may outlast the video before it is refused: 5 s and a fifth of the
/// video (trailing silence after the last labelled phone), never an hour under 3 s.
pub fn max_sound_seconds(video_seconds: f64) -> f64 {
    video_seconds * 1.2 + 5.0
}

/// Refuses sound that lasts longer than [`max_sound_seconds`] of a video of `video_seconds`,
/// from its header where it tells and otherwise without holding its samples (bounded memory).
pub fn check_sound(path: &Path, video_seconds: f64) -> Result<(), OutputError> {
    let max = max_sound_seconds(video_seconds);
    let reason = |e: crate::audio::AudioError| match e {
        crate::audio::AudioError::TooLong { seconds, .. } => format!(
            "the sound lasts at least {seconds:.1} s, the video {video_seconds:.1} s (at most {max:.1} s of sound is taken)"
        ),
        e => e.to_string(),
    };
    crate::audio::duration(path, max)
        .map(|_| ())
        .map_err(|e| OutputError::Sound {
            path: path.into(),
            reason: reason(e),
        })
}

/// Options of [`write()`].
#[derive(Clone, Copy, Debug, Default)]
pub struct OutputOptions<'a> {
    /// Sound muxed into every MP4.
    pub audio: Option<&'a Path>,
    /// Seed of the blind A/B order.
    pub seed: u64,
    /// The real trajectory of the same utterance, drawn in the plot.
    pub real: Option<&'a Frames>,
    /// The text spoken, recorded in the report.
    pub text: Option<&'a str>,
    /// Also write `beside_background.mp4`: the background frames as they are (over a
    /// sentence's own take: the real recording) beside the synthesis drawn on them.
    pub beside_background: bool,
}

/// Which variant is on which side of the blind side-by-side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct AbKey {
    /// The variant on the left.
    pub left: &'static str,
    /// The variant on the right.
    pub right: &'static str,
    /// The seed of the coin.
    pub seed: u64,
}

/// `report.json`: what was synthesised, how, and what was chosen.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// The text spoken, when it was given as text.
    pub text: Option<String>,
    /// The synthesiser.
    pub method: String,
    /// The smoothing.
    pub smoothing: Smoothing,
    /// Where the pose came from.
    pub pose: String,
    /// Frames per second.
    pub fps: f64,
    /// Frames written per variant.
    pub frames: usize,
    /// What rendered the frames.
    pub renderer: String,
    /// Per target phone, what was used.
    pub phones: Vec<PhoneReport>,
    /// Fallbacks and other notes.
    pub warnings: Vec<String>,
    /// For unit selection and the graph: TC_avg, SL_avg, VC_avg, the path cost and the runs
    /// of codebook frames used.
    pub selection: Option<super::unit::SelectionStats>,
    /// The A/B order, for an A/B comparison.
    pub ab_key: Option<AbKey>,
}

/// The sinks of one variant.
struct VariantSinks {
    frames: Sink,
    video: Sink,
}

/// `dir/stem.mp4`, or `.y4m` when a side is odd (4:2:0 needs even sides).
fn video_path(dir: &Path, stem: &str, (w, h): (u32, u32)) -> PathBuf {
    let ext = if w % 2 == 0 && h % 2 == 0 {
        "mp4"
    } else {
        "y4m"
    };
    dir.join(format!("{stem}.{ext}"))
}

/// [`write()`] into a staging folder swapped in for `dir` when everything is written: a
/// killed or failed run leaves `dir` as it was (and its staging is cleaned by the next run),
/// and a folder facespace did not write, or one holding files it did not write, is never
/// replaced or mixed into.
pub fn write_folder(
    dir: &Path,
    renderer: &dyn Renderer,
    utterance: &Utterance,
    background: Background,
    options: &OutputOptions<'_>,
    progress: impl FnMut(Progress),
) -> Result<Report, OutputError> {
    let mut report = None;
    atomic::replace_dir(
        dir,
        "synthesis",
        |staged| {
            report = Some(write(
                staged, renderer, utterance, background, options, progress,
            )?);
            Ok(())
        },
        |source| OutputError::Io {
            path: dir.into(),
            source,
        },
    )?;
    Ok(report.expect("the folder was written"))
}

/// Renders and writes `utterance` into `dir` over `background` (see the module docs).
pub fn write(
    dir: &Path,
    renderer: &dyn Renderer,
    utterance: &Utterance,
    mut background: Background,
    options: &OutputOptions<'_>,
    progress: impl FnMut(Progress),
) -> Result<Report, OutputError> {
    let model = renderer.model();
    let variants = utterance.variants();
    let ab = variants.len() == 2;
    let size = background.size();
    let fps = utterance.synthesis.frames.fps();
    if let Some(sound) = options.audio {
        check_sound(sound, utterance.synthesis.frames.len() as f64 / fps)?;
    }
    let mut sinks = Vec::with_capacity(variants.len());
    for (name, frames) in &variants {
        let vdir = if ab {
            dir.join(name)
        } else {
            dir.to_path_buf()
        };
        npy::write(&vdir.join("trajectory.npy"), frames.values())?;
        let n_landmarks = model.shape.n_landmarks();
        let mut landmarks = Array3::<f32>::zeros((frames.len(), n_landmarks, 2));
        for (i, p) in frames.iter().enumerate() {
            for (k, q) in model.landmarks(p)?.points.iter().enumerate() {
                landmarks[[i, k, 0]] = q[0] as f32;
                landmarks[[i, k, 1]] = q[1] as f32;
            }
        }
        npy::write(&vdir.join("landmarks.npy"), landmarks.view())?;
        sinks.push(VariantSinks {
            frames: Sink::create(&vdir.join("frames"), size.0, size.1, fps, None)?,
            video: Sink::create(
                &video_path(&vdir, "video", size),
                size.0,
                size.1,
                fps,
                options.audio,
            )?,
        });
    }
    let key = ab.then(|| {
        let smoothed_left = Rng::new(options.seed).uniform() < 0.5;
        let (left, right) = if smoothed_left {
            ("smoothed", "unsmoothed")
        } else {
            ("unsmoothed", "smoothed")
        };
        AbKey {
            left,
            right,
            seed: options.seed,
        }
    });
    // Two frames side by side, with the sound.
    let wide_sink = |stem: &str| {
        let wide = (2 * size.0, size.1);
        Sink::create(
            &video_path(dir, stem, wide),
            wide.0,
            wide.1,
            fps,
            options.audio,
        )
    };
    let mut side_by_side = key.map(|_| wide_sink("side_by_side")).transpose()?;
    let mut beside = options
        .beside_background
        .then(|| wide_sink("beside_background"))
        .transpose()?;
    let total = variants[0].1.len();
    pipeline(
        total,
        |range| -> Result<Vec<Vec<RgbImage>>, OutputError> {
            let canvases = background.canvases(range.len(), total)?;
            let mut per_variant = Vec::with_capacity(variants.len() + 1);
            for (_, frames) in &variants {
                let mut c = canvases.clone();
                renderer.render_batch(frames, range.start, &mut c)?;
                per_variant.push(c);
            }
            if options.beside_background {
                // Last: the background as it is.
                per_variant.push(canvases);
            }
            // Frame-major: one item per frame holding every variant's image.
            Ok((0..range.len())
                .map(|k| per_variant.iter().map(|v| v[k].clone()).collect())
                .collect())
        },
        |images: Vec<RgbImage>| -> Result<(), OutputError> {
            for (image, s) in images.iter().zip(&mut sinks) {
                s.frames.write(image)?;
                s.video.write(image)?;
            }
            if let (Some(sink), Some(key)) = (&mut side_by_side, key) {
                let (l, r) = if key.left == "smoothed" {
                    (&images[0], &images[1])
                } else {
                    (&images[1], &images[0])
                };
                sink.write(&video::side_by_side(l, r))?;
            }
            if let (Some(sink), Some(plain)) = (&mut beside, images.last()) {
                // The variants come smoothed first (`Utterance::variants`).
                sink.write(&video::side_by_side(plain, &images[0]))?;
            }
            Ok(())
        },
        progress,
    )?;
    for s in sinks {
        s.frames.finish()?;
        s.video.finish()?;
    }
    if let Some(sink) = side_by_side {
        sink.finish()?;
    }
    if let Some(sink) = beside {
        sink.finish()?;
    }
    let io = |path: PathBuf| move |source| OutputError::Io { path, source };
    if let Some(key) = key {
        let path = dir.join("key.json");
        let json = serde_json::to_vec_pretty(&key).expect("key serialises");
        atomic::write_file(&path, &json).map_err(io(path.clone()))?;
    }
    // The unsmoothed variant as dots: at a small λ it lies on the smoothed line, which would
    // hide it (or it the smoothed one).
    let mut series: Vec<(&str, ndarray::ArrayView2<'_, f32>, bool)> = variants
        .iter()
        .map(|(n, f)| (*n, f.values(), *n == "unsmoothed"))
        .collect();
    if let Some(real) = options.real {
        series.push(("real", real.values(), false));
    }
    let plot = plot::parameter_plot(model.layout(), fps, &series, &utterance.target);
    video::write_png(&dir.join("plot.png"), &plot)?;
    let report = Report {
        text: options.text.map(str::to_owned),
        method: utterance.method.clone(),
        smoothing: utterance.smoothing,
        pose: utterance.pose.clone(),
        fps,
        frames: total,
        renderer: renderer.describe(),
        phones: utterance.synthesis.phones.clone(),
        warnings: utterance.synthesis.warnings.clone(),
        selection: utterance.synthesis.selection.clone(),
        ab_key: key,
    };
    let path = dir.join("report.json");
    let json = serde_json::to_vec_pretty(&report).expect("report serialises");
    atomic::write_file(&path, &json).map_err(io(path.clone()))?;
    crate::phonemes::write_labels(&dir.join("utterance.lab"), &utterance.target)?;
    Ok(report)
}
