//! Frame sinks: PNG sequences and YUV4MPEG2 (`.y4m`, 4:4:4, BT.601), both always available
//! without system tools. (MP4 in and out, and audio, belong to the video issue.)

use std::io::Write;
use std::path::Path;

use image::RgbImage;
use rayon::prelude::*;

use crate::atomic;

/// Writes one PNG atomically.
pub fn write_png(path: &Path, image: &RgbImage) -> std::io::Result<()> {
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(std::io::Error::other)?;
    atomic::write_file(path, &bytes)
}

/// Writes frames as `dir/0000.png`, `0001.png`, … (in parallel).
pub fn write_png_frames(dir: &Path, frames: &[RgbImage]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    frames
        .par_iter()
        .enumerate()
        .try_for_each(|(i, f)| write_png(&dir.join(format!("{i:04}.png")), f))
}

/// Encodes frames as YUV4MPEG2 4:4:4 (studio-range BT.601), the raw format every video tool
/// reads (`ffplay out.y4m`, `ffmpeg -i out.y4m out.mp4`).
pub fn y4m_bytes(frames: &[RgbImage], fps: f64) -> Vec<u8> {
    let (w, h) = frames.first().map_or((0, 0), |f| (f.width(), f.height()));
    let (num, den) = ((fps * 1000.0).round() as u64, 1000u64);
    let mut out = Vec::with_capacity(frames.len() * (w * h * 3 + 6) as usize + 64);
    let _ = writeln!(out, "YUV4MPEG2 W{w} H{h} F{num}:{den} Ip A1:1 C444");
    for f in frames {
        out.extend_from_slice(b"FRAME\n");
        let px: Vec<[f32; 3]> = f.pixels().map(|p| p.0.map(|v| v as f32)).collect();
        let plane = |c: usize| -> Vec<u8> {
            px.iter()
                .map(|&[r, g, b]| {
                    let v = match c {
                        0 => 16.0 + 0.2568 * r + 0.5041 * g + 0.0979 * b,
                        1 => 128.0 - 0.1482 * r - 0.2910 * g + 0.4392 * b,
                        _ => 128.0 + 0.4392 * r - 0.3678 * g - 0.0714 * b,
                    };
                    v.round().clamp(0.0, 255.0) as u8
                })
                .collect()
        };
        for c in 0..3 {
            out.extend_from_slice(&plane(c));
        }
    }
    out
}

/// Writes a `.y4m` file atomically.
pub fn write_y4m(path: &Path, frames: &[RgbImage], fps: f64) -> std::io::Result<()> {
    atomic::write_file(path, &y4m_bytes(frames, fps))
}

/// Two equally long frame sequences side by side (left | right).
pub fn side_by_side(left: &[RgbImage], right: &[RgbImage]) -> Vec<RgbImage> {
    left.iter()
        .zip(right)
        .map(|(a, b)| {
            let mut out = RgbImage::new(a.width() + b.width(), a.height().max(b.height()));
            image::imageops::replace(&mut out, a, 0, 0);
            image::imageops::replace(&mut out, b, a.width() as i64, 0);
            out
        })
        .collect()
}

/// Errors of frame sources.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("{0}: no frames (png, jpg, ppm)")]
    NoFrames(std::path::PathBuf),
    #[error("{path}: cannot read frame: {source}")]
    Image {
        path: std::path::PathBuf,
        source: image::ImageError,
    },
    #[error(
        "{0}: reading video files needs a system ffmpeg (not found on PATH) until the built-in MP4 reader lands; give a folder of frames instead"
    )]
    NeedsFfmpeg(std::path::PathBuf),
    #[error("{path}: ffmpeg could not decode it ({status})")]
    Ffmpeg {
        path: std::path::PathBuf,
        status: String,
    },
}

/// The image files of a frame folder, in name order.
pub fn frame_files(dir: &Path) -> Result<Vec<std::path::PathBuf>, VideoError> {
    let mut files: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| VideoError::Io {
            path: dir.into(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .is_some_and(|e| crate::model::IMAGE_EXTENSIONS.contains(&e.as_str()))
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(VideoError::NoFrames(dir.into()));
    }
    Ok(files)
}

pub fn read_frame(path: &Path) -> Result<RgbImage, VideoError> {
    Ok(image::open(path)
        .map_err(|source| VideoError::Image {
            path: path.into(),
            source,
        })?
        .to_rgb8())
}

/// A system ffmpeg on PATH, if any (detected at run time, never required).
pub fn system_ffmpeg() -> Option<std::path::PathBuf> {
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|p| p.join("ffmpeg"))
            .find(|p| p.is_file())
    })
}

/// Decodes a video file to PNG frames in `dir` with the system ffmpeg.
pub fn decode_with_ffmpeg(video: &Path, dir: &Path) -> Result<Vec<std::path::PathBuf>, VideoError> {
    let ffmpeg = system_ffmpeg().ok_or_else(|| VideoError::NeedsFfmpeg(video.into()))?;
    let status = std::process::Command::new(ffmpeg)
        .args(["-v", "error", "-i"])
        .arg(video)
        .args(["-vsync", "0"])
        .arg(dir.join("%06d.png"))
        .status()
        .map_err(|source| VideoError::Io {
            path: video.into(),
            source,
        })?;
    if !status.success() {
        return Err(VideoError::Ffmpeg {
            path: video.into(),
            status: status.to_string(),
        });
    }
    frame_files(dir).map_err(|_| VideoError::NoFrames(video.into()))
}
