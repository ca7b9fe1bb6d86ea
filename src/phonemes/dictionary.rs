//! Text → phones: the embedded CMU Pronouncing Dictionary and a duration table.

use std::collections::HashMap;
use std::io::Read;
use std::sync::OnceLock;

use super::{Phone, PhonemeError, Segment};

static CMUDICT_GZ: &[u8] = include_bytes!("../../data/cmudict/cmudict.txt.gz");

/// The CMU Pronouncing Dictionary, decompressed once: each word with the rest of its line.
/// The phones are parsed only for the words looked up — parsing all 126 k entries into a
/// map took 0.2 s of every synthesis from text.
fn entries() -> &'static HashMap<&'static str, &'static str> {
    static ENTRIES: OnceLock<HashMap<&'static str, &'static str>> = OnceLock::new();
    ENTRIES.get_or_init(|| {
        let mut text = String::new();
        flate2::read::GzDecoder::new(CMUDICT_GZ)
            .read_to_string(&mut text)
            .expect("embedded dictionary decompresses");
        // Kept for the life of the program, as the map itself is.
        let text: &'static str = Box::leak(text.into_boxed_str());
        text.lines()
            .filter_map(|l| {
                let l = l.trim();
                let word = l.split_whitespace().next()?;
                Some((word, &l[word.len()..]))
            })
            .collect()
    })
}

/// A word's phones: its pronunciation in the CMU Pronouncing Dictionary (lower case, as the
/// dictionary spells it), when it has one made of our phones.
pub fn pronunciation(word: &str) -> Option<Vec<Phone>> {
    entries().get(word)?.split_whitespace().map(Phone::parse).collect()
}

/// Mean phone durations in seconds for read English speech, used when no codebook gives
/// its own: approximate figures of the kind reported for TIMIT (vowels ~70–160 ms,
/// consonants ~40–120 ms). Indexed like [`super::PHONES`].
pub const DEFAULT_DURATIONS: [f64; 40] = [
    0.20, 0.12, 0.13, 0.08, 0.12, 0.15, 0.14, 0.07, 0.10, 0.06, 0.04, 0.09, 0.11, 0.12, 0.10, 0.07,
    0.06, 0.07, 0.10, 0.09, 0.08, 0.07, 0.07, 0.06, 0.07, 0.12, 0.16, 0.08, 0.07, 0.11, 0.12, 0.07,
    0.10, 0.07, 0.10, 0.06, 0.06, 0.06, 0.09, 0.09,
];

/// Silence at the start and end of an utterance, and at a punctuation mark.
const EDGE_SILENCE: f64 = 0.2;
const PAUSE: f64 = 0.15;

/// Words of `text` → phone segments with durations from `durations` (seconds per phone,
/// indexed like [`super::PHONES`]). Silence opens and closes the utterance and marks `, . ; : ? !`.
/// Every word missing from the dictionary is listed in one error.
pub fn text_to_segments(text: &str, durations: &[f64; 40]) -> Result<Vec<Segment>, PhonemeError> {
    let text = &super::spoken::written_out(text);
    let mut phones = vec![Phone::SIL];
    let mut missing = Vec::new();
    let mut words = 0;
    let mut word = String::new();
    let mut flush = |word: &mut String, phones: &mut Vec<Phone>, missing: &mut Vec<String>| {
        if word.is_empty() {
            return;
        }
        let w = word.trim_matches('\'').to_lowercase();
        match pronunciation(&w) {
            Some(p) => phones.extend_from_slice(&p),
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
