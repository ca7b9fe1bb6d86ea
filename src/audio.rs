//! Audio in: WAV and the AAC inside MP4/M4A decoded in Rust (symphonia), anything else through
//! a system ffmpeg when one is on PATH; mono, resampled to the rate asked for.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use symphonia::core::audio::SampleBuffer;
use symphonia::core::codecs::{CODEC_TYPE_NULL, DecoderOptions};
use symphonia::core::errors::Error as SymError;
use symphonia::core::formats::FormatOptions;
use symphonia::core::io::MediaSourceStream;
use symphonia::core::meta::MetadataOptions;
use symphonia::core::probe::Hint;
use thiserror::Error;

use crate::programs::system_ffmpeg;

/// Mono samples in −1…1 at `rate` Hz.
#[derive(Clone, Debug, PartialEq)]
pub struct Audio {
    /// The samples, −1…1.
    pub samples: Vec<f32>,
    /// Samples per second.
    pub rate: u32,
}

impl Audio {
    /// Duration in seconds.
    pub fn seconds(&self) -> f64 {
        self.samples.len() as f64 / self.rate.max(1) as f64
    }
}

/// What can be wrong with an audio input; every variant names the file.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum AudioError {
    /// The file could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a format read here, and no ffmpeg to read it.
    #[error(
        "{path}: {why}; WAV, MP4 and M4A (AAC) are read without ffmpeg, other formats need a system ffmpeg (not found on PATH)"
    )]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// The container holds no audio track.
    #[error("{path}: no audio track")]
    NoAudio {
        /// The file.
        path: PathBuf,
    },
    /// A packet that does not decode.
    #[error("{path}: audio packet {packet} does not decode: {why}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The packet (0-based).
        packet: usize,
        /// What is wrong.
        why: String,
    },
    /// Longer than the caller allows; decoding stopped there.
    #[error("{path}: the audio lasts more than {max:.0} s (at least {seconds:.0} s); split it")]
    TooLong {
        /// The file.
        path: PathBuf,
        /// Its duration (or as far as it was read), seconds.
        seconds: f64,
        /// The limit, seconds.
        max: f64,
    },
    /// The header is damaged or declares nonsense (checked before any decoder sees it).
    #[error("{path}: malformed audio header: {why}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// ffmpeg could not read it.
    #[error("{path}: ffmpeg could not decode the audio ({status})")]
    Ffmpeg {
        /// The file.
        path: PathBuf,
        /// How ffmpeg exited.
        status: String,
    },
}

/// Reads the audio of `path` as mono at `rate` Hz, refusing more than `max_seconds` (checked
/// from the header when it tells, else while decoding, so memory stays bounded).
pub fn read(path: &Path, rate: u32, max_seconds: f64) -> Result<Audio, AudioError> {
    Ok(resample(&read_at(path, Some(rate), max_seconds)?, rate))
}

/// Reads the audio of `path` as mono at its own sample rate (ffmpeg, when it is needed,
/// delivers 48 kHz).
pub fn read_native(path: &Path, max_seconds: f64) -> Result<Audio, AudioError> {
    read_at(path, None, max_seconds)
}

/// The duration of `path`'s audio in seconds, refusing more than `max_seconds` — from the
/// header when it tells, else by decoding without keeping the samples, so even an hour of
/// 96 kHz sound costs no memory.
pub fn duration(path: &Path, max_seconds: f64) -> Result<f64, AudioError> {
    let file = open_checked(path)?;
    match decode_native(path, file, max_seconds, false) {
        Ok((audio, frames)) => Ok(frames as f64 / f64::from(audio.rate.max(1))),
        Err(AudioError::Unsupported { .. }) => Ok(read_native(path, max_seconds)?.seconds()),
        Err(e) => Err(e),
    }
}

/// `path` opened as a regular file whose header passed [`check_header`].
fn open_checked(path: &Path) -> Result<std::fs::File, AudioError> {
    let io = |source| AudioError::Io {
        path: path.to_owned(),
        source,
    };
    let mut file = crate::safe_read::open_regular(path).map_err(io)?;
    check_header(&mut file).map_err(|why| AudioError::Malformed {
        path: path.to_owned(),
        why,
    })?;
    Ok(file)
}

fn read_at(path: &Path, rate: Option<u32>, max_seconds: f64) -> Result<Audio, AudioError> {
    let file = open_checked(path)?;
    match decode_native(path, file, max_seconds, true).map(|(a, _)| a) {
        Ok(a) if is_mp4(path) => trim_to_edit_list(path, a),
        Ok(a) => Ok(a),
        Err(AudioError::Unsupported { why, .. }) => match system_ffmpeg() {
            Some(ffmpeg) => decode_ffmpeg(&ffmpeg, path, rate.unwrap_or(48_000), max_seconds),
            None => Err(AudioError::Unsupported {
                path: path.to_owned(),
                why,
            }),
        },
        Err(e) => Err(e),
    }
}

/// Largest sample rate taken (768 kHz, the highest any audio interface records at).
const MAX_RATE: u32 = 768_000;
/// Smallest sample rate taken: 4 kHz carries the speech band up to 2 kHz; below it a header
/// is damaged (a 128 Hz "recording" of 3 s of data reads as six minutes to upsample).
const MIN_RATE: u32 = 4_000;

/// The header checks run before symphonia sees a file, which panics on some declared values
/// (issue 39: a WAV at 0 Hz, an MP4 `mdhd` timescale of 0, an `hdlr` box of size 0). A RIFF
/// WAVE file must have a sane `fmt ` chunk; a file whose second word is `ftyp` (MP4, M4A,
/// MOV) must pass the MP4 box check. Anything else is left to the decoders. The file is
/// rewound.
fn check_header(file: &mut std::fs::File) -> Result<(), String> {
    use std::io::{Seek, SeekFrom};
    let mut head = [0u8; 12];
    let n = read_up_to(file, &mut head).map_err(|e| e.to_string())?;
    let head = &head[..n];
    let result = if head.len() == 12 && &head[..4] == b"RIFF" && &head[8..12] == b"WAVE" {
        check_wav(file)
    } else if head.len() >= 8 && &head[4..8] == b"ftyp" {
        crate::mp4_file::check_structure(file).map_err(|e| e.to_string())
    } else {
        Ok(())
    };
    file.seek(SeekFrom::Start(0)).map_err(|e| e.to_string())?;
    result
}

/// Reads until `buf` is full or the file ends; the bytes read.
fn read_up_to(file: &mut std::fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// A WAV's chunks up to its `fmt ` chunk: each must fit the file, and the format must have
/// 1–64 channels, a rate of [`MIN_RATE`]–[`MAX_RATE`], a non-zero block size and 1–64 bits a
/// sample.
fn check_wav(file: &mut std::fs::File) -> Result<(), String> {
    use std::io::{Seek, SeekFrom};
    let len = file.metadata().map_err(|e| e.to_string())?.len();
    let mut at = 12u64;
    loop {
        let mut head = [0u8; 8];
        file.seek(SeekFrom::Start(at)).map_err(|e| e.to_string())?;
        if read_up_to(file, &mut head).map_err(|e| e.to_string())? < 8 {
            return Err("no fmt chunk".into());
        }
        let size = u64::from(u32::from_le_bytes(head[4..8].try_into().expect("4 bytes")));
        let name = String::from_utf8_lossy(&head[..4]).into_owned();
        if &head[..4] == b"fmt " {
            if !(16..=1024).contains(&size) || at + 8 + size > len {
                return Err(format!("fmt chunk of {size} bytes"));
            }
            let mut fmt = [0u8; 16];
            read_up_to(file, &mut fmt).map_err(|e| e.to_string())?;
            let u16_at = |i: usize| u16::from_le_bytes([fmt[i], fmt[i + 1]]);
            let (channels, rate) = (
                u16_at(2),
                u32::from_le_bytes(fmt[4..8].try_into().expect("4")),
            );
            let (block, bits) = (u16_at(12), u16_at(14));
            if !(1..=64).contains(&channels) {
                return Err(format!("{channels} channels (1 to 64 are read)"));
            }
            if !(MIN_RATE..=MAX_RATE).contains(&rate) {
                return Err(format!(
                    "a sample rate of {rate} Hz ({MIN_RATE} to {MAX_RATE} are read)"
                ));
            }
            if block == 0 || !(1..=64).contains(&bits) {
                return Err(format!(
                    "a block of {block} bytes with {bits} bits a sample"
                ));
            }
            return Ok(());
        }
        if &head[..4] == b"data" {
            return Err("the data chunk comes before the fmt chunk".into());
        }
        // Chunks are padded to an even size.
        let next = at + 8 + size + (size & 1);
        if next > len {
            return Err(format!("{name:?} chunk of {size} bytes runs past the end"));
        }
        at = next;
    }
}

fn is_mp4(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    matches!(ext.as_str(), "mp4" | "m4a" | "m4v" | "mov")
}

/// Drops the AAC encoder's priming samples and the padding after the last real sample, as
/// the MP4's edit list says (players and ffmpeg do the same), so that sample 0 is time 0 of
/// the video beside it.
fn trim_to_edit_list(path: &Path, mut audio: Audio) -> Result<Audio, AudioError> {
    let edit = crate::mp4_file::audio_edit(path).map_err(|e| AudioError::Decode {
        path: path.to_owned(),
        packet: 0,
        why: e.to_string(),
    })?;
    if let Some((skip, keep)) = edit {
        let rate = audio.rate as f64;
        let skip = ((skip * rate).round() as usize).min(audio.samples.len());
        audio.samples.drain(..skip);
        if let Some(keep) = keep {
            audio.samples.truncate((keep * rate).round() as usize);
        }
    }
    Ok(audio)
}

/// The audio of `file` (its samples when `keep`, else none) and how many frames it holds.
fn decode_native(
    path: &Path,
    file: std::fs::File,
    max_seconds: f64,
    keep: bool,
) -> Result<(Audio, u64), AudioError> {
    let unsupported = |why: String| AudioError::Unsupported {
        path: path.to_owned(),
        why,
    };
    let mut hint = Hint::new();
    if let Some(ext) = path.extension().and_then(|e| e.to_str()) {
        hint.with_extension(&ext.to_ascii_lowercase());
    }
    let stream = MediaSourceStream::new(Box::new(file), Default::default());
    let probed = symphonia::default::get_probe()
        .format(
            &hint,
            stream,
            &FormatOptions::default(),
            &MetadataOptions::default(),
        )
        .map_err(|e| unsupported(format!("not a WAV or MP4/M4A file ({e})")))?;
    let mut format = probed.format;
    let track = format
        .tracks()
        .iter()
        .find(|t| t.codec_params.codec != CODEC_TYPE_NULL && t.codec_params.sample_rate.is_some())
        .ok_or_else(|| AudioError::NoAudio {
            path: path.to_owned(),
        })?;
    let id = track.id;
    let rate = track.codec_params.sample_rate.unwrap_or(0);
    if rate == 0 {
        return Err(AudioError::NoAudio {
            path: path.to_owned(),
        });
    }
    if !(MIN_RATE..=MAX_RATE).contains(&rate) {
        return Err(AudioError::Malformed {
            path: path.to_owned(),
            why: format!("a sample rate of {rate} Hz ({MIN_RATE} to {MAX_RATE} are read)"),
        });
    }
    let too_long = |frames: u64| AudioError::TooLong {
        path: path.to_owned(),
        seconds: frames as f64 / rate as f64,
        max: max_seconds,
    };
    let max_frames = (max_seconds * rate as f64) as u64;
    if let Some(n) = track.codec_params.n_frames
        && n > max_frames
    {
        return Err(too_long(n));
    }
    let mut decoder = symphonia::default::get_codecs()
        .make(&track.codec_params, &DecoderOptions::default())
        .map_err(|e| unsupported(format!("audio codec not supported ({e})")))?;
    let mut samples = Vec::new();
    let mut count = 0u64;
    let mut buffer: Option<SampleBuffer<f32>> = None;
    let mut packet_index = 0;
    loop {
        let packet = match format.next_packet() {
            Ok(p) => p,
            Err(SymError::IoError(e)) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(SymError::ResetRequired) => break,
            Err(e) => {
                return Err(AudioError::Decode {
                    path: path.to_owned(),
                    packet: packet_index,
                    why: e.to_string(),
                });
            }
        };
        if packet.track_id() != id {
            continue;
        }
        packet_index += 1;
        let decoded = decoder.decode(&packet).map_err(|e| AudioError::Decode {
            path: path.to_owned(),
            packet: packet_index - 1,
            why: e.to_string(),
        })?;
        let spec = *decoded.spec();
        let channels = spec.channels.count().max(1);
        count += decoded.frames() as u64;
        if count > max_frames {
            return Err(too_long(count));
        }
        if !keep {
            continue;
        }
        let buf = match &mut buffer {
            Some(b) if b.capacity() >= decoded.capacity() * channels => b,
            _ => buffer.insert(SampleBuffer::new(decoded.capacity() as u64, spec)),
        };
        buf.copy_interleaved_ref(decoded);
        samples.extend(
            buf.samples()
                .chunks_exact(channels)
                .map(|c| c.iter().sum::<f32>() / channels as f32),
        );
    }
    Ok((Audio { samples, rate }, count))
}

/// `ffmpeg -i PATH -f s16le -ac 1 -ar RATE -`, read as it streams, stopped past the limit.
fn decode_ffmpeg(
    ffmpeg: &Path,
    path: &Path,
    rate: u32,
    max_seconds: f64,
) -> Result<Audio, AudioError> {
    let mut child = Command::new(ffmpeg)
        .args(["-nostdin", "-v", "error", "-i"])
        .arg(path)
        .args([
            "-vn",
            "-f",
            "s16le",
            "-ac",
            "1",
            "-ar",
            &rate.to_string(),
            "-",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|source| AudioError::Io {
            path: path.to_owned(),
            source,
        })?;
    let mut out = child.stdout.take().expect("piped stdout");
    let max_samples = (max_seconds * rate as f64) as usize;
    let mut samples = Vec::new();
    let mut chunk = vec![0u8; 1 << 16];
    let mut carry: Option<u8> = None;
    loop {
        let n = match out.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(source) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(AudioError::Io {
                    path: path.to_owned(),
                    source,
                });
            }
        };
        let mut bytes = &chunk[..n];
        if let Some(lo) = carry.take() {
            samples.push(i16::from_le_bytes([lo, bytes[0]]) as f32 / 32768.0);
            bytes = &bytes[1..];
        }
        let pairs = bytes.chunks_exact(2);
        carry = pairs.remainder().first().copied();
        samples.extend(pairs.map(|b| i16::from_le_bytes([b[0], b[1]]) as f32 / 32768.0));
        if samples.len() > max_samples {
            let _ = child.kill();
            let _ = child.wait();
            return Err(AudioError::TooLong {
                path: path.to_owned(),
                seconds: samples.len() as f64 / rate as f64,
                max: max_seconds,
            });
        }
    }
    let status = child.wait().map_err(|source| AudioError::Io {
        path: path.to_owned(),
        source,
    })?;
    if !status.success() {
        return Err(AudioError::Ffmpeg {
            path: path.to_owned(),
            status: status.to_string(),
        });
    }
    Ok(Audio { samples, rate })
}

/// Half-width of the resampling kernel, in input samples at the lower of the two rates.
const SINC_HALF_WIDTH: f64 = 16.0;

/// Band-limited resampling: a Hann-windowed sinc whose cut-off is the lower Nyquist
/// frequency (× 0.95), evaluated at each output instant. Unchanged when the rates agree.
pub fn resample(audio: &Audio, rate: u32) -> Audio {
    if audio.rate == rate || audio.samples.is_empty() {
        return Audio {
            samples: audio.samples.clone(),
            rate,
        };
    }
    let mut stream = Resampler::new(audio.rate, rate);
    let mut samples = stream.push(&audio.samples);
    samples.extend(stream.finish());
    Audio { samples, rate }
}

/// [`resample`] a chunk at a time (live sound): each output sample leaves as soon as the
/// input its kernel spans has arrived, so the chunks' outputs joined are the whole's.
#[derive(Clone, Debug)]
pub struct Resampler {
    /// Output over input rate.
    ratio: f64,
    /// Cut-off relative to the input rate.
    cutoff: f64,
    /// The kernel's half-width, input samples.
    half: f64,
    /// Input samples kept, the first of them input sample `first`.
    kept: Vec<f32>,
    first: usize,
    /// Input samples taken.
    taken: usize,
    /// Output samples given.
    given: usize,
    /// The kernel's weights precomputed at every phase, when the rates' ratio has few.
    table: Option<Kernel>,
}

/// Phases past which [`Resampler`] computes its kernel at each sample instead of keeping a
/// table (rates whose ratio reduces to no small fraction: 44 101 Hz).
const MOST_PHASES: u64 = 4096;

/// The windowed sinc at each phase of a rational resampling: output sample `k` falls at input
/// position `k·step / phases` (the rates' ratio reduced), so its kernel is one of `phases`.
/// Computing it per sample cost a sine and a cosine per tap (100 taps a sample from 48 kHz):
/// most of a live session's time on a 48 kHz stream.
#[derive(Clone, Debug)]
struct Kernel {
    step: u64,
    phases: u64,
    /// Per phase: the first tap's offset from the position's integer part, and the weights.
    by_phase: Vec<(i64, Vec<f64>)>,
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The kernel's weight at distance `d` (input samples) from the output's position.
fn windowed_sinc(d: f64, cutoff: f64, half: f64) -> f64 {
    let arg = std::f64::consts::PI * cutoff * d;
    let sinc = if arg.abs() < 1e-12 { 1.0 } else { arg.sin() / arg };
    let window = 0.5 + 0.5 * (std::f64::consts::PI * d / half).cos();
    cutoff * sinc * window
}

impl Resampler {
    /// From `from` Hz to `to` Hz (both positive).
    pub fn new(from: u32, to: u32) -> Self {
        let ratio = to as f64 / from as f64;
        let cutoff = 0.95 * ratio.min(1.0);
        let half = SINC_HALF_WIDTH / cutoff;
        let g = gcd(u64::from(from), u64::from(to)).max(1);
        let (step, phases) = (u64::from(from) / g, u64::from(to) / g);
        let table = (phases <= MOST_PHASES).then(|| Kernel {
            step,
            phases,
            by_phase: (0..phases)
                .map(|phase| {
                    let f = phase as f64 / phases as f64;
                    let (lo, hi) = ((f - half).ceil() as i64, (f + half).floor() as i64);
                    let weights = (lo..=hi).map(|o| windowed_sinc(o as f64 - f, cutoff, half)).collect();
                    (lo, weights)
                })
                .collect(),
        });
        Resampler {
            ratio,
            cutoff,
            half,
            kept: Vec::new(),
            first: 0,
            taken: 0,
            given: 0,
            table,
        }
    }

    /// Takes `samples` and returns the output samples now complete.
    pub fn push(&mut self, samples: &[f32]) -> Vec<f32> {
        if (self.ratio - 1.0).abs() < 1e-12 {
            return samples.to_vec();
        }
        self.kept.extend_from_slice(samples);
        self.taken += samples.len();
        let mut out = Vec::new();
        // Output k needs input up to ⌊k / ratio + half⌋.
        while ((self.given as f64 / self.ratio + self.half).floor() as usize) < self.taken {
            out.push(self.sample(self.given, self.taken - 1));
            self.given += 1;
        }
        let needed = (self.given as f64 / self.ratio - self.half).ceil().max(0.0) as usize;
        if needed > self.first + 4096 {
            self.kept.drain(..needed - self.first);
            self.first = needed;
        }
        out
    }

    /// Ends the stream: the last output samples, their kernels cut at the last input.
    pub fn finish(&mut self) -> Vec<f32> {
        if (self.ratio - 1.0).abs() < 1e-12 || self.taken == 0 {
            return Vec::new();
        }
        let total = (self.taken as f64 * self.ratio).round() as usize;
        let out = (self.given..total).map(|k| self.sample(k, self.taken - 1)).collect();
        self.given = total.max(self.given);
        out
    }

    /// Output sample `k` from the kept input, the kernel cut at input `last`.
    fn sample(&self, k: usize, last: usize) -> f32 {
        if let Some(kernel) = &self.table {
            let position = k as u64 * kernel.step;
            let (whole, phase) = (position / kernel.phases, position % kernel.phases);
            let (lo, weights) = &kernel.by_phase[phase as usize];
            let start = whole as i64 + lo;
            let mut acc = 0.0;
            for (j, w) in weights.iter().enumerate() {
                let i = start + j as i64;
                if i > last as i64 {
                    break;
                }
                if i >= self.first as i64 {
                    acc += f64::from(self.kept[i as usize - self.first]) * w;
                }
            }
            return acc as f32;
        }
        let centre = k as f64 / self.ratio;
        let lo = ((centre - self.half).ceil().max(0.0)) as usize;
        let hi = ((centre + self.half).floor() as usize).min(last);
        let mut acc = 0.0;
        for i in lo.max(self.first)..=hi {
            acc += f64::from(self.kept[i - self.first])
                * windowed_sinc(i as f64 - centre, self.cutoff, self.half);
        }
        acc as f32
    }
}

/// A sample in −1…1 as a 16-bit PCM value (rounded, clipped at full scale).
pub fn to_pcm16(x: f32) -> i16 {
    (x * 32768.0).round().clamp(-32768.0, 32767.0) as i16
}

/// Writes 16-bit mono PCM WAV (for tests, benchmarks and the TTS path).
pub fn write_wav(path: &Path, audio: &Audio) -> std::io::Result<()> {
    let data: Vec<u8> = audio
        .samples
        .iter()
        .flat_map(|&s| to_pcm16(s).to_le_bytes())
        .collect();
    let mut out = Vec::with_capacity(44 + data.len());
    out.extend_from_slice(b"RIFF");
    out.extend_from_slice(&(36 + data.len() as u32).to_le_bytes());
    out.extend_from_slice(b"WAVEfmt ");
    out.extend_from_slice(&16u32.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&audio.rate.to_le_bytes());
    out.extend_from_slice(&(audio.rate * 2).to_le_bytes());
    out.extend_from_slice(&2u16.to_le_bytes());
    out.extend_from_slice(&16u16.to_le_bytes());
    out.extend_from_slice(b"data");
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(&data);
    crate::atomic::write_file(path, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The phase table gives what the kernel computed at each sample gives (its definition),
    /// for the rates live sound comes at, down and up.
    #[test]
    fn the_phase_table_is_the_kernel_at_each_sample() {
        let mut rng = crate::rng::Rng::new(5);
        for from in [48_000u32, 44_100, 22_050, 24_000, 8_000] {
            let input: Vec<f32> = (0..from as usize / 4).map(|_| rng.normal() as f32 * 0.3).collect();
            let mut table = Resampler::new(from, 16_000);
            assert!(table.table.is_some(), "{from} Hz");
            let mut direct = table.clone();
            direct.table = None;
            let (mut a, mut b) = (table.push(&input), direct.push(&input));
            a.extend(table.finish());
            b.extend(direct.finish());
            assert_eq!(a.len(), b.len(), "{from} Hz");
            let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max);
            assert!(worst < 1e-6, "{from} Hz: {worst}");
        }
        assert!(Resampler::new(44_101, 16_000).table.is_none(), "16 000 phases: computed per sample");
    }
}
