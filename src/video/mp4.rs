//! MP4 (H.264) without a system ffmpeg: OpenH264 (built from source by the `openh264` crate)
//! for the codec, the pure-Rust `mp4` crate for the container. Reads any H.264 track OpenH264
//! decodes (Baseline to High, B-frames included); writes Constrained Baseline 4:2:0 with an
//! IDR frame every two seconds, and copies an AAC audio track through untouched.

use std::collections::VecDeque;
use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::Path;

use image::RgbImage;
use openh264::decoder::{Decoder, DecoderConfig, Flush};
use openh264::encoder::{
    BitRate, Complexity, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, QpRange,
    RateControlMode,
};
use openh264::formats::{YUVSlices, YUVSource};

use thiserror::Error;

use crate::options::InvalidOption;

/// What can go wrong reading or writing an MP4.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Mp4Error {
    /// Reading or writing the file failed.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The container cannot be parsed.
    #[error("not a readable MP4 ({0})")]
    Container(#[from] mp4::Error),
    /// No track of the kind needed.
    #[error("no {0} track")]
    NoTrack(&'static str),
    /// OpenH264 failed.
    #[error("H.264: {0}")]
    Codec(#[from] openh264::Error),
    /// A sample the track lists is absent.
    #[error("sample {0} is missing (truncated file?)")]
    MissingSample(u32),
    /// A sample's NAL length prefixes do not fit it.
    #[error("sample {0}: malformed NAL lengths")]
    BadNal(u32),
    /// A sample could not be read or decoded.
    #[error("sample {id}: {source}")]
    Sample {
        /// The sample (1-based).
        id: u32,
        /// The cause.
        source: Box<Mp4Error>,
    },
    /// 4:2:0 needs even sides.
    #[error("H.264 4:2:0 needs even, non-zero width and height; got {width}×{height}")]
    OddSize {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// A frame of another size than the video.
    #[error("frame {index} is {width}×{height}, the video {expected:?}")]
    FrameSize {
        /// The frame.
        index: u64,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The video's size.
        expected: (u32, u32),
    },
    /// The encoder's first frame lacked its parameter sets.
    #[error("the encoder gave no SPS/PPS with its first frame")]
    NoParameterSets,
    /// Nothing to write.
    #[error("no frames to write")]
    NoFrames,
    /// An out-of-range frame rate.
    #[error(transparent)]
    Option(#[from] InvalidOption),
}

type Mp4File = mp4::Mp4Reader<BufReader<File>>;

fn open(path: &Path) -> Result<Mp4File, Mp4Error> {
    let file = File::open(path)?;
    let size = file.metadata()?.len();
    Ok(mp4::Mp4Reader::read_header(BufReader::new(file), size)?)
}

fn track_of(file: &Mp4File, kind: mp4::MediaType) -> Option<u32> {
    let mut ids: Vec<u32> = file
        .tracks()
        .iter()
        .filter(|(_, t)| t.media_type().ok() == Some(kind))
        .map(|(&id, _)| id)
        .collect();
    ids.sort();
    ids.first().copied()
}

/// The H.264 track of an MP4 file, decoded frame by frame in presentation order.
pub struct Reader {
    file: Mp4File,
    track: u32,
    next_sample: u32,
    samples: u32,
    length_size: usize,
    decoder: Decoder,
    pending: VecDeque<RgbImage>,
    flushed: bool,
    pub fps: f64,
    pub width: u32,
    pub height: u32,
}

impl Reader {
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
        let mut decoder = Decoder::with_api_config(
            openh264::OpenH264API::from_source(),
            DecoderConfig::new().flush_after_decode(Flush::NoFlush),
        )?;
        let mut head = Vec::new();
        for nal in [sps, pps] {
            head.extend_from_slice(&[0, 0, 0, 1]);
            head.extend_from_slice(nal);
        }
        decoder.decode(&head)?;
        Ok(Reader {
            file,
            track,
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

fn to_rgb(yuv: &openh264::decoder::DecodedYUV<'_>) -> RgbImage {
    let (w, h) = yuv.dimensions();
    let mut rgb = vec![0u8; w * h * 3];
    yuv.write_rgb8(&mut rgb);
    RgbImage::from_raw(w as u32, h as u32, rgb).expect("buffer sized for the frame")
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

/// An AAC track lifted out of an MP4, to be muxed into another unchanged.
pub struct AudioTrack {
    config: mp4::AacConfig,
    timescale: u32,
    samples: Vec<mp4::Mp4Sample>,
}

impl AudioTrack {
    /// The first AAC track of `path`, if it has one.
    pub fn read(path: &Path) -> Result<Option<Self>, Mp4Error> {
        let mut file = open(path)?;
        let Some(track) = track_of(&file, mp4::MediaType::AAC) else {
            return Ok(None);
        };
        let t = &file.tracks()[&track];
        let config = mp4::AacConfig {
            bitrate: t.bitrate(),
            profile: t.audio_profile()?,
            freq_index: t.sample_freq_index()?,
            chan_conf: t.channel_config()?,
        };
        let timescale = t.timescale();
        let samples = (1..=t.sample_count())
            .map(|id| {
                file.read_sample(track, id)?
                    .ok_or(Mp4Error::MissingSample(id))
            })
            .collect::<Result<_, _>>()?;
        Ok(Some(AudioTrack {
            config,
            timescale,
            samples,
        }))
    }

    /// The AAC packets, in order.
    pub fn packets(&self) -> Vec<Vec<u8>> {
        self.samples.iter().map(|s| s.bytes.to_vec()).collect()
    }

    fn add_to(&self, writer: &mut mp4::Mp4Writer<BufWriter<File>>, id: u32) -> mp4::Result<()> {
        writer.add_track(&mp4::TrackConfig {
            track_type: mp4::TrackType::Audio,
            timescale: self.timescale,
            language: "und".into(),
            media_conf: mp4::MediaConfig::AacConfig(self.config.clone()),
        })?;
        for s in &self.samples {
            writer.write_sample(id, s)?;
        }
        Ok(())
    }

    /// Writes the track alone as an `.m4a`-style MP4, atomically.
    pub fn save(&self, path: &Path) -> Result<(), Mp4Error> {
        let (tmp, mut writer) = start(path, 1000)?;
        self.add_to(&mut writer, 1)?;
        finish(tmp, writer, path)
    }
}

fn start(
    path: &Path,
    timescale: u32,
) -> Result<(tempfile::NamedTempFile, mp4::Mp4Writer<BufWriter<File>>), Mp4Error> {
    let tmp = crate::atomic::staging_file(path)?;
    let file = tmp.reopen()?;
    let config = mp4::Mp4Config {
        major_brand: str::parse("isom").expect("four letters"),
        minor_version: 512,
        compatible_brands: ["isom", "iso2", "avc1", "mp41"]
            .map(|b| str::parse(b).expect("four letters"))
            .to_vec(),
        timescale,
    };
    let writer = mp4::Mp4Writer::write_start(BufWriter::new(file), &config)?;
    Ok((tmp, writer))
}

fn finish(
    tmp: tempfile::NamedTempFile,
    mut writer: mp4::Mp4Writer<BufWriter<File>>,
    path: &Path,
) -> Result<(), Mp4Error> {
    writer.write_end()?;
    writer
        .into_writer()
        .into_inner()
        .map_err(|e| e.into_error())?;
    Ok(crate::atomic::persist(tmp, path)?)
}

/// Track ticks per frame: the timescale is fps × this, so 29.97 fps is exact to 1/1000.
const FRAME_TICKS: u32 = 1000;

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
    /// `width` and `height` must be even (4:2:0).
    pub fn create(path: &Path, width: u32, height: u32, fps: f64) -> Result<Self, Mp4Error> {
        if width == 0 || height == 0 || width % 2 == 1 || height % 2 == 1 {
            return Err(Mp4Error::OddSize { width, height });
        }
        // At least one tick per frame at the timescale fps × FRAME_TICKS.
        crate::options::in_range("frame rate", fps, 0.01, crate::facespace::MAX_FPS)?;
        let timescale = (fps * f64::from(FRAME_TICKS)).round() as u32;
        // About 0.25 bit per pixel: visually clean for faces; the codec report measures it.
        let bits = (f64::from(width * height) * fps * 0.25) as u32;
        let config = EncoderConfig::new()
            .bitrate(BitRate::from_bps(bits.max(100_000)))
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            .rate_control_mode(RateControlMode::Off)
            .qp(QpRange::new(12, 36))
            .skip_frames(false)
            // Speed over a few per cent of size: the faces are smooth and mostly static.
            .complexity(Complexity::Low)
            .background_detection(false)
            .scene_change_detect(false)
            .adaptive_quantization(false)
            .intra_frame_period(IntraFramePeriod::from_num_frames(
                ((2.0 * fps).round() as u32).max(1),
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
        finish(self.tmp, self.writer, path)?;
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
