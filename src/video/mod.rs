//! Frame sources and sinks (DESIGN §2 `video`): folders of PNG/JPEG frames, YUV4MPEG2 and MP4
//! (H.264) work everywhere, with nothing installed; other containers and codecs go through a
//! system ffmpeg when one is on PATH (detected at run time). Sinks write beside their
//! destination and rename into place when finished, so a failed run leaves no partial file.
//! An AAC track is carried from an MP4 input to an MP4 output; other audio needs ffmpeg.

mod export;
use crate::mp4_file as mp4;
mod sink;
mod source;
pub mod y4m;

use std::path::{Path, PathBuf};

use image::RgbImage;

pub use export::{MAX_EXPORT, export_frames, spread};
pub use sink::{FFMPEG_CONTAINERS, Sink, check_destination};
pub use source::{DEFAULT_FPS, Source, VideoInfo};

use crate::atomic;
use crate::options::InvalidOption;

/// BT.601 luma of an RGB pixel, in its units: the one grey of every grey measure, the
/// footage's thumbnails and the recorded mouths' detail.
/// (f64: the measures compare it to analytic values; f32 callers round the result.)
pub fn luma([r, g, b]: [f64; 3]) -> f64 {
    0.299 * r + 0.587 * g + 0.114 * b
}

/// Image file extensions a frame or training folder may hold.
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "ppm", "pgm", "pnm"];

/// Errors of frame sources and sinks; each names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum VideoError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A video or folder without frames.
    #[error("{0}: no frames")]
    NoFrames(PathBuf),
    /// A frame image could not be decoded or encoded.
    #[error("{path}: cannot read or write frame: {source}")]
    Image {
        /// The image.
        path: PathBuf,
        /// The cause.
        source: image::ImageError,
    },
    /// Sound that could not be read.
    #[error("{path}: {reason}")]
    Audio {
        /// The sound file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// A container only ffmpeg handles, and there is none.
    #[error(
        "{0}: this format needs a system ffmpeg (not found on PATH); MP4 (H.264), Y4M and frame folders work without one"
    )]
    NeedsFfmpeg(PathBuf),
    /// A destination whose extension names no video container.
    #[error(
        "{path}: .{extension} is not a video format; give .mp4 (or .y4m, a folder for PNG frames, or with a system ffmpeg .mkv, .webm, .avi, …)"
    )]
    NotVideo {
        /// The destination.
        path: PathBuf,
        /// Its extension.
        extension: String,
    },
    /// ffmpeg failed.
    #[error("{path}: ffmpeg failed ({status})")]
    Ffmpeg {
        /// The file.
        path: PathBuf,
        /// Its exit status, in words.
        status: String,
    },
    /// The MP4 reader or writer failed.
    #[error("{path}: {source}")]
    Mp4 {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: mp4::Mp4Error,
    },
    /// The Y4M reader or writer failed.
    #[error("{path}: {source}")]
    Y4m {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: y4m::Y4mError,
    },
    /// A frame of another size than the first.
    #[error("{path}: frame {index} is {found:?}, expected {expected:?} like the first")]
    FrameSize {
        /// The file.
        path: PathBuf,
        /// The frame.
        index: usize,
        /// Its size.
        found: (u32, u32),
        /// The first frame's size.
        expected: (u32, u32),
    },
    /// An out-of-range frame rate or size.
    #[error("{path}: {source}")]
    Option {
        /// The file.
        path: PathBuf,
        /// What is out of range.
        source: InvalidOption,
    },
}

pub(crate) fn io_error(path: &Path) -> impl Fn(std::io::Error) -> VideoError + '_ {
    move |source| VideoError::Io {
        path: path.into(),
        source,
    }
}

/// The lower-case extension of `path` (empty if none).
pub(crate) fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

/// The regular files of `dir` whose lower-case extension `keep` accepts, in name order.
pub(crate) fn files_where(dir: &Path, keep: impl Fn(&str) -> bool) -> std::io::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && keep(&extension(p)))
        .collect();
    files.sort();
    Ok(files)
}

/// The image files of a folder ([`IMAGE_EXTENSIONS`]), in name order; maybe none.
pub fn image_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    files_where(dir, |e| IMAGE_EXTENSIONS.contains(&e))
}

/// The files of a folder with extension `ext` (any case), in name order.
pub fn files_with_extension(dir: &Path, ext: &str) -> std::io::Result<Vec<PathBuf>> {
    files_where(dir, |e| e.eq_ignore_ascii_case(ext))
}

/// The frames of a frame folder, in name order; an error if there are none.
pub fn frame_files(dir: &Path) -> Result<Vec<PathBuf>, VideoError> {
    let files = image_files(dir).map_err(io_error(dir))?;
    if files.is_empty() {
        return Err(VideoError::NoFrames(dir.into()));
    }
    Ok(files)
}

/// Reads one image file as RGB.
pub fn read_frame(path: &Path) -> Result<RgbImage, VideoError> {
    read_image(path).map_err(|source| VideoError::Image {
        path: path.into(),
        source,
    })
}

/// Reads one image file as RGB, opened as a regular file only ([`crate::safe_read::open_regular`]:
/// a FIFO would block, a device never end); the format from the extension, else the content.
pub fn read_image(path: &Path) -> Result<RgbImage, image::ImageError> {
    let file = crate::safe_read::open_regular(path).map_err(image::ImageError::IoError)?;
    let mut reader = image::ImageReader::new(std::io::BufReader::new(file));
    match image::ImageFormat::from_path(path) {
        Ok(format) => reader.set_format(format),
        Err(_) => {
            reader = reader
                .with_guessed_format()
                .map_err(image::ImageError::IoError)?
        }
    }
    Ok(reader.decode()?.to_rgb8())
}

/// Writes one PNG atomically.
pub fn write_png(path: &Path, image: &RgbImage) -> Result<(), VideoError> {
    let mut bytes = Vec::new();
    image
        .write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|source| VideoError::Image {
            path: path.into(),
            source,
        })?;
    atomic::write_file(path, &bytes).map_err(io_error(path))
}

/// Two frames side by side (left | right).
pub fn side_by_side(left: &RgbImage, right: &RgbImage) -> RgbImage {
    let mut out = RgbImage::new(
        left.width() + right.width(),
        left.height().max(right.height()),
    );
    image::imageops::replace(&mut out, left, 0, 0);
    image::imageops::replace(&mut out, right, left.width() as i64, 0);
    out
}

/// The AAC track to mux: straight from an MP4/M4A (its edit list kept), else the sound
/// decoded (WAV and AAC in Rust, other formats through a system ffmpeg) and encoded as AAC
/// in Rust — no ffmpeg needed for WAV.
pub(crate) fn audio_track(audio: &Path) -> Result<mp4::AudioTrack, VideoError> {
    let mp4 = |source| VideoError::Mp4 {
        path: audio.into(),
        source,
    };
    if let Ok(Some(track)) = mp4::AudioTrack::read(audio) {
        return Ok(track);
    }
    let sound = crate::audio::read_native(audio, crate::facespace::MAX_DURATION).map_err(|e| {
        VideoError::Audio {
            path: audio.into(),
            reason: e.to_string(),
        }
    })?;
    if sound.samples.is_empty() {
        return Err(VideoError::Audio {
            path: audio.into(),
            reason: "no audio samples".into(),
        });
    }
    // Rates AAC does not have are resampled to 48 kHz.
    let sound = if mp4::AAC_RATES.contains(&sound.rate) {
        sound
    } else {
        crate::audio::resample(&sound, 48_000)
    };
    let pcm: Vec<i16> = sound.samples.iter().map(|&x| crate::audio::to_pcm16(x)).collect();
    mp4::AudioTrack::encode(&pcm, sound.rate).map_err(mp4)
}

/// Lifts the audio of `input` into `out` (an `.m4a`): copied from an MP4's AAC track, or
/// decoded (in Rust, or by a system ffmpeg) and encoded as AAC. `Ok(false)` when the input has
/// no audio that can be read.
pub fn extract_audio(input: &Path, out: &Path) -> Result<bool, VideoError> {
    let mp4_input = matches!(extension(input).as_str(), "mp4" | "m4v" | "mov" | "m4a");
    let track = match mp4_input.then(|| mp4::AudioTrack::read(input)) {
        Some(Ok(found)) => found,
        _ if input.is_dir() => None,
        _ => audio_track(input).ok(),
    };
    match track {
        Some(track) => track
            .save(out)
            .map(|()| true)
            .map_err(|source| VideoError::Mp4 {
                path: out.into(),
                source,
            }),
        None => Ok(false),
    }
}
