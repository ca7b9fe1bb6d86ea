//! An AAC track: copied packet for packet from one MP4 into another, or encoded from samples
//! (Fraunhofer FDK AAC, built from source by the `fdk-aac` crate), with the edit list that
//! says which decoded samples are heard — so that the sound starts with the video.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use super::{Mp4Error, open, track_of};

/// Which decoded samples of a track are heard, in the track's own timescale: `skip` priming
/// samples first (the encoder's delay), then `keep` samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edit {
    /// Samples decoded before time 0.
    pub skip: u64,
    /// Samples heard.
    pub keep: u64,
}

/// An AAC track, to be muxed beside a video.
pub struct AudioTrack {
    config: mp4::AacConfig,
    timescale: u32,
    samples: Vec<mp4::Mp4Sample>,
    edit: Option<Edit>,
}

/// AAC's sampling frequencies (ISO/IEC 14496-3 Table 1.18), ascending.
pub const AAC_RATES: [u32; 9] = [
    8_000, 11_025, 12_000, 16_000, 22_050, 24_000, 32_000, 44_100, 48_000,
];

impl AudioTrack {
    /// Encodes mono 16-bit PCM at one of [`AAC_RATES`] as AAC-LC (CBR, 48 kb/s below 32 kHz,
    /// else 64 kb/s), with an edit list that drops the encoder's delay and the padding of the
    /// last frame: decoded, the track is `pcm` sample for sample in time.
    pub fn encode(pcm: &[i16], rate: u32) -> Result<Self, Mp4Error> {
        use fdk_aac::enc::{
            AudioObjectType, BitRate, ChannelMode, Encoder, EncoderParams, Transport,
        };
        if !AAC_RATES.contains(&rate) {
            return Err(Mp4Error::AudioCodec(format!("{rate} Hz is not an AAC sampling rate")));
        }
        let codec = |e: fdk_aac::enc::EncoderError| Mp4Error::AudioCodec(format!("{e:?}"));
        let encoder = Encoder::new(EncoderParams {
            bit_rate: BitRate::Cbr(if rate < 32_000 { 48_000 } else { 64_000 }),
            sample_rate: rate,
            transport: Transport::Raw,
            channels: ChannelMode::Mono,
            audio_object_type: AudioObjectType::Mpeg4LowComplexity,
        })
        .map_err(codec)?;
        let info = encoder.info().map_err(codec)?;
        let frame = info.frameLength as usize;
        let delay = info.nDelay as u64;
        // Zeros after the end flush the encoder's delay line (the crate cannot signal the end).
        let padded_len = (pcm.len() + delay as usize).div_ceil(frame) * frame + frame;
        let mut input = pcm.to_vec();
        input.resize(padded_len, 0);
        let mut out = vec![0u8; info.maxOutBufBytes.max(8192) as usize];
        let mut samples = Vec::new();
        let mut at = 0;
        while at < input.len() {
            let chunk = &input[at..(at + frame).min(input.len())];
            let result = encoder.encode(chunk, &mut out).map_err(codec)?;
            at += result.input_consumed.max(1).min(chunk.len());
            if result.output_size > 0 {
                samples.push(mp4::Mp4Sample {
                    start_time: samples.len() as u64 * frame as u64,
                    duration: frame as u32,
                    rendering_offset: 0,
                    is_sync: true,
                    bytes: out[..result.output_size].to_vec().into(),
                });
            }
        }
        // Only whole frames that hold heard samples are kept.
        let needed = (pcm.len() as u64 + delay).div_ceil(frame as u64) as usize;
        samples.truncate(needed.max(1));
        let freq_index = mp4::SampleFreqIndex::try_from(
            [
                96_000u32, 88_200, 64_000, 48_000, 44_100, 32_000, 24_000, 22_050, 16_000, 12_000,
                11_025, 8_000,
            ]
            .iter()
            .position(|&r| r == rate)
            .expect("an AAC rate") as u8,
        )?;
        Ok(AudioTrack {
            config: mp4::AacConfig {
                bitrate: if rate < 32_000 { 48_000 } else { 64_000 },
                profile: mp4::AudioObjectType::AacLowComplexity,
                freq_index,
                chan_conf: mp4::ChannelConfig::Mono,
            },
            timescale: rate,
            samples,
            edit: Some(Edit {
                skip: delay,
                keep: pcm.len() as u64,
            }),
        })
    }

    /// The edit list, when the track has one.
    pub fn edit(&self) -> Option<Edit> {
        self.edit
    }

    /// Samples per second of the track.
    pub fn timescale(&self) -> u32 {
        self.timescale
    }

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
        let edit = audio_edit(path)?;
        let samples: Vec<mp4::Mp4Sample> = (1..=t.sample_count())
            .map(|id| {
                file.read_sample(track, id)?
                    .ok_or(Mp4Error::MissingSample(id))
            })
            .collect::<Result<_, _>>()?;
        // An edit list without a duration keeps everything after the priming.
        let total: u64 = samples.iter().map(|s| s.duration as u64).sum();
        let edit = edit.map(|(skip, keep)| {
            let scale = timescale as f64;
            let skip = (skip * scale).round() as u64;
            Edit {
                skip,
                keep: keep.map_or(total.saturating_sub(skip), |k| (k * scale).round() as u64),
            }
        });
        Ok(Some(AudioTrack {
            config,
            timescale,
            samples,
            edit,
        }))
    }

    /// The AAC packets, in order.
    pub fn packets(&self) -> Vec<Vec<u8>> {
        self.samples.iter().map(|s| s.bytes.to_vec()).collect()
    }

    pub(super) fn add_to(
        &self,
        writer: &mut mp4::Mp4Writer<BufWriter<File>>,
        id: u32,
    ) -> mp4::Result<()> {
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
        let (tmp, mut writer) = start(path, MOVIE_TIMESCALE)?;
        self.add_to(&mut writer, 1)?;
        finish(tmp, writer, path, Some((1, self.edit, self.timescale)))
    }
}

pub(super) fn start(
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

/// Ticks per second of the movie (and of edit-list durations).
pub(super) const MOVIE_TIMESCALE: u32 = 1000;

/// Ends the file; the audio track `audio` = (track id, its edit list, its timescale) is
/// mended before the file is renamed into place: its SL config descriptor says "MP4" (2, as
/// ISO/IEC 14496-14 requires; the mp4 crate writes 0, which strict demuxers refuse), and its
/// edit list is written as an `edts`/`elst` box.
pub(super) fn finish(
    tmp: tempfile::NamedTempFile,
    mut writer: mp4::Mp4Writer<BufWriter<File>>,
    path: &Path,
    audio: Option<(u32, Option<Edit>, u32)>,
) -> Result<(), Mp4Error> {
    writer.write_end()?;
    writer
        .into_writer()
        .into_inner()
        .map_err(|e| e.into_error())?;
    if let Some((track, edit, timescale)) = audio {
        let mut bytes = std::fs::read(tmp.path())?;
        mark_sl_config_mp4(&mut bytes);
        if let Some(edit) = edit {
            insert_edit_list(&mut bytes, track, edit, timescale)?;
        }
        std::fs::write(tmp.path(), &bytes)?;
        tmp.as_file().sync_all()?;
    }
    Ok(crate::atomic::persist(tmp, path)?)
}

/// Makes every `esds` box's SL config descriptor (tag 6) `06 01 02`: one byte,
/// `predefined = 2`. The mp4 crate writes `06 00 00` (a zero length, then a stray 0).
fn mark_sl_config_mp4(bytes: &mut [u8]) {
    let mut from = 0;
    while let Some(i) = bytes[from..].windows(4).position(|w| w == b"esds") {
        let at = from + i;
        let size = at
            .checked_sub(4)
            .map(|s| u32::from_be_bytes(bytes[s..at].try_into().unwrap()) as usize)
            .unwrap_or(0);
        let end = (at - 4 + size).min(bytes.len());
        if let Some(j) = bytes[at..end]
            .windows(3)
            .rposition(|w| w == [0x06, 0x01, 0x00] || w == [0x06, 0x00, 0x00])
            .filter(|&j| at + j + 3 == end)
        {
            bytes[at + j + 1] = 0x01;
            bytes[at + j + 2] = 0x02;
        }
        from = at + 4;
    }
}

/// Big-endian box walk over `bytes[start..end]`: (type, box start, box end).
fn boxes(bytes: &[u8], start: usize, end: usize) -> Vec<([u8; 4], usize, usize)> {
    let mut out = Vec::new();
    let mut at = start;
    while at + 8 <= end {
        let size = u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
        if size < 8 || at + size > end {
            break;
        }
        out.push((bytes[at + 4..at + 8].try_into().unwrap(), at, at + size));
        at += size;
    }
    out
}

/// Inserts `edts`/`elst` (one entry: `edit.keep` samples from media time `edit.skip`) after
/// the `tkhd` of track `track`, growing `trak` and `moov`. The `moov` must follow `mdat` (as
/// the mp4 crate writes it), so no chunk offset moves.
fn insert_edit_list(
    bytes: &mut Vec<u8>,
    track: u32,
    edit: Edit,
    timescale: u32,
) -> Result<(), Mp4Error> {
    let bad = |why: &str| {
        Mp4Error::Io(std::io::Error::other(format!(
            "writing the edit list: {why}"
        )))
    };
    let top = boxes(bytes, 0, bytes.len());
    let (_, moov_start, moov_end) = *top
        .iter()
        .find(|b| &b.0 == b"moov")
        .ok_or_else(|| bad("no moov"))?;
    if top.iter().any(|b| &b.0 == b"mdat" && b.1 > moov_start) {
        return Err(bad("moov precedes mdat"));
    }
    let children = boxes(bytes, moov_start + 8, moov_end);
    let mvhd = children
        .iter()
        .find(|b| &b.0 == b"mvhd")
        .ok_or_else(|| bad("no mvhd"))?;
    let v = bytes[mvhd.1 + 8];
    let ts_at = mvhd.1 + 12 + if v == 1 { 16 } else { 8 };
    let movie_scale = u32::from_be_bytes(bytes[ts_at..ts_at + 4].try_into().unwrap()).max(1);
    for &(kind, trak_start, trak_end) in &children {
        if &kind != b"trak" {
            continue;
        }
        let inner = boxes(bytes, trak_start + 8, trak_end);
        let Some(&(_, tkhd_start, tkhd_end)) = inner.iter().find(|b| &b.0 == b"tkhd") else {
            continue;
        };
        let v = bytes[tkhd_start + 8];
        let id_at = tkhd_start + 12 + if v == 1 { 16 } else { 8 };
        let id = u32::from_be_bytes(bytes[id_at..id_at + 4].try_into().unwrap());
        if id != track || inner.iter().any(|b| &b.0 == b"edts") {
            continue;
        }
        let duration =
            (edit.keep as f64 * movie_scale as f64 / timescale.max(1) as f64).round() as u32;
        let media_time = u32::try_from(edit.skip).map_err(|_| bad("priming too long"))?;
        let mut edts = Vec::with_capacity(36);
        edts.extend_from_slice(&36u32.to_be_bytes());
        edts.extend_from_slice(b"edts");
        edts.extend_from_slice(&28u32.to_be_bytes());
        edts.extend_from_slice(b"elst");
        edts.extend_from_slice(&0u32.to_be_bytes()); // version 0, no flags
        edts.extend_from_slice(&1u32.to_be_bytes()); // one entry
        edts.extend_from_slice(&duration.to_be_bytes());
        edts.extend_from_slice(&media_time.to_be_bytes());
        edts.extend_from_slice(&0x0001_0000u32.to_be_bytes()); // rate 1.0
        let grow = |bytes: &mut Vec<u8>, at: usize| {
            let size = u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap()) + 36;
            bytes[at..at + 4].copy_from_slice(&size.to_be_bytes());
        };
        grow(bytes, trak_start);
        grow(bytes, moov_start);
        bytes.splice(tkhd_end..tkhd_end, edts);
        return Ok(());
    }
    Err(bad("no such track"))
}

/// The audible part of an MP4's first AAC track by its edit list, in seconds: `(skip, keep)`
/// — the encoder's priming to drop at the start (`media_time`) and how much to keep after it
/// (`segment_duration`, `None` when the list does not say). `None` when there is no AAC
/// track; `(0, None)` when there is no edit list.
pub fn audio_edit(path: &Path) -> Result<Option<(f64, Option<f64>)>, Mp4Error> {
    let file = open(path)?;
    let Some(track) = track_of(&file, mp4::MediaType::AAC) else {
        return Ok(None);
    };
    let t = &file.tracks()[&track];
    let movie_scale = file.moov.mvhd.timescale.max(1) as f64;
    let media_scale = t.trak.mdia.mdhd.timescale.max(1) as f64;
    let entry = t
        .trak
        .edts
        .as_ref()
        .and_then(|e| e.elst.as_ref())
        .and_then(|l| {
            l.entries
                .iter()
                .find(|e| e.media_time as i64 >= 0 && e.media_time != u64::MAX)
        });
    Ok(Some(match entry {
        Some(e) => (
            e.media_time as f64 / media_scale,
            (e.segment_duration > 0).then(|| e.segment_duration as f64 / movie_scale),
        ),
        None => (0.0, None),
    }))
}
