//! Quality and size of video through face-space (DESIGN §9): per-frame PSNR and SSIM inside
//! the face mask of the decoded face (no compositing) against the input, bytes per frame.

use std::path::Path;

use image::{Rgb, RgbImage};
use rayon::prelude::*;
use serde::Serialize;

use super::{Clip, CodecError};
use crate::facespace::Frames;
use crate::model::FaceModel;
use crate::render::{CpuRenderer, RenderError, Renderer};
use crate::video::{self, Source};
use crate::{Progress, atomic, eval, plot};

/// Largest difference between two sequences' shape/appearance values, in standard deviations.
pub fn max_error_sd(model: &FaceModel, a: &Frames, b: &Frames) -> f64 {
    let sd = model.standard_deviations();
    let range = model.layout().params_range();
    a.values()
        .rows()
        .into_iter()
        .zip(b.values().rows())
        .flat_map(|(x, y)| {
            let sd = &sd;
            range
                .clone()
                .map(move |k| f64::from((x[k] - y[k]).abs()) / sd[k - range.start])
        })
        .fold(0.0, f64::max)
}

/// Mean, minimum and per-frame values of a measure.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Stat {
    /// Mean over frames.
    pub mean: f64,
    /// Minimum over frames.
    pub min: f64,
    /// Per frame.
    pub per_frame: Vec<f64>,
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

/// The codec report: quality inside the face and bytes per frame.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct QualityReport {
    /// The input video.
    pub input: String,
    /// Frames compared.
    pub frames: usize,
    /// Frame width.
    pub width: u32,
    /// Frame height.
    pub height: u32,
    /// Frame rate.
    pub fps: f64,
    /// PSNR (dB) inside the face mask, decoded face (no compositing) against the input.
    pub psnr: Stat,
    /// SSIM inside the face mask (scikit-image conventions).
    pub ssim: Stat,
    /// Bytes per frame of the parameter stream alone.
    pub params_bytes_per_frame: f64,
    /// Bytes per frame of the whole clip folder on disk (what decoding needs: parameters,
    /// tracking record, manifests; audio too when kept).
    pub clip_bytes_per_frame: f64,
    /// Bytes per frame of the input.
    pub input_bytes_per_frame: f64,
    /// Input bytes over the clip folder's bytes on disk.
    pub compression_ratio: f64,
    /// Input bytes over the parameter stream's bytes.
    pub params_compression_ratio: f64,
}

/// Bytes of the input: its file size, or a frame folder's total.
pub fn input_bytes(input: &Path) -> Result<u64, CodecError> {
    let io = |source| CodecError::Io {
        path: input.into(),
        source,
    };
    Ok(if input.is_dir() {
        video::frame_files(input)?
            .iter()
            .map(|f| f.metadata().map(|m| m.len()).unwrap_or(0))
            .sum()
    } else {
        input.metadata().map_err(io)?.len()
    })
}

/// Decodes every frame of `clip` (the face alone, no compositing) and compares it with the
/// frames of `input` inside the face mask.
pub fn score(
    model: &FaceModel,
    input: &Path,
    clip: &Clip,
    clip_dir: &Path,
    mut progress: impl FnMut(Progress),
) -> Result<QualityReport, CodecError> {
    let mut source = Source::open(input)?;
    let (w, h) = (clip.width, clip.height);
    let info = source.info();
    if (info.width, info.height) != (w, h) {
        return Err(RenderError::Size {
            what: input.display().to_string(),
            found: (info.width, info.height),
            expected: (w, h),
        }
        .into());
    }
    let renderer = CpuRenderer::new(model);
    let (mut psnr, mut ssim) = (Vec::new(), Vec::new());
    let n = clip.frames.len();
    while psnr.len() < n {
        let batch: Vec<RgbImage> = (0..64.min(n - psnr.len()))
            .map(|_| {
                source
                    .next_frame()?
                    .ok_or(CodecError::NoFrames(input.into()))
            })
            .collect::<Result<_, _>>()?;
        let start = psnr.len();
        let scores: Vec<(f64, f64)> = batch
            .par_iter()
            .enumerate()
            .map(|(k, original)| {
                let params = clip.frames.params(start + k);
                let mut decoded = RgbImage::from_pixel(w, h, Rgb([0, 0, 0]));
                renderer.render_into(params, &mut decoded)?;
                let landmarks = model.landmarks(params)?;
                let mask = eval::face_mask(model, &landmarks.points, w, h);
                Ok((
                    eval::psnr_masked(original, &decoded, &mask),
                    eval::ssim_masked(original, &decoded, &mask),
                ))
            })
            .collect::<Result<_, CodecError>>()?;
        for (p, s) in scores {
            psnr.push(p);
            ssim.push(s);
        }
        progress(Progress {
            stage: "scoring",
            done: psnr.len(),
            total: n,
        });
    }
    let frames = n.max(1) as f64;
    let (params_bpf, clip_bpf, input_bpf) = (
        clip.stream_bytes() as f64 / frames,
        Clip::disk_bytes(clip_dir)? as f64 / frames,
        input_bytes(input)? as f64 / frames,
    );
    Ok(QualityReport {
        input: input.display().to_string(),
        frames: n,
        width: w,
        height: h,
        fps: clip.frames.fps(),
        psnr: Stat::of(psnr),
        ssim: Stat::of(ssim),
        params_bytes_per_frame: params_bpf,
        clip_bytes_per_frame: clip_bpf,
        input_bytes_per_frame: input_bpf,
        compression_ratio: input_bpf / clip_bpf,
        params_compression_ratio: input_bpf / params_bpf,
    })
}

impl QualityReport {
    /// PSNR and SSIM over time, two panels.
    pub fn plot(&self) -> RgbImage {
        let t: Vec<f64> = (0..self.frames).map(|i| i as f64 / self.fps).collect();
        let panel = |title: &str, label: &str, y: &[f64], i: usize| {
            plot::line_plot(
                title,
                "time (s)",
                &[plot::Series {
                    label,
                    x: &t,
                    y,
                    color: plot::PALETTE[i],
                    dots: false,
                }],
                &[],
                900,
                260,
            )
        };
        plot::stack(&[
            panel(
                "PSNR inside the face mask",
                "PSNR (dB)",
                &self.psnr.per_frame,
                0,
            ),
            panel("SSIM inside the face mask", "SSIM", &self.ssim.per_frame, 1),
        ])
    }

    /// Writes the report as JSON at `path` and its plot beside it (same name, `.png`).
    pub fn write(&self, path: &Path) -> Result<(), CodecError> {
        let json = serde_json::to_vec_pretty(self).expect("report serialises");
        atomic::write_file(path, &json).map_err(|source| CodecError::Io {
            path: path.into(),
            source,
        })?;
        video::write_png(&path.with_extension("png"), &self.plot())?;
        Ok(())
    }
}
