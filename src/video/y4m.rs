//! YUV4MPEG2 (`.y4m`): the raw format every video tool reads and writes, and the pipe format
//! to and from a system ffmpeg. Written as 4:4:4; read as 4:4:4, 4:2:0 (every siting,
//! nearest-sample chroma) or mono. Studio-range BT.601 both ways.

use std::io::{BufRead, Write};

use image::RgbImage;

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

/// The stream header line.
pub fn header(width: u32, height: u32, fps: f64) -> String {
    let (num, den) = ((fps * 1000.0).round() as u64, 1000u64);
    format!("YUV4MPEG2 W{width} H{height} F{num}:{den} Ip A1:1 C444\n")
}

/// Appends one frame (4:4:4) to `out`.
pub fn write_frame(out: &mut impl Write, frame: &RgbImage) -> std::io::Result<()> {
    let n = (frame.width() * frame.height()) as usize;
    let mut planes = vec![0u8; 3 * n];
    for (i, p) in frame.pixels().enumerate() {
        let [y, cb, cr] = rgb_to_ycbcr(p.0);
        planes[i] = y;
        planes[n + i] = cb;
        planes[2 * n + i] = cr;
    }
    out.write_all(b"FRAME\n")?;
    out.write_all(&planes)
}

/// Largest frame accepted (8K UHD), so a corrupt header cannot ask for gigabytes.
const MAX_PIXELS: u64 = 7680 * 4320;

/// Chroma layout of a stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Chroma {
    C444,
    C420,
    Mono,
}

/// A Y4M stream being read frame by frame.
pub struct Reader<R> {
    input: R,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    chroma: Chroma,
    buffer: Vec<u8>,
}

impl<R: BufRead> Reader<R> {
    /// Reads and checks the stream header.
    pub fn new(mut input: R) -> Result<Self, String> {
        let mut line = Vec::new();
        input
            .read_until(b'\n', &mut line)
            .map_err(|e| e.to_string())?;
        let text = String::from_utf8_lossy(&line);
        let mut fields = text.split_ascii_whitespace();
        if fields.next() != Some("YUV4MPEG2") {
            return Err("not a YUV4MPEG2 stream".into());
        }
        let (mut width, mut height, mut fps, mut chroma) = (0u32, 0u32, 25.0, Chroma::C420);
        for f in fields {
            let (tag, value) = f.split_at(1);
            match tag {
                "W" => width = value.parse().map_err(|_| format!("bad width {value}"))?,
                "H" => height = value.parse().map_err(|_| format!("bad height {value}"))?,
                "F" => {
                    let (n, d) = value.split_once(':').unwrap_or((value, "1"));
                    let (n, d): (f64, f64) = (
                        n.parse().map_err(|_| format!("bad frame rate {value}"))?,
                        d.parse().map_err(|_| format!("bad frame rate {value}"))?,
                    );
                    fps = n / d;
                }
                "C" => {
                    chroma = match value {
                        "444" => Chroma::C444,
                        v if v.starts_with("420") => Chroma::C420,
                        "mono" => Chroma::Mono,
                        other => return Err(format!("unsupported chroma C{other}")),
                    }
                }
                _ => {}
            }
        }
        if width == 0 || height == 0 || !fps.is_finite() || fps <= 0.0 {
            return Err(format!("bad header: {}", text.trim()));
        }
        if u64::from(width) * u64::from(height) > MAX_PIXELS {
            return Err(format!(
                "{width}×{height} frames are larger than {MAX_PIXELS} pixels"
            ));
        }
        Ok(Reader {
            input,
            width,
            height,
            fps,
            chroma,
            buffer: Vec::new(),
        })
    }

    /// The next frame, `None` at a clean end of stream.
    pub fn next_frame(&mut self) -> Result<Option<RgbImage>, String> {
        let mut line = Vec::new();
        let n = self
            .input
            .read_until(b'\n', &mut line)
            .map_err(|e| e.to_string())?;
        if n == 0 {
            return Ok(None);
        }
        if !line.starts_with(b"FRAME") {
            return Err("expected a FRAME marker".into());
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let (cw, ch) = match self.chroma {
            Chroma::C444 => (w, h),
            Chroma::C420 => (w.div_ceil(2), h.div_ceil(2)),
            Chroma::Mono => (0, 0),
        };
        self.buffer.resize(w * h + 2 * cw * ch, 0);
        self.input
            .read_exact(&mut self.buffer)
            .map_err(|_| "truncated frame".to_string())?;
        let (luma, chroma) = self.buffer.split_at(w * h);
        let (cb, cr) = chroma.split_at(cw * ch);
        let mut image = RgbImage::new(self.width, self.height);
        for (i, p) in image.pixels_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            let c = match self.chroma {
                Chroma::C444 => i,
                Chroma::C420 => (y / 2) * cw + x / 2,
                Chroma::Mono => usize::MAX,
            };
            let (u, v) = if c == usize::MAX {
                (128, 128)
            } else {
                (cb[c], cr[c])
            };
            p.0 = ycbcr_to_rgb([luma[i], u, v]);
        }
        Ok(Some(image))
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
        let mut bytes = header(5, 3, 24.0).into_bytes();
        for f in &frames {
            write_frame(&mut bytes, f).unwrap();
        }
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
        assert!(cut.next_frame().unwrap_err().contains("truncated"));
        assert!(Reader::new(&b"RIFF"[..]).is_err());
    }
}
