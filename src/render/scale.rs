//! A finished picture in another size: the talker's frames in the size a video call or a
//! voice agent's track asks for (512×512, 1280×720), the aspect ratio kept.
//!
//! The resampling is separable with a triangle kernel widened by the shrink factor (bilinear
//! when enlarging, an area-like average when shrinking — what `image`'s `Triangle` filter
//! does), its taps computed once per size so a frame costs only multiply-adds in fixed point.

use image::RgbImage;

use crate::shape::Point;

/// How a picture fills a frame of another aspect ratio.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Fit {
    /// All of the picture, centred, with black bars where the aspect ratios differ.
    #[default]
    Contain,
    /// The frame filled, the picture's excess (centred) cut off.
    Cover,
}

impl std::str::FromStr for Fit {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "contain" => Ok(Fit::Contain),
            "cover" => Ok(Fit::Cover),
            _ => Err(format!("fit {s:?}: contain or cover")),
        }
    }
}

/// Weights are fixed point with this many fractional bits.
const BITS: u32 = 14;

/// One output sample's taps: the first source index and its weights (sum `1 << BITS`).
#[derive(Clone, Debug)]
struct Taps {
    first: usize,
    weights: Vec<i32>,
}

/// Taps of a triangle kernel mapping source samples `from` (offset `start`, `len` long, in
/// source pixels) onto `to` output samples.
fn taps(source: usize, start: f64, len: f64, to: usize) -> Vec<Taps> {
    let scale = len / to as f64;
    let support = scale.max(1.0);
    (0..to)
        .map(|i| {
            let centre = start + (i as f64 + 0.5) * scale - 0.5;
            let lo = ((centre - support).floor() as isize + 1).max(0) as usize;
            let hi = ((centre + support).ceil() as isize - 1).min(source as isize - 1).max(lo as isize) as usize;
            let raw: Vec<f64> = (lo..=hi)
                .map(|j| (1.0 - (j as f64 - centre).abs() / support).max(0.0))
                .collect();
            let sum: f64 = raw.iter().sum();
            let mut weights: Vec<i32> = raw
                .iter()
                .map(|w| if sum > 0.0 { (w / sum * f64::from(1 << BITS)).round() as i32 } else { 0 })
                .collect();
            // The rounding's remainder on the largest weight, so a flat picture stays flat.
            let rest = (1 << BITS) - weights.iter().sum::<i32>();
            if let Some(k) = (0..weights.len()).max_by_key(|&k| weights[k]) {
                weights[k] += rest;
            } else {
                weights.push(1 << BITS);
            }
            Taps { first: lo, weights }
        })
        .collect()
}

/// A picture size mapped onto a frame size ([`Fit`]), with its taps.
#[derive(Clone, Debug)]
pub struct Scaler {
    from: (u32, u32),
    to: (u32, u32),
    /// Where the picture lands in the frame: x0, y0, width, height (Contain), or the frame
    /// itself (Cover).
    area: (u32, u32, u32, u32),
    /// Frame pixel = picture pixel × scale + offset.
    scale: f64,
    offset: [f64; 2],
    columns: Vec<Taps>,
    rows: Vec<Taps>,
}

impl Scaler {
    /// Pictures of `from` (width, height) drawn into frames of `to`, fitted by `fit`.
    pub fn new(from: (u32, u32), to: (u32, u32), fit: Fit) -> Self {
        let (fw, fh) = (f64::from(from.0.max(1)), f64::from(from.1.max(1)));
        let (tw, th) = (f64::from(to.0.max(1)), f64::from(to.1.max(1)));
        let scale = match fit {
            Fit::Contain => (tw / fw).min(th / fh),
            Fit::Cover => (tw / fw).max(th / fh),
        };
        // The picture's size in the frame, and its top-left corner (negative: cut off).
        let (w, h) = ((fw * scale).round().min(tw), (fh * scale).round().min(th));
        let offset = [(tw - fw * scale) / 2.0, (th - fh * scale) / 2.0];
        let (x0, y0) = (offset[0].max(0.0).round(), offset[1].max(0.0).round());
        // The source span each covered frame pixel samples.
        let span = |frame_start: f64, n: f64, off: f64| ((frame_start - off) / scale, n / scale);
        let (sx, sw) = span(x0, w, offset[0]);
        let (sy, sh) = span(y0, h, offset[1]);
        Scaler {
            from,
            to,
            area: (x0 as u32, y0 as u32, w as u32, h as u32),
            scale,
            offset,
            columns: taps(from.0 as usize, sx, sw, w as usize),
            rows: taps(from.1 as usize, sy, sh, h as usize),
        }
    }

    /// The frame size.
    pub fn size(&self) -> (u32, u32) {
        self.to
    }

    /// Whether frames are the pictures as they are.
    pub fn is_identity(&self) -> bool {
        self.from == self.to
    }

    /// A picture point in frame pixels.
    pub fn point(&self, p: Point) -> Point {
        [p[0] * self.scale + self.offset[0], p[1] * self.scale + self.offset[1]]
    }

    /// `picture` (of the size given to [`Scaler::new`]) drawn into `frame` (the frame size),
    /// black where the picture does not reach.
    pub fn scale_into(&self, picture: &RgbImage, frame: &mut RgbImage) {
        assert_eq!(picture.dimensions(), self.from, "picture size");
        assert_eq!(frame.dimensions(), self.to, "frame size");
        if self.is_identity() {
            frame.copy_from_slice(picture);
            return;
        }
        let (x0, y0, w, _) = self.area;
        let src_w = self.from.0 as usize * 3;
        let dst_w = self.to.0 as usize * 3;
        let src: &[u8] = picture.as_raw();
        let dst: &mut [u8] = frame;
        dst.fill(0);
        let mut line = vec![0i32; src_w];
        let round = 1i64 << (2 * BITS - 1);
        for (r, row) in self.rows.iter().enumerate() {
            // Vertical pass into one source-width line (still scaled by 1 << BITS).
            line.iter_mut().for_each(|v| *v = 0);
            for (k, &wy) in row.weights.iter().enumerate() {
                let s = &src[(row.first + k) * src_w..][..src_w];
                for (v, &b) in line.iter_mut().zip(s) {
                    *v += wy * i32::from(b);
                }
            }
            let out = &mut dst[(y0 as usize + r) * dst_w + x0 as usize * 3..][..w as usize * 3];
            for (c, col) in self.columns.iter().enumerate() {
                let mut acc = [round; 3];
                for (k, &wx) in col.weights.iter().enumerate() {
                    let p = (col.first + k) * 3;
                    for (ch, a) in acc.iter_mut().enumerate() {
                        *a += i64::from(wx) * i64::from(line[p + ch]);
                    }
                }
                for (ch, a) in acc.iter().enumerate() {
                    out[c * 3 + ch] = (a >> (2 * BITS)).clamp(0, 255) as u8;
                }
            }
        }
    }

    /// [`Scaler::scale_into`] a new frame.
    pub fn scale(&self, picture: &RgbImage) -> RgbImage {
        let mut frame = RgbImage::new(self.to.0, self.to.1);
        self.scale_into(picture, &mut frame);
        frame
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 2) as u8, (y * 3) as u8, 77]))
    }

    /// Against `image`'s own triangle-filter resize (an independent implementation of the
    /// same kernel): within 1 grey level, enlarging and shrinking.
    #[test]
    fn matches_image_triangle_resize() {
        let picture = RgbImage::from_fn(90, 72, |x, y| {
            image::Rgb([((x * 7 + y * 3) % 256) as u8, ((x * y) % 256) as u8, (255 - x) as u8])
        });
        for to in [(225, 180), (45, 36), (30, 24)] {
            let exact = image::imageops::resize(&picture, to.0, to.1, image::imageops::FilterType::Triangle);
            // A frame of the picture's own aspect ratio: the picture fills it.
            let ours = Scaler::new((90, 72), to, Fit::Contain).scale(&picture);
            let worst = ours
                .as_raw()
                .iter()
                .zip(exact.as_raw())
                .map(|(a, b)| a.abs_diff(*b))
                .max()
                .unwrap();
            assert!(worst <= 1, "{to:?}: worst {worst}");
        }
    }

    /// A linear ramp stays linear when enlarged (bilinear reproduces it away from the edges),
    /// and a flat picture stays flat at any size.
    #[test]
    fn ramps_and_flats() {
        let scaler = Scaler::new((100, 80), (250, 200), Fit::Contain);
        let big = scaler.scale(&ramp(100, 80));
        for y in [20u32, 100, 180] {
            for x in [20u32, 125, 230] {
                let p = big.get_pixel(x, y);
                let sx = (f64::from(x) + 0.5) / 2.5 - 0.5;
                let sy = (f64::from(y) + 0.5) / 2.5 - 0.5;
                assert!((f64::from(p[0]) - 2.0 * sx).abs() <= 1.0, "x ramp at {x},{y}: {}", p[0]);
                assert!((f64::from(p[1]) - 3.0 * sy).abs() <= 1.0, "y ramp at {x},{y}: {}", p[1]);
            }
        }
        let flat = RgbImage::from_pixel(37, 23, image::Rgb([200, 13, 99]));
        for to in [(512, 512), (1280, 720), (20, 11)] {
            let s = Scaler::new((37, 23), to, Fit::Cover).scale(&flat);
            assert!(s.pixels().all(|p| p.0 == [200, 13, 99]), "{to:?}");
        }
    }

    /// Contain: the whole picture centred between black bars, its points mapped with it;
    /// cover: the frame filled, the picture's centre at the frame's centre.
    #[test]
    fn contain_bars_and_cover_crop() {
        let picture = RgbImage::from_pixel(360, 288, image::Rgb([255, 255, 255]));
        let contain = Scaler::new((360, 288), (1280, 720), Fit::Contain);
        let frame = contain.scale(&picture);
        // 360×288 × 2.5 = 900×720: bars of 190 px either side.
        assert_eq!(frame.get_pixel(189, 360).0, [0, 0, 0]);
        assert_eq!(frame.get_pixel(190, 360).0, [255, 255, 255]);
        assert_eq!(frame.get_pixel(1089, 360).0, [255, 255, 255]);
        assert_eq!(frame.get_pixel(1090, 360).0, [0, 0, 0]);
        assert_eq!(contain.point([0.0, 0.0]), [190.0, 0.0]);
        assert_eq!(contain.point([360.0, 288.0]), [1090.0, 720.0]);
        let cover = Scaler::new((360, 288), (512, 512), Fit::Cover);
        assert!(cover.scale(&picture).pixels().all(|p| p.0 == [255, 255, 255]));
        let c = cover.point([180.0, 144.0]);
        assert!((c[0] - 256.0).abs() < 1e-9 && (c[1] - 256.0).abs() < 1e-9);
        assert!(Scaler::new((360, 288), (360, 288), Fit::Contain).is_identity());
    }
}
