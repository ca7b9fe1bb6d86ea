//! Decoding the H.264 track of an MP4, frame by frame in presentation order.

use std::collections::VecDeque;
use std::path::Path;

use image::RgbImage;
use openh264::decoder::{Decoder, DecoderConfig, Flush};
use openh264::formats::YUVSource;

use super::{Mp4Error, Mp4File, open, track_of};

/// The H.264 track of an MP4 file, decoded frame by frame in presentation order.
pub struct Reader {
    file: Mp4File,
    track: u32,
    /// The parameter sets, as Annex B: what a decoder is given before the first sample.
    head: Vec<u8>,
    next_sample: u32,
    samples: u32,
    length_size: usize,
    decoder: Decoder,
    pending: VecDeque<RgbImage>,
    flushed: bool,
    /// Frames per second, from the media header.
    pub fps: f64,
    /// Frame width.
    pub width: u32,
    /// Frame height.
    pub height: u32,
}

impl Reader {
    /// Opens the first H.264 track of `path`.
    pub fn open(path: &Path) -> Result<Self, Mp4Error> {
        let file = open(path)?;
        let track =
            track_of(&file, mp4::MediaType::H264).ok_or(Mp4Error::NoTrack("H.264 video"))?;
        let t = &file.tracks()[&track];
        let sps = t.sequence_parameter_set()?;
        let pps = t.picture_parameter_set()?;
        let length_size = t
            .trak
            .mdia
            .minf
            .stbl
            .stsd
            .avc1
            .as_ref()
            .map_or(4, |a| a.avcc.length_size_minus_one as usize + 1);
        let samples = t.sample_count();
        // From the media header's own ticks (`Mp4Track::duration` rounds to milliseconds).
        let mdhd = &t.trak.mdia.mdhd;
        let fps = if mdhd.duration > 0 {
            samples as f64 * f64::from(mdhd.timescale) / mdhd.duration as f64
        } else {
            t.frame_rate()
        };
        let (width, height) = (u32::from(t.width()), u32::from(t.height()));
        let mut head = Vec::new();
        for nal in [sps, pps] {
            head.extend_from_slice(&[0, 0, 0, 1]);
            head.extend_from_slice(nal);
        }
        let decoder = decoder_after(&head)?;
        Ok(Reader {
            file,
            track,
            head,
            next_sample: 1,
            samples,
            length_size,
            decoder,
            pending: VecDeque::new(),
            flushed: false,
            fps,
            width,
            height,
        })
    }

    /// The frames (0-based) a decoder can start at: the sync samples (every frame when the
    /// track does not list them).
    pub fn sync_frames(&self) -> Vec<usize> {
        let stbl = &self.file.tracks()[&self.track].trak.mdia.minf.stbl;
        match &stbl.stss {
            // Sample numbers count from 1 (a 0 is malformed and left out).
            Some(stss) => stss.entries.iter().filter_map(|&s| (s as usize).checked_sub(1)).collect(),
            None => (0..self.samples as usize).collect(),
        }
    }

    /// Decodes from `frame` on, which must be one of [`Reader::sync_frames`]: pieces of one
    /// video decoded side by side.
    pub fn seek(&mut self, frame: usize) -> Result<(), Mp4Error> {
        if frame >= self.samples as usize || !self.sync_frames().contains(&frame) {
            return Err(Mp4Error::NotSync(frame));
        }
        self.decoder = decoder_after(&self.head)?;
        self.next_sample = frame as u32 + 1;
        self.pending.clear();
        self.flushed = false;
        Ok(())
    }

    /// Frames in the track (one per sample).
    pub fn frame_count(&self) -> usize {
        self.samples as usize
    }

    /// The next frame, `None` after the last.
    pub fn next_frame(&mut self) -> Result<Option<RgbImage>, Mp4Error> {
        while self.pending.is_empty() && self.next_sample <= self.samples {
            let id = self.next_sample;
            self.next_sample += 1;
            let in_sample = |source: Mp4Error| Mp4Error::Sample {
                id,
                source: Box::new(source),
            };
            let sample = self
                .file
                .read_sample(self.track, id)
                .map_err(|e| in_sample(e.into()))?
                .ok_or(Mp4Error::MissingSample(id))?;
            let annex_b =
                to_annex_b(&sample.bytes, self.length_size).ok_or(Mp4Error::BadNal(id))?;
            let decoded = self
                .decoder
                .decode(&annex_b)
                .map_err(|e| in_sample(e.into()))?;
            if let Some(yuv) = decoded {
                self.pending.push_back(to_rgb(&yuv));
            }
        }
        if self.pending.is_empty() && !self.flushed {
            self.flushed = true;
            let rest = self.decoder.flush_remaining()?;
            self.pending.extend(rest.iter().map(to_rgb));
        }
        Ok(self.pending.pop_front())
    }
}

/// A decoder that has taken the parameter sets `head`.
fn decoder_after(head: &[u8]) -> Result<Decoder, Mp4Error> {
    let mut decoder = Decoder::with_api_config(
        openh264::OpenH264API::from_source(),
        DecoderConfig::new().flush_after_decode(Flush::NoFlush),
    )?;
    decoder.decode(head)?;
    Ok(decoder)
}

fn to_rgb(yuv: &openh264::decoder::DecodedYUV<'_>) -> RgbImage {
    let (w, h) = yuv.dimensions();
    let mut rgb = vec![0u8; w * h * 3];
    if w % 8 == 0 && h >= 2 {
        // openh264's SIMD path.
        yuv.write_rgb8(&mut rgb);
    } else {
        // openh264 would take its scalar path, whose `mul_add`s are software calls on a
        // CPU build without FMA (a talker's 126-wide mouth store spent most of its loading
        // there): the same pixels, computed as below.
        yuv420_to_rgb([yuv.y(), yuv.u(), yuv.v()], (w, h), yuv.strides(), &mut rgb);
    }
    RgbImage::from_raw(w as u32, h as u32, rgb).expect("buffer sized for the frame")
}

// openh264's limited-range BT.601 coefficients (`formats::yuv2rgb`).
const Y_MUL: f32 = 255.0 / 219.0;
const RV_MUL: f32 = 255.0 / 224.0 * 1.402;
const GV_MUL: f32 = -255.0 / 224.0 * 1.402 * 0.299 / 0.587;
const GU_MUL: f32 = -255.0 / 224.0 * 1.772 * 0.114 / 0.587;
const BU_MUL: f32 = 255.0 / 224.0 * 1.772;

/// Limited-range BT.601, YUV 4:2:0 to RGB, to the bit as openh264's scalar path
/// (`formats::yuv2rgb::write_yuv420_float`) gives it: `Y_MUL·(y − 16)` rounded to f32, then
/// the fused multiply-adds `RV·v + y`, `GV·v + (GU·u + y)` and `BU·u + y`, each rounded
/// once to f32, clamped to 0..=255 and truncated. Those sums are exact in f64 (each term a
/// multiple of 2⁻²⁵ — the ulp of the smallest coefficient — below 2¹⁰: 35 bits), so one
/// rounding from f64 to f32 is the fused result.
fn yuv420_to_rgb(
    [y_plane, u_plane, v_plane]: [&[u8]; 3],
    (width, height): (usize, usize),
    (y_stride, u_stride, v_stride): (usize, usize, usize),
    rgb: &mut [u8],
) {
    let luma: [f64; 256] = std::array::from_fn(|y| f64::from(Y_MUL * (y as f32 - 16.0)));
    let byte = |v: f64| (v as f32).clamp(0.0, 255.0) as u8;
    for (row, out) in rgb.chunks_exact_mut(3 * width).take(height).enumerate() {
        let ys = &y_plane[row * y_stride..][..width];
        let us = &u_plane[row / 2 * u_stride..];
        let vs = &v_plane[row / 2 * v_stride..];
        for (x, (px, &y)) in out.chunks_exact_mut(3).zip(ys).enumerate() {
            let u = f64::from(us[x / 2]) - 128.0;
            let v = f64::from(vs[x / 2]) - 128.0;
            let y = luma[y as usize];
            let gu = f64::from((f64::from(GU_MUL) * u + y) as f32);
            px[0] = byte(f64::from(RV_MUL) * v + y);
            px[1] = byte(f64::from(GV_MUL) * v + gu);
            px[2] = byte(f64::from(BU_MUL) * u + y);
        }
    }
}

/// Length-prefixed NAL units (MP4) → start-code-prefixed (Annex B).
fn to_annex_b(mut bytes: &[u8], length_size: usize) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(bytes.len() + 16);
    while !bytes.is_empty() {
        if bytes.len() < length_size {
            return None;
        }
        let n = bytes[..length_size]
            .iter()
            .fold(0usize, |acc, &b| acc << 8 | b as usize);
        let nal = bytes.get(length_size..length_size + n)?;
        out.extend_from_slice(&[0, 0, 0, 1]);
        out.extend_from_slice(nal);
        bytes = &bytes[length_size + n..];
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// openh264's scalar expression itself (`write_yuv420_float`), fused multiply-adds and all.
    fn fused(y: u8, u: u8, v: u8) -> [u8; 3] {
        let (u, v) = (f32::from(u) - 128.0, f32::from(v) - 128.0);
        let y = Y_MUL * (f32::from(y) - 16.0);
        [
            RV_MUL.mul_add(v, y),
            GV_MUL.mul_add(v, GU_MUL.mul_add(u, y)),
            BU_MUL.mul_add(u, y),
        ]
        .map(|c| c.clamp(0.0, 255.0) as u8)
    }

    #[test]
    fn every_yuv_triple_converts_as_openh264_fuses_it() {
        let ys: Vec<u8> = (0..=255).collect();
        let mut rgb = vec![0u8; 3 * 256];
        for u in 0..=255u8 {
            for v in 0..=255u8 {
                yuv420_to_rgb([&ys, &[u; 128], &[v; 128]], (256, 1), (256, 128, 128), &mut rgb);
                for (y, px) in rgb.chunks_exact(3).enumerate() {
                    assert_eq!(px, fused(y as u8, u, v), "y {y} u {u} v {v}");
                }
            }
        }
    }

    /// A frame of the GRID talker's mouth store (126 wide: openh264's scalar path) decoded
    /// by openh264 and converted by it and by us: the same bytes.
    #[test]
    fn a_frame_of_odd_width_decodes_as_openh264_converts_it() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/grid/mouths/mouths.mp4");
        let mut reader = Reader::open(&path).unwrap();
        assert_ne!(reader.width % 8, 0);
        let sample = reader.file.read_sample(reader.track, 1).unwrap().unwrap();
        let annex_b = to_annex_b(&sample.bytes, reader.length_size).unwrap();
        // A sync frame without reordering: out at once.
        let yuv = reader.decoder.decode(&annex_b).unwrap().unwrap();
        let mut theirs = vec![0u8; 3 * (reader.width * reader.height) as usize];
        yuv.write_rgb8(&mut theirs);
        assert!(theirs == to_rgb(&yuv).into_raw(), "the conversions differ");
        assert!(theirs.iter().any(|&b| b > 0));
    }
}
