//! Frame sinks: a folder of PNGs, a Y4M stream, an MP4 (H.264), or anything a system ffmpeg
//! encodes. Nothing appears at the destination until [`Sink::finish`].

use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

use image::RgbImage;

use super::{VideoError, audio_track, extension, io_error, mp4, write_png, y4m};
use crate::programs::system_ffmpeg;
use crate::atomic;

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
    Frames(atomic::StagingDir),
    Y4m(y4m::Writer<BufWriter<tempfile::NamedTempFile>>),
    Mp4(Box<mp4::Writer>, Option<mp4::AudioTrack>),
    Ffmpeg(Child, y4m::Writer<BufWriter<Pipe>>, tempfile::NamedTempFile),
}

/// Containers a system ffmpeg writes for [`Sink`], beyond the built-in MP4, Y4M and frame
/// folders: anything else (`out.txt`, `dec.md`) is refused before any work.
pub const FFMPEG_CONTAINERS: [&str; 12] = [
    "mkv", "webm", "avi", "mpg", "mpeg", "ts", "m2ts", "flv", "ogv", "wmv", "3gp", "nut",
];

/// Refuses `path` as a video destination unless its extension names a container written here
/// (none: a folder of PNGs; `y4m`; `mp4`, `m4v`, `mov`) or, with a system ffmpeg on PATH, one
/// of [`FFMPEG_CONTAINERS`]. Checked by [`Sink::create`], and by commands before their work.
pub fn check_destination(path: &Path) -> Result<(), VideoError> {
    match extension(path).as_str() {
        "" | "y4m" | "mp4" | "m4v" | "mov" => Ok(()),
        e if FFMPEG_CONTAINERS.contains(&e) => match system_ffmpeg() {
            Some(_) => Ok(()),
            None => Err(VideoError::NeedsFfmpeg(path.into())),
        },
        e => Err(VideoError::NotVideo {
            path: path.into(),
            extension: crate::options::clipped(e, 40),
        }),
    }
}

/// ffmpeg's standard input. The binary keeps the default SIGPIPE disposition (it ends quietly
/// under `| head`), so a write after ffmpeg has exited would kill the whole process with no
/// message and its staging left behind (issue 69, R5-6): each write blocks SIGPIPE on its
/// thread, and a broken pipe is an error instead, its pending signal taken back.
pub(crate) struct Pipe(ChildStdin);

impl std::io::Write for Pipe {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        without_sigpipe(|| self.0.write(buf))
    }

    fn flush(&mut self) -> std::io::Result<()> {
        without_sigpipe(|| self.0.flush())
    }
}

/// Runs `write` with SIGPIPE blocked on this thread; a SIGPIPE it raised is consumed.
fn without_sigpipe<T>(write: impl FnOnce() -> std::io::Result<T>) -> std::io::Result<T> {
    #[cfg(unix)]
    {
        // SAFETY: plain signal-mask calls on this thread's own mask with initialised sets;
        // sigtimedwait with a zero timeout only takes a SIGPIPE already pending here.
        unsafe {
            let mut pipe: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut pipe);
            libc::sigaddset(&mut pipe, libc::SIGPIPE);
            let mut old: libc::sigset_t = std::mem::zeroed();
            libc::pthread_sigmask(libc::SIG_BLOCK, &pipe, &mut old);
            let result = write();
            if libc::sigismember(&old, libc::SIGPIPE) == 0 {
                if matches!(&result, Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe) {
                    let now = libc::timespec {
                        tv_sec: 0,
                        tv_nsec: 0,
                    };
                    libc::sigtimedwait(&pipe, std::ptr::null_mut(), &now);
                }
                libc::pthread_sigmask(libc::SIG_SETMASK, &old, std::ptr::null_mut());
            }
            result
        }
    }
    #[cfg(not(unix))]
    write()
}

impl Sink {
    /// A sink chosen by `path`: a path without extension → a folder of PNG frames
    /// (`000000.png`, …); `.y4m`; `.mp4`/`.m4v`/`.mov` → H.264; anything else through ffmpeg.
    /// `audio` (an MP4/M4A with AAC, or with ffmpeg any audio file) is muxed into containers
    /// that carry sound.
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        fps: f64,
        audio: Option<&Path>,
    ) -> Result<Self, VideoError> {
        let option = |source| VideoError::Option {
            path: path.into(),
            source,
        };
        crate::facespace::check_fps(fps).map_err(option)?;
        for (name, v) in [("frame width", width), ("frame height", height)] {
            crate::options::count_in(name, v as usize, 1, y4m::MAX_SIDE).map_err(option)?;
        }
        check_destination(path)?;
        let parent = atomic::parent_of(path);
        std::fs::create_dir_all(parent).map_err(io_error(parent))?;
        let y4m_error = |source| VideoError::Y4m {
            path: path.into(),
            source,
        };
        let kind = match extension(path).as_str() {
            "" => SinkKind::Frames(atomic::StagingDir::new(parent).map_err(io_error(parent))?),
            "y4m" => {
                let f = atomic::staging_file(path).map_err(io_error(parent))?;
                SinkKind::Y4m(
                    y4m::Writer::new(BufWriter::new(f), width, height, fps).map_err(y4m_error)?,
                )
            }
            "mp4" | "m4v" | "mov" => {
                let track = match audio {
                    Some(a) => Some(audio_track(a)?),
                    None => None,
                };
                let w = mp4::Writer::create(path, width, height, fps).map_err(|source| {
                    VideoError::Mp4 {
                        path: path.into(),
                        source,
                    }
                })?;
                SinkKind::Mp4(Box::new(w), track)
            }
            _ => {
                let ffmpeg = system_ffmpeg().ok_or_else(|| VideoError::NeedsFfmpeg(path.into()))?;
                if let Some(a) = audio {
                    // Never hand ffmpeg a FIFO or device: it would block or never end.
                    crate::safe_read::open_regular(a).map_err(io_error(a))?;
                }
                // Staged and locked like every other output: a killed run's file is ours
                // to clean, and it is renamed into place only once ffmpeg succeeds.
                let tmp = crate::atomic::staging_file(path).map_err(io_error(parent))?;
                let mut cmd = Command::new(ffmpeg);
                cmd.args(["-v", "error", "-y", "-f", "yuv4mpegpipe", "-i", "-"]);
                if let Some(a) = audio {
                    cmd.arg("-i")
                        .arg(a)
                        .args(["-map", "0:v", "-map", "1:a", "-shortest"]);
                }
                let mut child = cmd
                    .args(["-pix_fmt", "yuv420p"])
                    .arg(tmp.path())
                    .stdin(Stdio::piped())
                    .stderr(Stdio::null())
                    .spawn()
                    .map_err(io_error(path))?;
                let stdin = BufWriter::new(Pipe(child.stdin.take().expect("stdin is piped")));
                let writer = y4m::Writer::new(stdin, width, height, fps).map_err(y4m_error)?;
                SinkKind::Ffmpeg(child, writer, tmp)
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

    /// The destination.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends one frame (of the sink's size).
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
        let Some(kind) = &mut self.kind else {
            return Ok(());
        };
        let y4m_error = |source| VideoError::Y4m {
            path: self.path.clone(),
            source,
        };
        match kind {
            SinkKind::Frames(dir) => {
                write_png(&dir.path().join(format!("{:06}.png", self.frames)), frame)?
            }
            SinkKind::Y4m(w) => w.write(frame).map_err(y4m_error)?,
            SinkKind::Mp4(w, _) => w.write(frame).map_err(|source| VideoError::Mp4 {
                path: self.path.clone(),
                source,
            })?,
            SinkKind::Ffmpeg(child, w, _) => {
                if let Err(e) = w.write(frame) {
                    // ffmpeg gone: say so, with how it ended, rather than "broken pipe".
                    if let Ok(Some(status)) = child.try_wait() {
                        return Err(VideoError::Ffmpeg {
                            path: self.path.clone(),
                            status: format!("{status}, before all frames were written"),
                        });
                    }
                    return Err(y4m_error(e));
                }
            }
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
                atomic::replace_dir(
                    &path,
                    "frames",
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
                let f = w
                    .into_inner()
                    .into_inner()
                    .map_err(|e| io(e.into_error()))?;
                atomic::persist(f, &path).map_err(&io)?;
            }
            SinkKind::Mp4(w, audio) => {
                w.finish(&path, audio.as_ref())
                    .map_err(|source| VideoError::Mp4 {
                        path: path.clone(),
                        source,
                    })?;
            }
            SinkKind::Ffmpeg(mut child, w, tmp) => {
                drop(
                    w.into_inner()
                        .into_inner()
                        .map_err(|e| io(e.into_error()))?,
                );
                let status = child.wait().map_err(&io)?;
                if !status.success() {
                    return Err(VideoError::Ffmpeg {
                        path: path.clone(),
                        status: status.to_string(),
                    });
                }
                crate::atomic::persist(tmp, &path).map_err(&io)?;
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
