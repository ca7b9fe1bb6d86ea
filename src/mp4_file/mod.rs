//! MP4 (H.264) without a system ffmpeg: OpenH264 (built from source by the `openh264` crate)
//! for the codec, the pure-Rust `mp4` crate for the container. Reads any H.264 track OpenH264
//! decodes (Baseline to High, B-frames included); writes Constrained Baseline 4:2:0 with an
//! IDR frame every two seconds, and copies an AAC audio track through untouched.

mod audio;
mod boxes;
mod reader;
mod writer;

use std::fs::File;
use std::io::{BufReader, Seek};
use std::path::Path;

use thiserror::Error;

pub use audio::{AAC_RATES, AudioTrack, Edit, audio_edit};
pub use reader::Reader;
pub use writer::Writer;

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
    /// The AAC encoder failed.
    #[error("AAC encoder: {0}")]
    AudioCodec(String),
    /// A sample the track lists is absent.
    #[error("sample {0} is missing (truncated file?)")]
    MissingSample(u32),
    /// A decoder cannot start at this frame (not a sync sample, or past the end).
    #[error("frame {0} is not a sync sample: decoding cannot start there")]
    NotSync(usize),
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
    /// The box structure is damaged (checked before parsing).
    #[error("malformed MP4: {0}")]
    Malformed(String),
}

type Mp4File = mp4::Mp4Reader<BufReader<File>>;

/// Checks an MP4/M4A's box structure (sizes, fixed fields, table counts, timescales) without
/// parsing it further: what every reader of the file, `mp4` or symphonia, relies on.
pub fn check_structure(file: &mut File) -> Result<(), Mp4Error> {
    boxes::check(file)
}

fn open(path: &Path) -> Result<Mp4File, Mp4Error> {
    let mut file = crate::safe_read::open_regular(path)?;
    boxes::check(&mut file)?;
    let size = file.metadata()?.len();
    file.rewind()?;
    let reader = mp4::Mp4Reader::read_header(BufReader::new(file), size)?;
    // Every sample needs a time: the crate unwraps the stts lookup of each sample read
    // (found by the fuzz suite).
    for (id, t) in reader.tracks() {
        let timed: u64 = t
            .trak
            .mdia
            .minf
            .stbl
            .stts
            .entries
            .iter()
            .map(|e| u64::from(e.sample_count))
            .sum();
        if t.trafs.is_empty() && timed < u64::from(t.sample_count()) {
            return Err(Mp4Error::Malformed(format!(
                "track {id}: stts gives times for {timed} of its {} samples",
                t.sample_count()
            )));
        }
    }
    Ok(reader)
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
