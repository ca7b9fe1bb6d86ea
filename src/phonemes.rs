//! Phone set, viseme classes, phoneme-timing files and text → phonemes (DESIGN §6).
//!
//! Labels are normalised to ARPAbet (the 39 CMU phones, stress digits dropped, case folded)
//! plus `sil`; `sil`, `sp`, `pau`, `spn` and the empty label are silence. A few common
//! ARPAbet extensions (TIMIT/SAPI `ax`, `ix`, `h`, `axr`, `ux`, `el`, `em`, `en`, `nx`, `dx`)
//! fold onto their nearest CMU phone; any other set needs a [`PhoneMap`].

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::atomic;

/// The phones, `sil` first; a [`Phone`] is an index into this list.
pub const PHONES: [&str; 40] = [
    "sil", "aa", "ae", "ah", "ao", "aw", "ay", "b", "ch", "d", "dh", "eh", "er", "ey", "f", "g",
    "hh", "ih", "iy", "jh", "k", "l", "m", "n", "ng", "ow", "oy", "p", "r", "s", "sh", "t", "th",
    "uh", "uw", "v", "w", "y", "z", "zh",
];

/// Viseme class of each phone in [`PHONES`] order: the 22 classes of [unitsel] Table 1.
const VISEMES: [u8; 40] = [
    0, 2, 1, 1, 3, 9, 11, 21, 16, 19, 17, 4, 5, 4, 18, 20, 12, 6, 6, 16, //
    20, 14, 21, 19, 20, 8, 10, 21, 13, 15, 16, 19, 17, 4, 7, 18, 7, 6, 15, 16,
];

/// Number of viseme classes.
pub const N_VISEMES: usize = 22;

const SILENCE: [&str; 5] = ["sil", "sp", "pau", "spn", ""];
const ALIASES: [(&str, &str); 10] = [
    ("ax", "ah"),
    ("ix", "ih"),
    ("h", "hh"),
    ("axr", "er"),
    ("ux", "uw"),
    ("el", "l"),
    ("em", "m"),
    ("en", "n"),
    ("nx", "n"),
    ("dx", "t"),
];

/// One phone of [`PHONES`].
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Phone(u8);

impl std::fmt::Debug for Phone {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Phone {
    pub const SIL: Phone = Phone(0);
    pub const COUNT: usize = PHONES.len();

    /// Normalises a label (case, stress digits, silence, known aliases); `None` if unknown.
    pub fn parse(label: &str) -> Option<Phone> {
        let l: String = label
            .trim()
            .chars()
            .filter(|c| !c.is_ascii_digit())
            .collect::<String>()
            .to_ascii_lowercase();
        if SILENCE.contains(&l.as_str()) || l == "<sil>" {
            return Some(Phone::SIL);
        }
        let l = ALIASES
            .iter()
            .find(|(a, _)| *a == l)
            .map_or(l.as_str(), |(_, b)| b);
        PHONES.iter().position(|p| *p == l).map(|i| Phone(i as u8))
    }

    pub fn from_index(i: usize) -> Option<Phone> {
        (i < PHONES.len()).then_some(Phone(i as u8))
    }

    pub fn index(self) -> usize {
        self.0 as usize
    }

    pub fn name(self) -> &'static str {
        PHONES[self.index()]
    }

    /// Viseme class, 0–21 (DESIGN §6).
    pub fn viseme(self) -> u8 {
        VISEMES[self.index()]
    }

    pub fn all() -> impl Iterator<Item = Phone> {
        (0..PHONES.len()).map(|i| Phone(i as u8))
    }
}

impl std::fmt::Display for Phone {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for Phone {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Phone {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        Phone::parse(&s).ok_or_else(|| serde::de::Error::custom(format!("unknown phone {s:?}")))
    }
}

/// A labelled interval, in seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    pub start: f64,
    pub end: f64,
    pub phone: Phone,
}

impl Segment {
    pub fn duration(&self) -> f64 {
        self.end - self.start
    }
}

#[derive(Debug, Error)]
pub enum PhonemeError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}:{line}: {reason}")]
    Parse {
        path: PathBuf,
        line: usize,
        reason: String,
    },
    #[error("{path}:{line}: unknown phone label {label:?} (give a phone map for other phone sets)")]
    UnknownLabel {
        path: PathBuf,
        line: usize,
        label: String,
    },
    #[error("{path}: no tier named {wanted}; the tiers are {found:?}")]
    NoTier {
        path: PathBuf,
        wanted: String,
        found: Vec<String>,
    },
    #[error("{path}: no phone intervals")]
    Empty { path: PathBuf },
    #[error("words not in the pronouncing dictionary: {}", .0.join(", "))]
    OutOfDictionary(Vec<String>),
    #[error("no words in the text")]
    NoWords,
}

/// A mapping from another phone set's labels to ARPAbet, read from a two-column file
/// (`label<whitespace>arpabet`, `#` comments).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PhoneMap(BTreeMap<String, Phone>);

impl PhoneMap {
    pub fn read(path: &Path) -> Result<Self, PhonemeError> {
        let text = read_text(path)?;
        let mut map = BTreeMap::new();
        for (i, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let parse = |reason: String| PhonemeError::Parse {
                path: path.into(),
                line: i + 1,
                reason,
            };
            let mut it = line.split_whitespace();
            let (Some(from), Some(to), None) = (it.next(), it.next(), it.next()) else {
                return Err(parse(format!("expected `label arpabet`, found {line:?}")));
            };
            let phone =
                Phone::parse(to).ok_or_else(|| parse(format!("{to:?} is not an ARPAbet phone")))?;
            map.insert(from.to_owned(), phone);
        }
        Ok(PhoneMap(map))
    }

    /// The map's entry for `label`, else the built-in normalisation.
    pub fn phone(&self, label: &str) -> Option<Phone> {
        self.0
            .get(label.trim())
            .copied()
            .or_else(|| Phone::parse(label))
    }
}

fn read_text(path: &Path) -> Result<String, PhonemeError> {
    let bytes = std::fs::read(path).map_err(|source| PhonemeError::Io {
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

/// Labels with their source line, before normalisation and validation.
struct RawInterval {
    start: f64,
    end: f64,
    label: String,
    line: usize,
}

/// Normalises labels and checks times: finite, non-negative, `end ≥ start`, sorted and
/// non-overlapping (a 1 µs tolerance absorbs rounding in the files).
fn finish(
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
                label: r.label.clone(),
            })?;
        out.push(Segment {
            start: r.start,
            end: r.end,
            phone,
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

/// Praat TextGrid, long or short text form (UTF-8 or UTF-16). The tier is `tier` if given,
/// else the first named `phones` or `phonemes` (any case).
pub fn read_textgrid(
    path: &Path,
    tier: Option<&str>,
    map: &PhoneMap,
) -> Result<Vec<Segment>, PhonemeError> {
    parse_textgrid(&read_text(path)?, path, tier, map)
}

/// A TextGrid token: the short form is the long form without its `key =` labels, so both
/// reduce to the same token stream of strings, numbers and `<exists>` flags.
#[derive(Debug)]
enum Token {
    Str(String),
    Num(f64),
    Flag,
}

fn tokenise(text: &str, path: &Path) -> Result<Vec<(Token, usize)>, PhonemeError> {
    let mut tokens = Vec::new();
    let mut chars = text.chars().peekable();
    let mut line = 1;
    while let Some(c) = chars.next() {
        match c {
            '\n' => line += 1,
            '"' => {
                let start_line = line;
                let mut s = String::new();
                loop {
                    match chars.next() {
                        Some('"') if chars.peek() == Some(&'"') => {
                            chars.next();
                            s.push('"');
                        }
                        Some('"') => break,
                        Some(ch) => {
                            if ch == '\n' {
                                line += 1;
                            }
                            s.push(ch);
                        }
                        None => {
                            return Err(PhonemeError::Parse {
                                path: path.into(),
                                line: start_line,
                                reason: "unterminated string".into(),
                            });
                        }
                    }
                }
                tokens.push((Token::Str(s), start_line));
            }
            '[' => {
                for ch in chars.by_ref() {
                    if ch == ']' {
                        break;
                    }
                }
            }
            '<' => {
                for ch in chars.by_ref() {
                    if ch == '>' {
                        break;
                    }
                }
                tokens.push((Token::Flag, line));
            }
            '!' => {
                // a comment to the end of the line
                while chars.peek().is_some_and(|&ch| ch != '\n') {
                    chars.next();
                }
            }
            c if c.is_ascii_digit() || c == '-' || c == '.' || c == '+' => {
                let mut s = String::from(c);
                while chars
                    .peek()
                    .is_some_and(|ch| ch.is_ascii_alphanumeric() || matches!(ch, '.' | '-' | '+'))
                {
                    s.push(chars.next().unwrap_or_default());
                }
                let v = s.parse::<f64>().map_err(|_| PhonemeError::Parse {
                    path: path.into(),
                    line,
                    reason: format!("bad number {s:?}"),
                })?;
                tokens.push((Token::Num(v), line));
            }
            c if c.is_alphabetic() => {
                while chars
                    .peek()
                    .is_some_and(|ch| ch.is_alphanumeric() || *ch == '_' || *ch == '?')
                {
                    chars.next();
                }
            }
            _ => {}
        }
    }
    Ok(tokens)
}

pub fn parse_textgrid(
    text: &str,
    path: &Path,
    tier: Option<&str>,
    map: &PhoneMap,
) -> Result<Vec<Segment>, PhonemeError> {
    let tokens = tokenise(text, path)?;
    let mut it = tokens.into_iter().peekable();
    let mut last_line = 1;
    let mut next = |what: &str| -> Result<(Token, usize), PhonemeError> {
        let t = it.next().ok_or_else(|| PhonemeError::Parse {
            path: path.into(),
            line: last_line,
            reason: format!("file ends where {what} was expected"),
        })?;
        last_line = t.1;
        Ok(t)
    };
    let err = |line: usize, reason: String| PhonemeError::Parse {
        path: path.into(),
        line,
        reason,
    };
    macro_rules! string {
        ($what:expr) => {
            match next($what)? {
                (Token::Str(s), l) => (s, l),
                (t, l) => {
                    return Err(err(
                        l,
                        format!("expected {} (a string), found {:?}", $what, t),
                    ))
                }
            }
        };
    }
    macro_rules! number {
        ($what:expr) => {
            match next($what)? {
                (Token::Num(v), l) => (v, l),
                (t, l) => {
                    return Err(err(
                        l,
                        format!("expected {} (a number), found {:?}", $what, t),
                    ))
                }
            }
        };
    }
    let (file_type, l) = string!("the file type");
    if file_type != "ooTextFile" {
        return Err(err(
            l,
            format!("not a Praat text file (file type {file_type:?})"),
        ));
    }
    let (class, l) = string!("the object class");
    if class != "TextGrid" {
        return Err(err(
            l,
            format!("object class {class:?}, expected \"TextGrid\""),
        ));
    }
    number!("xmin");
    number!("xmax");
    match next("<exists>")? {
        (Token::Flag, _) => {}
        (t, l) => return Err(err(l, format!("expected <exists>, found {t:?}"))),
    }
    let (n_tiers, _) = number!("the tier count");
    let mut names = Vec::new();
    for _ in 0..n_tiers as usize {
        let (kind, _) = string!("the tier class");
        let (name, _) = string!("the tier name");
        number!("tier xmin");
        number!("tier xmax");
        let (n, _) = number!("the interval count");
        let wanted = match tier {
            Some(t) => name == t,
            None => matches!(name.to_ascii_lowercase().as_str(), "phones" | "phonemes"),
        };
        let mut raw = Vec::new();
        for _ in 0..n as usize {
            if kind == "IntervalTier" {
                let (start, line) = number!("interval xmin");
                let (end, _) = number!("interval xmax");
                let (label, _) = string!("interval text");
                raw.push(RawInterval {
                    start,
                    end,
                    label,
                    line,
                });
            } else {
                number!("point time");
                string!("point mark");
            }
        }
        if wanted {
            if kind != "IntervalTier" {
                return Err(err(
                    last_line,
                    format!("tier {name:?} is a {kind}, not an IntervalTier"),
                ));
            }
            return finish(path, raw, map);
        }
        names.push(name);
    }
    let wanted = tier.map_or_else(
        || "\"phones\" or \"phonemes\"".to_owned(),
        |t| format!("{t:?}"),
    );
    Err(PhonemeError::NoTier {
        path: path.into(),
        wanted,
        found: names,
    })
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

// ---- text → phonemes ----

static CMUDICT_GZ: &[u8] = include_bytes!("../data/cmudict/cmudict.txt.gz");

/// The CMU Pronouncing Dictionary (first pronunciation of each word), decompressed once.
pub fn dictionary() -> &'static BTreeMap<String, Vec<Phone>> {
    static DICT: OnceLock<BTreeMap<String, Vec<Phone>>> = OnceLock::new();
    DICT.get_or_init(|| {
        let mut text = String::new();
        flate2::read::GzDecoder::new(CMUDICT_GZ)
            .read_to_string(&mut text)
            .expect("embedded dictionary decompresses");
        text.lines()
            .filter_map(|l| {
                let mut it = l.split_whitespace();
                let word = it.next()?.to_owned();
                let phones: Option<Vec<Phone>> = it.map(Phone::parse).collect();
                Some((word, phones?))
            })
            .collect()
    })
}

/// Mean phone durations in seconds for read English speech, used when no codebook gives
/// its own: approximate figures of the kind reported for TIMIT (vowels ~70–160 ms,
/// consonants ~40–120 ms). Indexed like [`PHONES`].
pub const DEFAULT_DURATIONS: [f64; 40] = [
    0.20, 0.12, 0.13, 0.08, 0.12, 0.15, 0.14, 0.07, 0.10, 0.06, 0.04, 0.09, 0.11, 0.12, 0.10, 0.07,
    0.06, 0.07, 0.10, 0.09, 0.08, 0.07, 0.07, 0.06, 0.07, 0.12, 0.16, 0.08, 0.07, 0.11, 0.12, 0.07,
    0.10, 0.07, 0.10, 0.06, 0.06, 0.06, 0.09, 0.09,
];

/// Silence at the start and end of an utterance, and at a punctuation mark.
const EDGE_SILENCE: f64 = 0.2;
const PAUSE: f64 = 0.15;

/// Words of `text` → phone segments with durations from `durations` (seconds per phone,
/// indexed like [`PHONES`]). Silence opens and closes the utterance and marks `, . ; : ? !`.
/// Every word missing from the dictionary is listed in one error.
pub fn text_to_segments(text: &str, durations: &[f64; 40]) -> Result<Vec<Segment>, PhonemeError> {
    let dict = dictionary();
    let mut phones = vec![Phone::SIL];
    let mut missing = Vec::new();
    let mut words = 0;
    let mut word = String::new();
    let mut flush = |word: &mut String, phones: &mut Vec<Phone>, missing: &mut Vec<String>| {
        if word.is_empty() {
            return;
        }
        let w = word.trim_matches('\'').to_lowercase();
        match dict.get(&w) {
            Some(p) => phones.extend_from_slice(p),
            None => missing.push(w),
        }
        words += 1;
        word.clear();
    };
    for c in text.chars() {
        if c.is_alphanumeric() || c == '\'' {
            word.push(c);
        } else {
            flush(&mut word, &mut phones, &mut missing);
            if matches!(c, ',' | '.' | ';' | ':' | '?' | '!') && phones.last() != Some(&Phone::SIL)
            {
                phones.push(Phone::SIL);
            }
        }
    }
    flush(&mut word, &mut phones, &mut missing);
    if !missing.is_empty() {
        return Err(PhonemeError::OutOfDictionary(missing));
    }
    if words == 0 {
        return Err(PhonemeError::NoWords);
    }
    if phones.last() != Some(&Phone::SIL) {
        phones.push(Phone::SIL);
    }
    let mut t = 0.0;
    let last = phones.len() - 1;
    Ok(phones
        .iter()
        .enumerate()
        .map(|(i, &phone)| {
            let d = match phone {
                Phone::SIL if i == 0 || i == last => EDGE_SILENCE,
                Phone::SIL => PAUSE,
                p => durations[p.index()],
            };
            let s = Segment {
                start: t,
                end: t + d,
                phone,
            };
            t += d;
            s
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_phone_has_a_viseme_and_classes_match_the_table() {
        let class = |names: &[&str]| {
            names
                .iter()
                .map(|n| Phone::parse(n).unwrap().viseme())
                .collect::<Vec<_>>()
        };
        assert_eq!(class(&["p", "b", "m"]), vec![21; 3]);
        assert_eq!(class(&["f", "v"]), vec![18; 2]);
        assert_eq!(class(&["d", "t", "n"]), vec![19; 3]);
        assert_eq!(class(&["ae", "ax", "ah"]), vec![1; 3]);
        assert_eq!(class(&["iy", "y", "ih", "ix"]), vec![6; 4]);
        assert_eq!(class(&["sh", "ch", "jh", "zh"]), vec![16; 4]);
        assert_eq!(class(&["h", "hh"]), vec![12; 2]);
        assert_eq!(Phone::SIL.viseme(), 0);
        let used: std::collections::BTreeSet<u8> = Phone::all().map(|p| p.viseme()).collect();
        assert_eq!(used.len(), N_VISEMES, "all 22 classes are used");
    }

    #[test]
    fn labels_normalise() {
        assert_eq!(Phone::parse("AH0"), Phone::parse("ah"));
        assert_eq!(Phone::parse("sp"), Some(Phone::SIL));
        assert_eq!(Phone::parse(""), Some(Phone::SIL));
        assert_eq!(Phone::parse("ax").unwrap().name(), "ah");
        assert_eq!(Phone::parse("qq"), None);
    }
}
