//! Frame sources: a frame folder, a Y4M stream, an MP4 (H.264), or anything a system ffmpeg
//! decodes, read one frame at a time.

use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};

use image::RgbImage;

use super::{VideoError, extension, frame_files, io_error, mp4, read_frame, y4m};
use crate::programs::system_ffmpeg;

/// What a source knows of itself before its frames are read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VideoInfo {
    /// Frame width.
    pub width: u32,
    /// Frame height.
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
    /// Frames handed out at most ([`Source::limit`]).
    limit: Option<usize>,
}

enum SourceKind {
    Frames(Vec<PathBuf>, Option<RgbImage>),
    Y4m(y4m::Reader<BufReader<std::fs::File>>),
    Mp4(Box<mp4::Reader>),
    Ffmpeg(Child, y4m::Reader<BufReader<ChildStdout>>),
}

/// Frame rate given to frame folders.
pub const DEFAULT_FPS: f64 = 25.0;

impl Source {
    /// Opens a frame folder, a `.y4m`, an MP4 (`.mp4`, `.m4v`, `.mov`) or, through a system
    /// ffmpeg, anything else.
    pub fn open(path: &Path) -> Result<Self, VideoError> {
        let y4m_error = |source| VideoError::Y4m {
            path: path.into(),
            source,
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
        } else if let Err(e) = crate::safe_read::open_regular(path) {
            // Missing, or a FIFO or device (which would block or never end).
            return Err(io_error(path)(e));
        } else {
            match extension(path).as_str() {
                "y4m" => {
                    let file = crate::safe_read::open_regular(path).map_err(io_error(path))?;
                    let r = y4m::Reader::new(BufReader::new(file)).map_err(y4m_error)?;
                    (r.info(), SourceKind::Y4m(r))
                }
                "mp4" | "m4v" | "mov" => {
                    let r = mp4::Reader::open(path).map_err(|source| VideoError::Mp4 {
                        path: path.into(),
                        source,
                    })?;
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
            limit: None,
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
            Ok(r) => Ok((r.info(), SourceKind::Ffmpeg(child, r))),
            Err(_) => {
                let status = child.wait().map_err(io_error(path))?;
                Err(VideoError::Ffmpeg {
                    path: path.into(),
                    status: format!("{status}; no video stream it can decode"),
                })
            }
        }
    }

    /// Size, frame rate and (where known) frame count.
    pub fn info(&self) -> VideoInfo {
        self.info
    }

    /// A frame folder's file stems, in frame order (`None` for a video file).
    pub fn frame_names(&self) -> Option<Vec<String>> {
        match &self.kind {
            SourceKind::Frames(files, _) => Some(
                files
                    .iter()
                    .map(|f| {
                        f.file_stem()
                            .unwrap_or_default()
                            .to_string_lossy()
                            .into_owned()
                    })
                    .collect(),
            ),
            _ => None,
        }
    }

    /// The same source ending after its first `n` frames: a caller that needs a few frames of
    /// a long video (a background under a 3 s sentence) never decodes the rest.
    pub fn limit(mut self, n: usize) -> Self {
        self.limit = Some(n);
        self.info.frames = Some(self.info.frames.map_or(n, |f| f.min(n)));
        self
    }

    /// Frames handed out so far.
    pub fn frames_read(&self) -> usize {
        self.read
    }

    /// The file or folder read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Overrides the frame rate (for frame folders, or a container that states it wrongly).
    pub fn set_fps(&mut self, fps: f64) -> Result<(), VideoError> {
        self.info.fps = crate::facespace::check_fps(fps).map_err(|source| VideoError::Option {
            path: self.path.clone(),
            source,
        })?;
        Ok(())
    }

    /// The next frame, `None` after the last; every frame must match the first's size.
    pub fn next_frame(&mut self) -> Result<Option<RgbImage>, VideoError> {
        let y4m_error = |path: &Path| {
            let path = path.to_path_buf();
            move |source| VideoError::Y4m { path, source }
        };
        if self.limit.is_some_and(|n| self.read >= n) {
            return Ok(None);
        }
        let frame = match &mut self.kind {
            SourceKind::Frames(files, first) => match first.take() {
                Some(f) => Some(f),
                None => files.get(self.read).map(|f| read_frame(f)).transpose()?,
            },
            SourceKind::Y4m(r) => r.next_frame().map_err(y4m_error(&self.path))?,
            SourceKind::Mp4(r) => r.next_frame().map_err(|source| VideoError::Mp4 {
                path: self.path.clone(),
                source,
            })?,
            SourceKind::Ffmpeg(child, r) => {
                let frame = r.next_frame().map_err(y4m_error(&self.path))?;
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
