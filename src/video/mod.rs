//! Frame sources and sinks (DESIGN §2 `video`): folders of PNG/JPEG frames, YUV4MPEG2 and MP4
//! (H.264) work everywhere, with nothing installed; other containers and codecs go through a
//! system ffmpeg when one is on PATH (detected at run time). Sinks write beside their
//! destination and rename into place when finished, so a failed run leaves no partial file.
//! An AAC track is carried from an MP4 input to an MP4 output; other audio needs ffmpeg.

pub mod mp4;
pub mod y4m;

use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

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
    let mut out = y4m::header(w, h, fps).into_bytes();
    for f in frames {
        y4m::write_frame(&mut out, f).expect("writing to memory");
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

/// Errors of frame sources and sinks; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{0}: no frames")]
    NoFrames(PathBuf),
    #[error("{path}: cannot read frame: {source}")]
    Image {
        path: PathBuf,
        source: image::ImageError,
    },
    #[error(
        "{0}: this format needs a system ffmpeg (not found on PATH); MP4 (H.264), Y4M and frame folders work without one"
    )]
    NeedsFfmpeg(PathBuf),
    #[error("{path}: ffmpeg failed ({status})")]
    Ffmpeg { path: PathBuf, status: String },
    #[error("{path}: {message}")]
    Decode { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Encode { path: PathBuf, message: String },
    #[error("{path}: frame {index} is {found:?}, expected {expected:?} like the first")]
    FrameSize {
        path: PathBuf,
        index: usize,
        found: (u32, u32),
        expected: (u32, u32),
    },
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> VideoError + '_ {
    move |source| VideoError::Io {
        path: path.into(),
        source,
    }
}

/// The image files of a frame folder, in name order.
pub fn frame_files(dir: &Path) -> Result<Vec<PathBuf>, VideoError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| VideoError::Io {
            path: dir.into(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| crate::model::IMAGE_EXTENSIONS.contains(&extension(p).as_str()))
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
pub fn system_ffmpeg() -> Option<PathBuf> {
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|p| p.join("ffmpeg"))
            .find(|p| p.is_file())
    })
}

/// What a source knows of itself before its frames are read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VideoInfo {
    pub width: u32,
    pub height: u32,
    /// Frames per second (a frame folder has none of its own: 25 unless set).
    pub fps: f64,
    /// Frame count, where the container says it.
    pub frames: Option<usize>,
}

/// Frames of a video file or folder, read one at a time.
pub struct Source {
    path: PathBuf,
    info: VideoInfo,
    kind: SourceKind,
    /// Frames handed out so far.
    read: usize,
}

enum SourceKind {
    Frames(Vec<PathBuf>, Option<RgbImage>),
    Y4m(y4m::Reader<BufReader<std::fs::File>>),
    Mp4(Box<mp4::Reader>),
    Ffmpeg(Child, y4m::Reader<BufReader<ChildStdout>>),
}

/// Frame rate given to frame folders.
pub const DEFAULT_FPS: f64 = 25.0;

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

impl Source {
    /// Opens a frame folder, a `.y4m`, an MP4 (`.mp4`, `.m4v`, `.mov`) or, through a system
    /// ffmpeg, anything else.
    pub fn open(path: &Path) -> Result<Self, VideoError> {
        let decode = |message: String| VideoError::Decode {
            path: path.into(),
            message,
        };
        let (info, kind) = if path.is_dir() {
            let files = frame_files(path)?;
            let first = read_frame(&files[0])?;
            let info = VideoInfo {
                width: first.width(),
                height: first.height(),
                fps: DEFAULT_FPS,
                frames: Some(files.len()),
            };
            (info, SourceKind::Frames(files, Some(first)))
        } else if !path.is_file() {
            return Err(io_error(path)(std::io::ErrorKind::NotFound.into()));
        } else {
            match extension(path).as_str() {
                "y4m" => {
                    let file = std::fs::File::open(path).map_err(io_error(path))?;
                    let r = y4m::Reader::new(BufReader::new(file)).map_err(decode)?;
                    let info = VideoInfo {
                        width: r.width,
                        height: r.height,
                        fps: r.fps,
                        frames: None,
                    };
                    (info, SourceKind::Y4m(r))
                }
                "mp4" | "m4v" | "mov" => {
                    let r = mp4::Reader::open(path).map_err(decode)?;
                    if r.frame_count() == 0 {
                        return Err(VideoError::NoFrames(path.into()));
                    }
                    let info = VideoInfo {
                        width: r.width,
                        height: r.height,
                        fps: r.fps,
                        frames: Some(r.frame_count()),
                    };
                    (info, SourceKind::Mp4(Box::new(r)))
                }
                _ => Self::through_ffmpeg(path)?,
            }
        };
        Ok(Source {
            path: path.into(),
            info,
            kind,
            read: 0,
        })
    }

    /// ffmpeg decodes to a 4:4:4 Y4M stream on its stdout, read as it comes.
    fn through_ffmpeg(path: &Path) -> Result<(VideoInfo, SourceKind), VideoError> {
        let ffmpeg = system_ffmpeg().ok_or_else(|| VideoError::NeedsFfmpeg(path.into()))?;
        let mut child = Command::new(ffmpeg)
            .args(["-v", "error", "-nostdin", "-i"])
            .arg(path)
            .args(["-an", "-f", "yuv4mpegpipe", "-pix_fmt", "yuv444p", "-"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(io_error(path))?;
        let stdout = child.stdout.take().expect("stdout is piped");
        match y4m::Reader::new(BufReader::new(stdout)) {
            Ok(r) => {
                let info = VideoInfo {
                    width: r.width,
                    height: r.height,
                    fps: r.fps,
                    frames: None,
                };
                Ok((info, SourceKind::Ffmpeg(child, r)))
            }
            Err(_) => {
                let status = child.wait().map_err(io_error(path))?;
                Err(VideoError::Ffmpeg {
                    path: path.into(),
                    status: format!("{status}; no video stream it can decode"),
                })
            }
        }
    }

    pub fn info(&self) -> VideoInfo {
        self.info
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Overrides the frame rate (for frame folders, or a container that states it wrongly).
    pub fn set_fps(&mut self, fps: f64) {
        self.info.fps = fps;
    }

    /// The next frame, `None` after the last; every frame must match the first's size.
    pub fn next_frame(&mut self) -> Result<Option<RgbImage>, VideoError> {
        let decode = |message: String| VideoError::Decode {
            path: self.path.clone(),
            message,
        };
        let frame = match &mut self.kind {
            SourceKind::Frames(files, first) => match first.take() {
                Some(f) => Some(f),
                None => files.get(self.read).map(|f| read_frame(f)).transpose()?,
            },
            SourceKind::Y4m(r) => r.next_frame().map_err(decode)?,
            SourceKind::Mp4(r) => r.next_frame().map_err(decode)?,
            SourceKind::Ffmpeg(child, r) => {
                let frame = r.next_frame().map_err(decode)?;
                if frame.is_none() {
                    let status = child.wait().map_err(io_error(&self.path))?;
                    if !status.success() {
                        return Err(VideoError::Ffmpeg {
                            path: self.path.clone(),
                            status: status.to_string(),
                        });
                    }
                }
                frame
            }
        };
        if let Some(f) = &frame {
            let expected = (self.info.width, self.info.height);
            if f.dimensions() != expected {
                return Err(VideoError::FrameSize {
                    path: self.path.clone(),
                    index: self.read,
                    found: f.dimensions(),
                    expected,
                });
            }
            self.read += 1;
        }
        Ok(frame)
    }
}

impl Iterator for Source {
    type Item = Result<RgbImage, VideoError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_frame().transpose()
    }
}

impl Drop for Source {
    fn drop(&mut self) {
        if let SourceKind::Ffmpeg(child, _) = &mut self.kind {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Frames written to a folder of PNGs, a `.y4m`, an MP4, or (through a system ffmpeg) any
/// other container ffmpeg knows by its extension. Nothing appears at the destination until
/// [`Sink::finish`]; a sink dropped unfinished leaves nothing behind.
pub struct Sink {
    path: PathBuf,
    width: u32,
    height: u32,
    /// `None` once finished.
    kind: Option<SinkKind>,
    frames: usize,
}

enum SinkKind {
    Frames(tempfile::TempDir),
    Y4m(BufWriter<tempfile::NamedTempFile>),
    Mp4(Box<mp4::Writer>, Option<mp4::AudioTrack>),
    Ffmpeg(Child, BufWriter<ChildStdin>, tempfile::TempPath),
}

/// Marker of a frame folder written by a [`Sink`].
const FIRST_FRAME: &str = "000000.png";

impl Sink {
    /// A sink chosen by `path`: an existing folder or a path without extension → PNG frames;
    /// `.y4m`; `.mp4`/`.m4v`/`.mov` → H.264; anything else through ffmpeg. `audio` (an MP4/M4A
    /// with AAC, or with ffmpeg any audio file) is muxed into containers that carry sound.
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        fps: f64,
        audio: Option<&Path>,
    ) -> Result<Self, VideoError> {
        let encode = |message: String| VideoError::Encode {
            path: path.into(),
            message,
        };
        if width == 0 || height == 0 {
            return Err(encode(format!("cannot write {width}×{height} frames")));
        }
        let parent = crate::atomic::parent_of(path);
        std::fs::create_dir_all(parent).map_err(io_error(parent))?;
        let ext = extension(path);
        let kind = match ext.as_str() {
            "" => SinkKind::Frames(
                tempfile::Builder::new()
                    .prefix(".tmp-")
                    .tempdir_in(parent)
                    .map_err(io_error(parent))?,
            ),
            "y4m" => {
                let mut f = crate::atomic::staging_file(path).map_err(io_error(parent))?;
                f.write_all(y4m::header(width, height, fps).as_bytes())
                    .map_err(io_error(path))?;
                SinkKind::Y4m(BufWriter::new(f))
            }
            "mp4" | "m4v" | "mov" => {
                let track = match audio {
                    Some(a) => Some(audio_track(a)?),
                    None => None,
                };
                let w = mp4::Writer::create(path, width, height, fps).map_err(encode)?;
                SinkKind::Mp4(Box::new(w), track)
            }
            _ => {
                let ffmpeg = system_ffmpeg().ok_or_else(|| VideoError::NeedsFfmpeg(path.into()))?;
                let tmp = tempfile::Builder::new()
                    .prefix(".tmp-")
                    .suffix(&format!(".{ext}"))
                    .tempfile_in(parent)
                    .map_err(io_error(parent))?
                    .into_temp_path();
                let mut cmd = Command::new(ffmpeg);
                cmd.args(["-v", "error", "-y", "-f", "yuv4mpegpipe", "-i", "-"]);
                if let Some(a) = audio {
                    cmd.arg("-i")
                        .arg(a)
                        .args(["-map", "0:v", "-map", "1:a", "-shortest"]);
                }
                let mut child = cmd
                    .args(["-pix_fmt", "yuv420p"])
                    .arg(&tmp)
                    .stdin(Stdio::piped())
                    .stderr(Stdio::null())
                    .spawn()
                    .map_err(io_error(path))?;
                let mut stdin = BufWriter::new(child.stdin.take().expect("stdin is piped"));
                stdin
                    .write_all(y4m::header(width, height, fps).as_bytes())
                    .map_err(io_error(path))?;
                SinkKind::Ffmpeg(child, stdin, tmp)
            }
        };
        Ok(Sink {
            path: path.into(),
            width,
            height,
            kind: Some(kind),
            frames: 0,
        })
    }

    /// Whether the container chosen carries sound.
    pub fn carries_audio(&self) -> bool {
        matches!(self.kind, Some(SinkKind::Mp4(..) | SinkKind::Ffmpeg(..)))
    }

    pub fn write(&mut self, frame: &RgbImage) -> Result<(), VideoError> {
        let expected = (self.width, self.height);
        if frame.dimensions() != expected {
            return Err(VideoError::FrameSize {
                path: self.path.clone(),
                index: self.frames,
                found: frame.dimensions(),
                expected,
            });
        }
        let io = io_error(&self.path);
        let Some(kind) = &mut self.kind else {
            return Ok(());
        };
        match kind {
            SinkKind::Frames(dir) => {
                write_png(&dir.path().join(format!("{:06}.png", self.frames)), frame).map_err(io)?
            }
            SinkKind::Y4m(w) => y4m::write_frame(w, frame).map_err(io)?,
            SinkKind::Mp4(w, _) => w.write(frame).map_err(|message| VideoError::Encode {
                path: self.path.clone(),
                message,
            })?,
            SinkKind::Ffmpeg(_, stdin, _) => y4m::write_frame(stdin, frame).map_err(io)?,
        }
        self.frames += 1;
        Ok(())
    }

    /// Completes the file and renames it into place; returns the frames written.
    pub fn finish(mut self) -> Result<usize, VideoError> {
        let (path, frames) = (self.path.clone(), self.frames);
        let Some(kind) = self.kind.take() else {
            return Ok(frames);
        };
        if frames == 0 {
            if let SinkKind::Ffmpeg(mut child, ..) = kind {
                let _ = child.kill();
                let _ = child.wait();
            }
            return Err(VideoError::NoFrames(path));
        }
        let io = io_error(&path);
        match kind {
            SinkKind::Frames(dir) => {
                crate::atomic::replace_dir(
                    &path,
                    FIRST_FRAME,
                    |staged| {
                        for e in std::fs::read_dir(dir.path())? {
                            let e = e?;
                            std::fs::rename(e.path(), staged.join(e.file_name()))?;
                        }
                        Ok(())
                    },
                    |e| e,
                )
                .map_err(&io)?;
            }
            SinkKind::Y4m(w) => {
                let f = w.into_inner().map_err(|e| io(e.into_error()))?;
                crate::atomic::persist(f, &path).map_err(&io)?;
            }
            SinkKind::Mp4(w, audio) => {
                w.finish(&path, audio.as_ref())
                    .map_err(|message| VideoError::Encode {
                        path: path.clone(),
                        message,
                    })?;
            }
            SinkKind::Ffmpeg(mut child, stdin, tmp) => {
                drop(stdin.into_inner().map_err(|e| io(e.into_error()))?);
                let status = child.wait().map_err(&io)?;
                if !status.success() {
                    return Err(VideoError::Ffmpeg {
                        path: path.clone(),
                        status: status.to_string(),
                    });
                }
                tmp.persist(&path).map_err(|e| io(e.error))?;
            }
        }
        Ok(frames)
    }
}

impl Drop for Sink {
    /// An unfinished ffmpeg sink stops its ffmpeg (its temporary file goes with the guard).
    fn drop(&mut self) {
        if let Some(SinkKind::Ffmpeg(child, ..)) = &mut self.kind {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The AAC track to mux: straight from an MP4/M4A, or (with ffmpeg) transcoded from anything.
fn audio_track(audio: &Path) -> Result<mp4::AudioTrack, VideoError> {
    let decode = |message: String| VideoError::Decode {
        path: audio.into(),
        message,
    };
    if let Ok(Some(track)) = mp4::AudioTrack::read(audio) {
        return Ok(track);
    }
    let ffmpeg = system_ffmpeg().ok_or_else(|| VideoError::NeedsFfmpeg(audio.into()))?;
    let tmp = tempfile::Builder::new()
        .suffix(".m4a")
        .tempfile()
        .map_err(io_error(audio))?
        .into_temp_path();
    let status = Command::new(ffmpeg)
        .args(["-v", "error", "-y", "-nostdin", "-i"])
        .arg(audio)
        .args(["-vn", "-c:a", "aac"])
        .arg(&tmp)
        .status()
        .map_err(io_error(audio))?;
    if !status.success() {
        return Err(decode(format!(
            "ffmpeg found no audio it can read ({status})"
        )));
    }
    mp4::AudioTrack::read(&tmp)
        .map_err(decode)?
        .ok_or_else(|| decode("no audio track".into()))
}

/// Lifts the audio of `input` into `out` (an `.m4a`): copied from an MP4's AAC track, or
/// transcoded by a system ffmpeg. `Ok(false)` when the input has no audio (or only ffmpeg could
/// tell, and there is none).
pub fn extract_audio(input: &Path, out: &Path) -> Result<bool, VideoError> {
    let mp4_input = matches!(extension(input).as_str(), "mp4" | "m4v" | "mov" | "m4a");
    let track = match mp4_input.then(|| mp4::AudioTrack::read(input)) {
        Some(Ok(found)) => found,
        _ if input.is_dir() || system_ffmpeg().is_none() => None,
        _ => audio_track(input).ok(),
    };
    match track {
        Some(track) => track
            .save(out)
            .map(|()| true)
            .map_err(|message| VideoError::Encode {
                path: out.into(),
                message,
            }),
        None => Ok(false),
    }
}
