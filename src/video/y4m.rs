//! YUV4MPEG2 (`.y4m`): the raw format every video tool reads and writes, and the pipe format
//! to and from a system ffmpeg. Read through the `y4m` crate (as rav1e does) with a frame-size
//! cap — 8-bit 4:4:4, 4:2:2, 4:2:0 (every siting, nearest-sample chroma) and mono; written as
//! 4:4:4. Studio-range BT.601 both ways.

use std::io::{Chain, Cursor, Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use image::RgbImage;
use thiserror::Error;

use super::VideoInfo;

/// Longest frame side read or written.
pub const MAX_SIDE: usize = 16_384;
/// Largest frame read (8K UHD), so a corrupt header cannot ask for gigabytes.
pub const MAX_PIXELS: u64 = 7680 * 4320;

/// What can be wrong with a Y4M stream.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Y4mError {
    /// The stream header or a frame marker is malformed.
    #[error("not a readable YUV4MPEG2 stream: {0}")]
    Malformed(String),
    /// A colour space this reader does not convert.
    #[error("unsupported colour space C{0} (8-bit 444, 422, 420 and mono are read)")]
    Colorspace(String),
    /// Frames larger than [`MAX_PIXELS`].
    #[error("{width}×{height} frames are larger than {MAX_PIXELS} pixels")]
    TooLarge {
        /// Declared width.
        width: u64,
        /// Declared height.
        height: u64,
    },
    /// A frame rate that is zero, infinite or out of range.
    #[error("frame rate {num}:{den} is out of range")]
    FrameRate {
        /// Numerator.
        num: usize,
        /// Denominator.
        den: usize,
    },
    /// The stream ends inside a frame.
    #[error("frame {0} is truncated")]
    Truncated(usize),
    /// Reading or writing failed.
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// BT.601 studio range, RGB → Y'CbCr, in the usual 8-bit fixed point (ITU-R BT.601
/// coefficients × 256, rounded): no float rounding call per pixel.
#[inline]
pub fn rgb_to_ycbcr([r, g, b]: [u8; 3]) -> [u8; 3] {
    let [r, g, b] = [r, g, b].map(i32::from);
    let y = ((66 * r + 129 * g + 25 * b + 128) >> 8) + 16;
    let cb = ((-38 * r - 74 * g + 112 * b + 128) >> 8) + 128;
    let cr = ((112 * r - 94 * g - 18 * b + 128) >> 8) + 128;
    [y, cb, cr].map(|v| v.clamp(0, 255) as u8)
}

/// The inverse of [`rgb_to_ycbcr`], same fixed point.
#[inline]
pub fn ycbcr_to_rgb([y, cb, cr]: [u8; 3]) -> [u8; 3] {
    let c = 298 * (i32::from(y) - 16) + 128;
    let (d, e) = (i32::from(cb) - 128, i32::from(cr) - 128);
    [c + 409 * e, c - 100 * d - 208 * e, c + 516 * d].map(|v| (v >> 8).clamp(0, 255) as u8)
}

/// Counts the bytes read through it, to tell a clean end of stream from a cut-off frame
/// (the crate reports both as end of file).
struct Counting<R> {
    inner: R,
    count: Arc<AtomicU64>,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
}

/// Chroma subsampling of a stream: (horizontal, vertical) divisors; `None` for mono.
type Subsampling = Option<(usize, usize)>;

/// A Y4M stream being read frame by frame.
pub struct Reader<R: Read> {
    decoder: y4m::Decoder<Counting<Chain<Cursor<Vec<u8>>, R>>>,
    width: u32,
    height: u32,
    fps: f64,
    subsampling: Subsampling,
    frames: usize,
    /// Bytes the decoder has read.
    count: Arc<AtomicU64>,
}

/// Reads the header line (at most 1 KiB) and checks the declared size before the crate
/// allocates for it.
fn header_line<R: Read>(input: &mut R) -> Result<Vec<u8>, Y4mError> {
    let mut line = Vec::new();
    let mut byte = [0u8];
    while line.len() < 1024 {
        if input.read(&mut byte)? == 0 {
            break;
        }
        line.push(byte[0]);
        if byte[0] == b'\n' {
            break;
        }
    }
    for field in line.split(|&b| b == b' ' || b == b'\n') {
        if let [tag @ (b'W' | b'H'), digits @ ..] = field {
            let v = std::str::from_utf8(digits)
                .ok()
                .and_then(|s| s.parse::<u64>().ok())
                .ok_or_else(|| Y4mError::Malformed(format!("bad {} field", *tag as char)))?;
            if v as usize > MAX_SIDE || v == 0 {
                let (width, height) = if *tag == b'W' { (v, 1) } else { (1, v) };
                return Err(Y4mError::TooLarge { width, height });
            }
        }
    }
    Ok(line)
}

impl<R: Read> Reader<R> {
    /// Reads and checks the stream header.
    pub fn new(mut input: R) -> Result<Self, Y4mError> {
        let line = header_line(&mut input)?;
        let count = Arc::new(AtomicU64::new(0));
        let counting = Counting {
            inner: Cursor::new(line).chain(input),
            count: Arc::clone(&count),
        };
        let limits = y4m::Limits {
            bytes: 3 * MAX_PIXELS as usize,
        };
        let decoder = y4m::Decoder::new_with_limits(counting, limits).map_err(|e| match e {
            y4m::Error::UnknownColorspace => Y4mError::Colorspace("(unknown)".into()),
            y4m::Error::OutOfMemory => Y4mError::TooLarge {
                width: 0,
                height: 0,
            },
            other => Y4mError::Malformed(other.to_string()),
        })?;
        let (w, h) = (decoder.get_width() as u64, decoder.get_height() as u64);
        if w * h > MAX_PIXELS {
            return Err(Y4mError::TooLarge {
                width: w,
                height: h,
            });
        }
        let rate = decoder.get_framerate();
        let fps = rate.num as f64 / rate.den as f64;
        if crate::facespace::check_fps(fps).is_err() {
            return Err(Y4mError::FrameRate {
                num: rate.num,
                den: rate.den,
            });
        }
        use y4m::Colorspace as C;
        let subsampling = match decoder.get_colorspace() {
            C::C444 => Some((1, 1)),
            C::C422 => Some((2, 1)),
            C::C420 | C::C420jpeg | C::C420paldv | C::C420mpeg2 => Some((2, 2)),
            C::Cmono => None,
            other => return Err(Y4mError::Colorspace(format!("{other:?}"))),
        };
        Ok(Reader {
            decoder,
            width: w as u32,
            height: h as u32,
            fps,
            subsampling,
            frames: 0,
            count,
        })
    }

    /// Size and frame rate (the stream does not state its length).
    pub fn info(&self) -> VideoInfo {
        VideoInfo {
            width: self.width,
            height: self.height,
            fps: self.fps,
            frames: None,
        }
    }

    /// The next frame, `None` at a clean end of stream.
    pub fn next_frame(&mut self) -> Result<Option<RgbImage>, Y4mError> {
        let count = Arc::clone(&self.count);
        let before = count.load(Ordering::Relaxed);
        let frame = match self.decoder.read_frame() {
            Ok(f) => f,
            Err(y4m::Error::EOF) if count.load(Ordering::Relaxed) == before => return Ok(None),
            Err(y4m::Error::EOF) => return Err(Y4mError::Truncated(self.frames)),
            Err(e) => return Err(Y4mError::Malformed(format!("frame {}: {e}", self.frames))),
        };
        let w = self.width as usize;
        let (luma, cb, cr) = (
            frame.get_y_plane(),
            frame.get_u_plane(),
            frame.get_v_plane(),
        );
        let mut image = RgbImage::new(self.width, self.height);
        match self.subsampling {
            Some((sx, sy)) => {
                let cw = w.div_ceil(sx);
                for (i, p) in image.pixels_mut().enumerate() {
                    let (x, y) = (i % w, i / w);
                    let c = (y / sy) * cw + x / sx;
                    p.0 = ycbcr_to_rgb([luma[i], cb[c], cr[c]]);
                }
            }
            None => {
                for (p, &l) in image.pixels_mut().zip(luma) {
                    p.0 = ycbcr_to_rgb([l, 128, 128]);
                }
            }
        }
        self.frames += 1;
        Ok(Some(image))
    }
}

/// The stream header line for `width × height` 4:4:4 frames at `fps`.
pub fn header(width: u32, height: u32, fps: f64) -> String {
    let (num, den) = ((fps * 1000.0).round() as u64, 1000u64);
    format!("YUV4MPEG2 W{width} H{height} F{num}:{den} Ip A1:1 C444\n")
}

/// Writes 4:4:4 frames after the stream header.
pub struct Writer<W: Write> {
    out: W,
    planes: Vec<u8>,
}

impl<W: Write> Writer<W> {
    /// Writes the header of a `width × height` stream at `fps`.
    pub fn new(mut out: W, width: u32, height: u32, fps: f64) -> Result<Self, Y4mError> {
        out.write_all(header(width, height, fps).as_bytes())?;
        Ok(Writer {
            out,
            planes: Vec::new(),
        })
    }

    /// Appends one frame.
    pub fn write(&mut self, frame: &RgbImage) -> Result<(), Y4mError> {
        let n = (frame.width() * frame.height()) as usize;
        self.planes.resize(3 * n, 0);
        for (i, p) in frame.pixels().enumerate() {
            let [y, cb, cr] = rgb_to_ycbcr(p.0);
            self.planes[i] = y;
            self.planes[n + i] = cb;
            self.planes[2 * n + i] = cr;
        }
        self.out.write_all(b"FRAME\n")?;
        self.out.write_all(&self.planes)?;
        Ok(())
    }

    /// The underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_conversion_round_trips_within_two_levels() {
        let mut worst = 0;
        for r in (0..=255).step_by(15) {
            for g in (0..=255).step_by(15) {
                for b in (0..=255).step_by(15) {
                    let back = ycbcr_to_rgb(rgb_to_ycbcr([r, g, b]));
                    for (x, y) in back.iter().zip([r, g, b]) {
                        worst = worst.max((*x as i32 - y as i32).abs());
                    }
                }
            }
        }
        assert!(worst <= 2, "worst {worst}");
    }

    #[test]
    fn stream_round_trips() {
        let frames: Vec<RgbImage> = (0..3)
            .map(|k| {
                RgbImage::from_fn(5, 3, |x, y| {
                    image::Rgb([x as u8 * 40, y as u8 * 60, k * 90])
                })
            })
            .collect();
        let mut writer = Writer::new(Vec::new(), 5, 3, 24.0).unwrap();
        for f in &frames {
            writer.write(f).unwrap();
        }
        let bytes = writer.into_inner();
        let mut reader = Reader::new(&bytes[..]).unwrap();
        assert_eq!((reader.width, reader.height, reader.fps), (5, 3, 24.0));
        for f in &frames {
            let back = reader.next_frame().unwrap().unwrap();
            for (a, b) in back.pixels().zip(f.pixels()) {
                for c in 0..3 {
                    assert!((a.0[c] as i32 - b.0[c] as i32).abs() <= 2);
                }
            }
        }
        assert!(reader.next_frame().unwrap().is_none());
        // A cut-off stream is an error, not a short frame.
        let mut cut = Reader::new(&bytes[..bytes.len() - 4]).unwrap();
        cut.next_frame().unwrap();
        cut.next_frame().unwrap();
        assert!(matches!(cut.next_frame(), Err(Y4mError::Truncated(2))));
        assert!(Reader::new(&b"RIFF"[..]).is_err());
    }

    #[test]
    fn hostile_headers_are_errors() {
        for header in [
            &b"YUV4MPEG2 W99999999999999999999 H2 F25:1\n"[..],
            b"YUV4MPEG2 W16384 H16384 F25:1 C444\n",
            b"YUV4MPEG2 W4 H4 F0:1 C444\n",
            b"YUV4MPEG2 W4 H4 F25:0 C444\n",
            b"YUV4MPEG2 W4 H4 F25:1 C444p10\n",
            b"YUV4MPEG2 W0 H4 F25:1\n",
        ] {
            assert!(
                Reader::new(header).is_err(),
                "{}",
                String::from_utf8_lossy(header)
            );
        }
        // A non-ASCII tag the reader does not know is ignored, not a panic.
        let ok = b"YUV4MPEG2 W2 H2 F25:1 \xc3\xa9 C444\nFRAME\n000000000000";
        assert!(
            Reader::new(&ok[..])
                .unwrap()
                .next_frame()
                .unwrap()
                .is_some()
        );
    }
}
