//! An AAC track copied packet for packet from one MP4 into another.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use super::{Mp4Error, open, track_of};

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
        let (tmp, mut writer) = start(path, 1000)?;
        self.add_to(&mut writer, 1)?;
        finish(tmp, writer, path)
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

pub(super) fn finish(
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
        .and_then(|l| l.entries.iter().find(|e| e.media_time as i64 >= 0 && e.media_time != u64::MAX));
    Ok(Some(match entry {
        Some(e) => (
            e.media_time as f64 / media_scale,
            (e.segment_duration > 0).then(|| e.segment_duration as f64 / movie_scale),
        ),
        None => (0.0, None),
    }))
}
