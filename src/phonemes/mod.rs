//! Phone set, viseme classes, phoneme-timing files ([`labels`]: HTK, TextGrid, TSV) and text →
//! phonemes ([`mod@dictionary`]) (DESIGN §6).
//!
//! Labels are normalised to ARPAbet (the 39 CMU phones, stress digits dropped, case folded)
//! plus `sil`; `sil`, `sp`, `pau`, `spn` and the empty label are silence. A few common
//! ARPAbet extensions (TIMIT/SAPI `ax`, `ix`, `h`, `axr`, `ux`, `el`, `em`, `en`, `nx`, `dx`)
//! fold onto their nearest CMU phone; any other set needs a [`PhoneMap`].

pub mod dictionary;
pub mod labels;
pub mod spoken;
mod textgrid;
pub use textgrid::{Tier, format_textgrid};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use dictionary::{DEFAULT_DURATIONS, pronunciation, text_to_segments};
pub use labels::{
    format_htk, format_tsv, parse_htk, parse_textgrid, parse_tsv, read_htk, read_labels,
    read_textgrid, read_tsv, write_labels,
};

use labels::read_text;

/// The phones, `sil` first; a [`Phone`] is an index into this list.
pub const PHONES: [&str; 40] = [
    "sil", "aa", "ae", "ah", "ao", "aw", "ay", "b", "ch", "d", "dh", "eh", "er", "ey", "f", "g",
    "hh", "ih", "iy", "jh", "k", "l", "m", "n", "ng", "ow", "oy", "p", "r", "s", "sh", "t", "th",
    "uh", "uw", "v", "w", "y", "z", "zh",
];

/// Viseme class of each phone in [`PHONES`] order: the 22 classes of \[unitsel\] Table 1.
const VISEMES: [u8; 40] = [
    0, 2, 1, 1, 3, 9, 11, 21, 16, 19, 17, 4, 5, 4, 18, 20, 12, 6, 6, 16, //
    20, 14, 21, 19, 20, 8, 10, 21, 13, 15, 16, 19, 17, 4, 7, 18, 7, 6, 15, 16,
];

/// Number of viseme classes.
pub const N_VISEMES: usize = 22;

/// Mouth shape per viseme class: (lip-opening, mouth-width) as quantiles over a talker's
/// frames, 0 = least, 1 = most — the generated corpus's targets, and the distance by which a
/// phone whose whole class is missing from a codebook borrows the nearest class present.
pub const VISEME_MOUTHS: [(f64, f64); N_VISEMES] = [
    (0.05, 0.45), // 0 silence: closed, relaxed
    (0.80, 0.60), // 1 ae ah
    (1.00, 0.50), // 2 aa
    (0.80, 0.20), // 3 ao
    (0.60, 0.60), // 4 ey eh uh
    (0.35, 0.25), // 5 er
    (0.35, 0.95), // 6 iy y ih
    (0.25, 0.00), // 7 w uw
    (0.60, 0.10), // 8 ow
    (0.90, 0.30), // 9 aw
    (0.60, 0.15), // 10 oy
    (0.90, 0.60), // 11 ay
    (0.50, 0.50), // 12 hh
    (0.35, 0.15), // 13 r
    (0.50, 0.55), // 14 l
    (0.25, 0.85), // 15 s z
    (0.35, 0.10), // 16 sh ch jh zh
    (0.30, 0.60), // 17 th dh
    (0.15, 0.55), // 18 f v
    (0.35, 0.70), // 19 d t n
    (0.45, 0.55), // 20 k g ng
    (0.00, 0.40), // 21 p b m
];

/// The viseme classes by mouth-shape distance from `class` (itself first; ties by index).
pub fn nearest_visemes(class: u8) -> Vec<u8> {
    let (o, w) = VISEME_MOUTHS[class as usize];
    let d = |c: u8| {
        let (p, q) = VISEME_MOUTHS[c as usize];
        (p - o).powi(2) + (q - w).powi(2)
    };
    let mut order: Vec<u8> = (0..N_VISEMES as u8).collect();
    order.sort_by(|&a, &b| d(a).total_cmp(&d(b)).then(a.cmp(&b)));
    order
}

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
    /// Silence.
    pub const SIL: Phone = Phone(0);
    /// Number of phones.
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

    /// The phone at index `i` of [`PHONES`].
    pub fn from_index(i: usize) -> Option<Phone> {
        (i < PHONES.len()).then_some(Phone(i as u8))
    }

    /// Index into [`PHONES`] (and the rows of S and M).
    pub fn index(self) -> usize {
        self.0 as usize
    }

    /// The ARPAbet name, lower case.
    pub fn name(self) -> &'static str {
        PHONES[self.index()]
    }

    /// Viseme class, 0–21 (DESIGN §6).
    pub fn viseme(self) -> u8 {
        VISEMES[self.index()]
    }

    /// Every phone, in index order.
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
    /// Start, seconds.
    pub start: f64,
    /// End, seconds.
    pub end: f64,
    /// The phone.
    pub phone: Phone,
}

impl Segment {
    /// `end − start`.
    pub fn duration(&self) -> f64 {
        self.end - self.start
    }
}

/// What can be wrong with phone labels or text.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PhonemeError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A malformed line.
    #[error("{path}:{line}: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The line (1-based).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A label that is no known phone.
    #[error("{path}:{line}: unknown phone label {label:?} (give a phone map for other phone sets)")]
    UnknownLabel {
        /// The file.
        path: PathBuf,
        /// The line (1-based).
        line: usize,
        /// The label.
        label: String,
    },
    /// A TextGrid without the tier asked for.
    #[error("{path}: no tier named {wanted}; the tiers are {found:?}")]
    NoTier {
        /// The file.
        path: PathBuf,
        /// The tier looked for.
        wanted: String,
        /// The tiers there are.
        found: Vec<String>,
    },
    /// A file without intervals.
    #[error("{path}: no phone intervals")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// Words the dictionary lacks.
    #[error("words not in the pronouncing dictionary: {}", crate::options::clipped_list(.0))]
    OutOfDictionary(Vec<String>),
    /// Text without words.
    #[error("no words in the text")]
    NoWords,
}

/// A mapping from another phone set's labels to ARPAbet, read from a two-column file
/// (`label<whitespace>arpabet`, `#` comments).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PhoneMap(BTreeMap<String, Phone>);

impl PhoneMap {
    /// Reads a map file, naming the line of any error.
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
