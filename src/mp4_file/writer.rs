//! Encoding frames to an H.264 MP4 (Constrained Baseline 4:2:0).

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use image::RgbImage;
use openh264::encoder::{
    BitRate, Complexity, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, QpRange,
    RateControlMode,
};
use openh264::formats::YUVSlices;

use super::audio::{finish, start};
use super::{AudioTrack, Mp4Error};

/// Track ticks per frame: the timescale is fps × this, so 29.97 fps is exact to 1/1000.
const FRAME_TICKS: u32 = 1000;

/// The quantiser of the videos written for viewers ([`Writer::create`]: `say`, `synth`, the
/// demo, decoded clips): about the bit rate of the recordings a talker is made from (GRID s1's
/// clips, x264 at CRF 21: ≈ 240 kbit/s at 360×288; QP 20 gives ≈ 240 here). At OpenH264's
/// own quantiser (26, a third of the bits) the encoder smoothed away the recorded mouths'
/// detail: a discriminator told the drawn mouths from the recordings 0.95 of the time, against
/// 0.69 before encoding (BENCHMARKS.md, "What a viewer gets").
pub const VIEWING_QP: u8 = 20;

/// Seconds between keyframes of a video for viewers ([`Writer::create`]; see there).
pub const KEYFRAME_SECONDS: f64 = 10.0;

/// Seconds between keyframes of video kept as data ([`Writer::create_with_qp`]): decoded a
/// picture group at a time wherever a frame is wanted (a talker's recorded mouths), so short.
pub const DATA_KEYFRAME_SECONDS: f64 = 2.0;

/// Encodes frames to an H.264 MP4, written beside its destination and renamed into place on
/// [`Writer::finish`] (dropped unfinished, it leaves nothing behind).
pub struct Writer {
    tmp: tempfile::NamedTempFile,
    writer: mp4::Mp4Writer<BufWriter<File>>,
    encoder: Encoder,
    yuv: Vec<u8>,
    width: u32,
    height: u32,
    /// Ticks per second of the video track: fps × [`FRAME_TICKS`].
    timescale: u32,
    frames: u64,
    has_track: bool,
}

impl Writer {
    /// A writer for viewers: at [`VIEWING_QP`], a keyframe every [`KEYFRAME_SECONDS`] (at the
    /// same quantiser an I frame is drawn unlike the P frames before it, and the frame-to-frame
    /// change jumped 2.4× the source's at each one — a pulse a viewer sees every 2 s; issue 68,
    /// BENCHMARKS "Keyframes"); `width` and `height` must be even (4:2:0).
    pub fn create(path: &Path, width: u32, height: u32, fps: f64) -> Result<Self, Mp4Error> {
        Self::create_with(path, width, height, fps, VIEWING_QP, KEYFRAME_SECONDS)
    }

    /// A writer of video kept as data, whose fine detail is the point: at another quantiser
    /// for every frame (`qp`, 0–51; lower keeps more), a keyframe every
    /// [`DATA_KEYFRAME_SECONDS`] so any frame is reached by decoding a short picture group.
    pub fn create_with_qp(
        path: &Path,
        width: u32,
        height: u32,
        fps: f64,
        qp: u8,
    ) -> Result<Self, Mp4Error> {
        Self::create_with(path, width, height, fps, qp, DATA_KEYFRAME_SECONDS)
    }

    fn create_with(
        path: &Path,
        width: u32,
        height: u32,
        fps: f64,
        qp: u8,
        keyframe_seconds: f64,
    ) -> Result<Self, Mp4Error> {
        if width == 0 || height == 0 || width % 2 == 1 || height % 2 == 1 {
            return Err(Mp4Error::OddSize { width, height });
        }
        // At least one tick per frame at the timescale fps × FRAME_TICKS.
        crate::facespace::check_fps(fps)?;
        let timescale = (fps * f64::from(FRAME_TICKS)).round() as u32;
        // One quantiser: rate control on, with bits to spare (64 × a quarter bit per pixel),
        // held to it (with rate control off OpenH264 keeps its own default quantiser whatever
        // the range).
        let bits = ((f64::from(width * height) * fps * 0.25) as u32).saturating_mul(64);
        let config = EncoderConfig::new()
            .bitrate(BitRate::from_bps(bits.max(100_000)))
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            .rate_control_mode(RateControlMode::Bufferbased)
            .qp(QpRange::new(qp, qp))
            .skip_frames(false)
            // Speed over a few per cent of size: the faces are smooth and mostly static.
            .complexity(Complexity::Low)
            .background_detection(false)
            .scene_change_detect(false)
            .adaptive_quantization(false)
            .intra_frame_period(IntraFramePeriod::from_num_frames(
                ((keyframe_seconds * fps).round() as u32).max(1),
            ));
        let encoder = Encoder::with_api_config(openh264::OpenH264API::from_source(), config)?;
        let (tmp, writer) = start(path, timescale)?;
        Ok(Writer {
            tmp,
            writer,
            encoder,
            yuv: Vec::new(),
            width,
            height,
            timescale,
            frames: 0,
            has_track: false,
        })
    }

    /// Encodes one frame (of the video's size).
    pub fn write(&mut self, frame: &RgbImage) -> Result<(), Mp4Error> {
        if frame.dimensions() != (self.width, self.height) {
            return Err(Mp4Error::FrameSize {
                index: self.frames,
                width: frame.width(),
                height: frame.height(),
                expected: (self.width, self.height),
            });
        }
        let (w, h) = (self.width as usize, self.height as usize);
        rgb_to_yuv420(frame, &mut self.yuv);
        let (luma, chroma) = self.yuv.split_at(w * h);
        let (cb, cr) = chroma.split_at(w * h / 4);
        let source = YUVSlices::new((luma, cb, cr), (w, h), (w, w / 2, w / 2));
        let encoded = self.encoder.encode(&source)?;
        let is_sync = matches!(encoded.frame_type(), FrameType::IDR);
        let mut sample = Vec::new();
        let (mut sps, mut pps) = (None, None);
        for l in 0..encoded.num_layers() {
            let layer = encoded.layer(l).expect("layer index in range");
            for n in 0..layer.nal_count() {
                let nal = strip_start_code(layer.nal_unit(n).expect("nal index in range"));
                match nal.first().map(|b| b & 0x1f) {
                    Some(7) => sps = Some(nal.to_vec()),
                    Some(8) => pps = Some(nal.to_vec()),
                    Some(_) => {
                        sample.extend_from_slice(&(nal.len() as u32).to_be_bytes());
                        sample.extend_from_slice(nal);
                    }
                    None => {}
                }
            }
        }
        if !self.has_track {
            let (Some(sps), Some(pps)) = (sps, pps) else {
                return Err(Mp4Error::NoParameterSets);
            };
            self.writer.add_track(&mp4::TrackConfig {
                track_type: mp4::TrackType::Video,
                timescale: self.timescale,
                language: "und".into(),
                media_conf: mp4::MediaConfig::AvcConfig(mp4::AvcConfig {
                    width: self.width as u16,
                    height: self.height as u16,
                    seq_param_set: sps,
                    pic_param_set: pps,
                }),
            })?;
            self.has_track = true;
        }
        let sample = mp4::Mp4Sample {
            start_time: self.frames * u64::from(FRAME_TICKS),
            duration: FRAME_TICKS,
            rendering_offset: 0,
            is_sync,
            bytes: sample.into(),
        };
        self.writer.write_sample(1, &sample)?;
        self.frames += 1;
        Ok(())
    }

    /// Closes the file (muxing `audio` beside the video) and renames it into place.
    pub fn finish(mut self, path: &Path, audio: Option<&AudioTrack>) -> Result<u64, Mp4Error> {
        if self.frames == 0 {
            return Err(Mp4Error::NoFrames);
        }
        if let Some(a) = audio {
            a.add_to(&mut self.writer, 2)?;
        }
        let audio = audio.map(|a| (2, a.edit(), a.timescale()));
        finish(self.tmp, self.writer, path, audio)?;
        Ok(self.frames)
    }
}

fn strip_start_code(nal: &[u8]) -> &[u8] {
    nal.strip_prefix(&[0, 0, 0, 1])
        .or_else(|| nal.strip_prefix(&[0, 0, 1]))
        .unwrap_or(nal)
}

/// RGB → planar Y'CbCr 4:2:0, BT.601 studio range in the fixed point of
/// [`super::y4m::rgb_to_ycbcr`]: luma per pixel, chroma from each 2×2 block's mean RGB.
fn rgb_to_yuv420(frame: &RgbImage, out: &mut Vec<u8>) {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let (cw, ch) = (w / 2, h / 2);
    out.clear();
    out.resize(w * h + 2 * cw * ch, 0);
    let (luma, chroma) = out.split_at_mut(w * h);
    let (cb, cr) = chroma.split_at_mut(cw * ch);
    let raw = frame.as_raw();
    for (src, dst) in raw.chunks_exact(3 * w).zip(luma.chunks_exact_mut(w)) {
        for (p, l) in src.chunks_exact(3).zip(dst.iter_mut()) {
            let (r, g, b) = (i32::from(p[0]), i32::from(p[1]), i32::from(p[2]));
            *l = (((66 * r + 129 * g + 25 * b + 128) >> 8) + 16) as u8;
        }
    }
    for cy in 0..ch {
        let top = &raw[2 * cy * w * 3..(2 * cy + 1) * w * 3];
        let bottom = &raw[(2 * cy + 1) * w * 3..(2 * cy + 2) * w * 3];
        let (cb_row, cr_row) = (
            &mut cb[cy * cw..(cy + 1) * cw],
            &mut cr[cy * cw..(cy + 1) * cw],
        );
        for (cx, (u, v)) in cb_row.iter_mut().zip(cr_row.iter_mut()).enumerate() {
            let i = 6 * cx;
            let sum = |c: usize| {
                i32::from(top[i + c])
                    + i32::from(top[i + 3 + c])
                    + i32::from(bottom[i + c])
                    + i32::from(bottom[i + 3 + c])
            };
            let (r, g, b) = (sum(0), sum(1), sum(2));
            // Sums of four: the coefficients' fixed point grows by 2 bits.
            *u = (((-38 * r - 74 * g + 112 * b + 512) >> 10) + 128).clamp(0, 255) as u8;
            *v = (((112 * r - 94 * g - 18 * b + 512) >> 10) + 128).clamp(0, 255) as u8;
        }
    }
}
