//! Phone timing files: HTK `.lab` (100 ns units), Praat TextGrid (long or short, UTF-8/16),
//! TSV (seconds); read with line numbers in every error, written atomically.

use std::path::Path;

use super::{PhoneMap, PhonemeError, Segment};
use crate::atomic;

pub use super::textgrid::{parse_textgrid, read_textgrid};

/// A file's text: UTF-8 (a byte-order mark dropped) or, as Praat may write, UTF-16.
pub(super) fn read_text(path: &Path) -> Result<String, PhonemeError> {
    let bytes = crate::safe_read::read_regular(path).map_err(|source| PhonemeError::Io {
        path: path.into(),
        source,
    })?;
    // Praat may write UTF-16 with a byte-order mark.
    let utf16 = |le: bool| {
        let units: Vec<u16> = bytes[2..]
            .chunks_exact(2)
            .map(|c| {
                if le {
                    u16::from_le_bytes([c[0], c[1]])
                } else {
                    u16::from_be_bytes([c[0], c[1]])
                }
            })
            .collect();
        String::from_utf16_lossy(&units)
    };
    Ok(match bytes.get(..2) {
        Some([0xFF, 0xFE]) => utf16(true),
        Some([0xFE, 0xFF]) => utf16(false),
        _ => String::from_utf8_lossy(bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes))
            .into_owned(),
    })
}

/// Most segments a timing file may hold: an hour ([`crate::facespace::MAX_DURATION`]) at
/// [`MAX_PHONES_PER_SECOND`]. Parsers stop there, so an absurd file costs bounded memory.
pub const MAX_SEGMENTS: usize = 3600 * MAX_PHONES_PER_SECOND;

/// Most segments a second of labels may hold on average: fast speech has about 15 phones a
/// second, and a frame lasts 40 ms; more is phones far shorter than a frame, not speech.
pub const MAX_PHONES_PER_SECOND: usize = 30;

/// The error for a file past [`MAX_SEGMENTS`], at `line`.
pub(super) fn too_many(path: &Path, line: usize) -> PhonemeError {
    PhonemeError::Parse {
        path: path.into(),
        line,
        reason: format!(
            "more than {MAX_SEGMENTS} segments (an hour at {MAX_PHONES_PER_SECOND} a second): not a phone timing file of one utterance"
        ),
    }
}

/// Labels with their source line, before normalisation and validation.
pub(super) struct RawInterval {
    pub(super) start: f64,
    pub(super) end: f64,
    pub(super) label: String,
    pub(super) line: usize,
}

/// Normalises labels and checks times: finite, non-negative, `end ≥ start`, sorted and
/// non-overlapping (a 1 µs tolerance absorbs rounding in the files).
pub(super) fn finish(
    path: &Path,
    raw: Vec<RawInterval>,
    map: &PhoneMap,
) -> Result<Vec<Segment>, PhonemeError> {
    let err = |line: usize, reason: String| PhonemeError::Parse {
        path: path.into(),
        line,
        reason,
    };
    if raw.is_empty() {
        return Err(PhonemeError::Empty { path: path.into() });
    }
    if let Some(r) = raw.get(MAX_SEGMENTS) {
        return Err(too_many(path, r.line));
    }
    let mut out: Vec<Segment> = Vec::with_capacity(raw.len());
    for r in raw {
        if !(r.start.is_finite() && r.end.is_finite()) {
            return Err(err(r.line, "time is not finite".into()));
        }
        if r.start < 0.0 {
            return Err(err(r.line, format!("negative time {}", r.start)));
        }
        if r.end < r.start {
            return Err(err(
                r.line,
                format!("interval ends ({}) before it starts ({})", r.end, r.start),
            ));
        }
        if let Some(prev) = out.last() {
            if r.start < prev.start - 1e-6 {
                return Err(err(
                    r.line,
                    format!(
                        "intervals out of order: {} starts before the previous one ({})",
                        r.start, prev.start
                    ),
                ));
            }
            if r.start < prev.end - 1e-6 {
                return Err(err(
                    r.line,
                    format!(
                        "interval {}–{} overlaps the previous one ({}–{})",
                        r.start, r.end, prev.start, prev.end
                    ),
                ));
            }
        }
        let phone = map
            .phone(&r.label)
            .ok_or_else(|| PhonemeError::UnknownLabel {
                path: path.into(),
                line: r.line,
                // A label is quoted whole only when short: a 3 MB "label" is not echoed.
                label: crate::options::clipped(&r.label, 40),
            })?;
        out.push(Segment {
            start: r.start,
            end: r.end,
            phone,
        });
    }
    // Phones far shorter than a frame: a file that would cost minutes and gigabytes
    // downstream for a few seconds of speech.
    let span = out.last().map_or(0.0, |l| l.end) - out[0].start;
    let allowed = (MAX_PHONES_PER_SECOND as f64 * span).ceil() as usize + 10;
    if out.len() > allowed {
        return Err(PhonemeError::Parse {
            path: path.into(),
            line: 1,
            reason: format!(
                "{} segments in {span:.3} s: more than {MAX_PHONES_PER_SECOND} a second (speech has about 15; these are far shorter than a video frame)",
                out.len()
            ),
        });
    }
    Ok(out)
}

/// Reads a timing file by extension: `.lab` (HTK), `.TextGrid` (Praat), `.tsv`/`.txt`.
pub fn read_labels(
    path: &Path,
    tier: Option<&str>,
    map: &PhoneMap,
) -> Result<Vec<Segment>, PhonemeError> {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("textgrid") => read_textgrid(path, tier, map),
        Some("tsv") | Some("txt") => read_tsv(path, map),
        _ => read_htk(path, map),
    }
}

/// HTK label file: `start end label [score …]`, times in 100 ns units.
pub fn read_htk(path: &Path, map: &PhoneMap) -> Result<Vec<Segment>, PhonemeError> {
    parse_htk(&read_text(path)?, path, map)
}

/// Parses HTK label text; `path` names the source in errors.
pub fn parse_htk(text: &str, path: &Path, map: &PhoneMap) -> Result<Vec<Segment>, PhonemeError> {
    let mut raw = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line == "." || line.starts_with("#!") || line.starts_with('"') {
            continue; // blank, MLF terminators and headers
        }
        if line == "///" {
            break; // only the first alternative of a multi-level file
        }
        if raw.len() >= MAX_SEGMENTS {
            return Err(too_many(path, i + 1));
        }
        let err = |reason: String| PhonemeError::Parse {
            path: path.into(),
            line: i + 1,
            reason,
        };
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() < 3 {
            return Err(err(format!("expected `start end label`, found {line:?}")));
        }
        let time = |s: &str| {
            s.parse::<i64>()
                .map(|t| t as f64 / 1e7)
                .map_err(|_| err(format!("bad time {s:?} (integer 100 ns units)")))
        };
        raw.push(RawInterval {
            start: time(fields[0])?,
            end: time(fields[1])?,
            label: fields[2].to_owned(),
            line: i + 1,
        });
    }
    finish(path, raw, map)
}

/// Tab- or space-separated `start_s end_s label`; `#` comments and a header line allowed.
pub fn read_tsv(path: &Path, map: &PhoneMap) -> Result<Vec<Segment>, PhonemeError> {
    parse_tsv(&read_text(path)?, path, map)
}

/// Parses TSV label text; `path` names the source in errors.
pub fn parse_tsv(text: &str, path: &Path, map: &PhoneMap) -> Result<Vec<Segment>, PhonemeError> {
    let mut raw = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim_end_matches(['\r', '\n']);
        if line.trim().is_empty() || line.trim_start().starts_with('#') {
            continue;
        }
        let err = |reason: String| PhonemeError::Parse {
            path: path.into(),
            line: i + 1,
            reason,
        };
        let fields: Vec<&str> = if line.contains('\t') {
            line.split('\t').collect()
        } else {
            line.split_whitespace().collect()
        };
        let start = fields.first().map(|s| s.trim().parse::<f64>());
        if i == 0 && raw.is_empty() && !matches!(start, Some(Ok(_))) {
            continue; // a header
        }
        if raw.len() >= MAX_SEGMENTS {
            return Err(too_many(path, i + 1));
        }
        if fields.len() < 2 {
            return Err(err(format!("expected `start end label`, found {line:?}")));
        }
        let time = |s: &str| {
            s.trim()
                .parse::<f64>()
                .map_err(|_| err(format!("bad time {s:?}")))
        };
        let label = fields.get(2).map_or("", |s| s.trim());
        raw.push(RawInterval {
            start: time(fields[0])?,
            end: time(fields[1])?,
            label: label.to_owned(),
            line: i + 1,
        });
    }
    finish(path, raw, map)
}

/// HTK label text (100 ns units).
pub fn format_htk(segments: &[Segment]) -> String {
    segments
        .iter()
        .map(|s| {
            format!(
                "{} {} {}\n",
                (s.start * 1e7).round() as i64,
                (s.end * 1e7).round() as i64,
                s.phone
            )
        })
        .collect()
}

/// TSV text with a header, times in seconds.
pub fn format_tsv(segments: &[Segment]) -> String {
    let mut s = String::from("start\tend\tlabel\n");
    for seg in segments {
        s.push_str(&format!("{}\t{}\t{}\n", seg.start, seg.end, seg.phone));
    }
    s
}

/// Writes a timing file by extension (`.lab` or `.tsv`), atomically.
pub fn write_labels(path: &Path, segments: &[Segment]) -> Result<(), PhonemeError> {
    let text = match path.extension().and_then(|e| e.to_str()) {
        Some("tsv") | Some("txt") => format_tsv(segments),
        _ => format_htk(segments),
    };
    atomic::write_file(path, text.as_bytes()).map_err(|source| PhonemeError::Io {
        path: path.into(),
        source,
    })
}
