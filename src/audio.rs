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

use crate::video::system_ffmpeg;

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

fn read_at(path: &Path, rate: Option<u32>, max_seconds: f64) -> Result<Audio, AudioError> {
    let io = |source| AudioError::Io {
        path: path.to_owned(),
        source,
    };
    let file = crate::manifest::open_regular(path).map_err(io)?;
    match decode_native(path, file, max_seconds) {
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
    let edit = crate::video::mp4::audio_edit(path).map_err(|e| AudioError::Decode {
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

fn decode_native(path: &Path, file: std::fs::File, max_seconds: f64) -> Result<Audio, AudioError> {
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
        if samples.len() as u64 > max_frames {
            return Err(too_long(samples.len() as u64));
        }
    }
    Ok(Audio { samples, rate })
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
    let ratio = rate as f64 / audio.rate as f64;
    // Cut-off relative to the input rate, and the kernel's half-width in input samples.
    let cutoff = 0.95 * ratio.min(1.0);
    let half = SINC_HALF_WIDTH / cutoff;
    let n_out = (audio.samples.len() as f64 * ratio).round() as usize;
    let x = &audio.samples;
    let samples = (0..n_out)
        .map(|k| {
            let centre = k as f64 / ratio;
            let lo = ((centre - half).ceil().max(0.0)) as usize;
            let hi = ((centre + half).floor() as usize).min(x.len() - 1);
            let mut acc = 0.0;
            for (i, &v) in x.iter().enumerate().take(hi + 1).skip(lo) {
                let d = i as f64 - centre;
                let arg = std::f64::consts::PI * cutoff * d;
                let sinc = if arg.abs() < 1e-12 {
                    1.0
                } else {
                    arg.sin() / arg
                };
                let window = 0.5 + 0.5 * (std::f64::consts::PI * d / half).cos();
                acc += v as f64 * cutoff * sinc * window;
            }
            acc as f32
        })
        .collect();
    Audio { samples, rate }
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
