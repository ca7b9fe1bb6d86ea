//! The pronouncing dictionary of the acoustic model (CMUdict in Sphinx form: `word P H O N`,
//! alternatives as `word(2)`, no stress digits), with the user's additions.

use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

use super::{AcousticModel, AlignError};

/// Words → their pronunciations (CI phone ids of the model), in the dictionary's order: the
/// model's dictionary kept as text and searched by bisection (it is sorted by headword, so
/// loading costs one decompression, not 135 000 insertions), plus the user's additions.
pub struct Dictionary {
    text: String,
    /// Start of every line of `text`.
    lines: Vec<u32>,
    added: HashMap<String, Vec<Vec<u8>>>,
    path: std::path::PathBuf,
}

/// The words of a transcript: lower case, split at anything but letters, digits and
/// apostrophes, with apostrophes at a word's ends dropped.
pub fn words(text: &str) -> Vec<String> {
    text.split(|c: char| !(c.is_alphanumeric() || c == '\''))
        .map(|w| w.trim_matches('\'').to_lowercase())
        .filter(|w| !w.is_empty())
        .collect()
}

/// How many words [`words`] finds in `text`, without making them (a 20 MB transcript is
/// judged against its audio before millions of strings are built).
pub fn word_count(text: &str) -> usize {
    text.split(|c: char| !(c.is_alphanumeric() || c == '\''))
        .filter(|w| !w.trim_matches('\'').is_empty())
        .count()
}

/// A line's headword without its `(n)` alternative marker, and its phones.
fn split_entry(line: &str) -> Option<(&str, std::str::SplitWhitespace<'_>)> {
    let line = line.split('#').next().unwrap_or("").trim();
    let mut it = line.split_whitespace();
    let head = it.next()?;
    let word = match head.find('(') {
        Some(i) if head.ends_with(')') && i > 0 => &head[..i],
        _ => head,
    };
    Some((word, it))
}

fn read_text(path: &Path) -> Result<String, AlignError> {
    let io = |e: std::io::Error| AlignError::Dictionary {
        path: path.to_owned(),
        line: 0,
        why: e.to_string(),
    };
    let raw = crate::safe_read::read_regular(path).map_err(io)?;
    if raw.starts_with(&[0x1f, 0x8b]) {
        let mut s = String::new();
        flate2::read::GzDecoder::new(&raw[..])
            .read_to_string(&mut s)
            .map_err(io)?;
        Ok(s)
    } else {
        String::from_utf8(raw).map_err(|_| AlignError::Dictionary {
            path: path.to_owned(),
            line: 0,
            why: "not UTF-8 text".into(),
        })
    }
}

impl Dictionary {
    /// Reads the model's dictionary (gzipped or plain, sorted by headword as CMUdict is).
    pub fn load(path: &Path, _model: &AcousticModel) -> Result<Self, AlignError> {
        let text = read_text(path)?;
        let mut lines = vec![0u32];
        lines.extend(text.match_indices('\n').map(|(i, _)| i as u32 + 1));
        if lines.last() == Some(&(text.len() as u32)) {
            lines.pop();
        }
        let d = Dictionary {
            text,
            lines,
            added: HashMap::new(),
            path: path.to_owned(),
        };
        // Bisection needs sorted headwords: check it once, cheaply, on a sample.
        let heads: Vec<&str> = (0..d.lines.len())
            .step_by(997)
            .filter_map(|i| d.head(i))
            .collect();
        if heads.windows(2).any(|w| w[0] > w[1]) {
            return Err(AlignError::Dictionary {
                path: path.to_owned(),
                line: 0,
                why: "headwords are not sorted (CMUdict order); add such files with --dict".into(),
            });
        }
        Ok(d)
    }

    fn line(&self, i: usize) -> &str {
        let start = self.lines[i] as usize;
        let end = self
            .lines
            .get(i + 1)
            .map_or(self.text.len(), |&e| e as usize);
        self.text[start..end].trim_end()
    }

    fn head(&self, i: usize) -> Option<&str> {
        split_entry(self.line(i)).map(|(w, _)| w)
    }

    /// Adds the pronunciations of a file (after those already known for the same word).
    pub fn add_file(&mut self, path: &Path, model: &AcousticModel) -> Result<(), AlignError> {
        let text = read_text(path)?;
        self.add_text(&text, path, model)
    }

    /// Adds `word PHONES…` lines (`#` starts a comment; a `(n)` suffix marks an alternative).
    pub fn add_text(
        &mut self,
        text: &str,
        path: &Path,
        model: &AcousticModel,
    ) -> Result<(), AlignError> {
        for (n, line) in text.lines().enumerate() {
            let Some((word, phones)) = split_entry(line) else {
                continue;
            };
            let pron = parse_pron(phones, model).map_err(|why| AlignError::Dictionary {
                path: path.to_owned(),
                line: n + 1,
                why: format!("{word:?}: {why}"),
            })?;
            let prons = self.added.entry(word.to_lowercase()).or_default();
            if !prons.contains(&pron) {
                prons.push(pron);
            }
        }
        Ok(())
    }

    /// Every pronunciation the dictionary holds (lines it cannot read are skipped): what a
    /// phone language model is estimated from.
    pub fn every_pronunciation(&self, model: &AcousticModel) -> Vec<Vec<u8>> {
        let mut out: Vec<Vec<u8>> = (0..self.lines.len())
            .filter_map(|i| split_entry(self.line(i)))
            .filter_map(|(_, phones)| parse_pron(phones, model).ok())
            .collect();
        out.extend(self.added.values().flatten().cloned());
        out
    }

    /// Every pronunciation of `word` (lower case): the model dictionary's, then the added ones.
    fn lookup(&self, word: &str, model: &AcousticModel) -> Result<Vec<Vec<u8>>, AlignError> {
        // First line whose headword is not below `word` (blank lines sort first).
        let (mut lo, mut hi) = (0, self.lines.len());
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.head(mid).is_none_or(|h| h < word) {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        let first = lo;
        let mut prons = Vec::new();
        for i in first..self.lines.len() {
            let Some((head, phones)) = split_entry(self.line(i)) else {
                break;
            };
            if head != word {
                break;
            }
            let pron = parse_pron(phones, model).map_err(|why| AlignError::Dictionary {
                path: self.path.clone(),
                line: i + 1,
                why: format!("{word:?}: {why}"),
            })?;
            if !prons.contains(&pron) {
                prons.push(pron);
            }
        }
        for p in self.added.get(word).into_iter().flatten() {
            if !prons.contains(p) {
                prons.push(p.clone());
            }
        }
        Ok(prons)
    }

    /// Every pronunciation of every word; all the words missing are named in one error.
    pub fn pronunciations(
        &self,
        words: &[String],
        model: &AcousticModel,
    ) -> Result<Vec<Vec<Vec<u8>>>, AlignError> {
        let mut found = Vec::with_capacity(words.len());
        let mut missing: Vec<String> = Vec::new();
        for w in words {
            let prons = self.lookup(w, model)?;
            if prons.is_empty() {
                if !missing.contains(w) {
                    missing.push(w.clone());
                }
            } else {
                found.push(prons);
            }
        }
        if !missing.is_empty() {
            return Err(AlignError::OutOfDictionary(missing));
        }
        Ok(found)
    }

    /// Whether the dictionary knows `word` (lower case).
    pub fn contains(&self, word: &str, model: &AcousticModel) -> bool {
        self.lookup(word, model).is_ok_and(|p| !p.is_empty())
    }
}

/// Phone names → CI ids (upper case, stress digits dropped; fillers refused).
fn parse_pron(
    phones: std::str::SplitWhitespace<'_>,
    model: &AcousticModel,
) -> Result<Vec<u8>, String> {
    let mut pron = Vec::new();
    for p in phones {
        let name = p.trim_end_matches(|c: char| c.is_ascii_digit());
        match model.ci(name).filter(|&c| !model.is_filler(c)) {
            Some(c) => pron.push(c as u8),
            None => return Err(format!("{p:?} is not a phone of the acoustic model")),
        }
    }
    if pron.is_empty() {
        return Err("no phones".into());
    }
    Ok(pron)
}

#[cfg(test)]
mod tests {
    /// The count is the number of words made, on text of every kind of separator.
    #[test]
    fn word_count_counts_the_words_made() {
        for text in ["", "  ", "Hello, world!", "'tis the cats' toys", "a-b--c ' '' 1,250 o'clock", "ünïcode wörds—and dashes"] {
            assert_eq!(super::word_count(text), super::words(text).len(), "{text:?}");
        }
    }
}
