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
