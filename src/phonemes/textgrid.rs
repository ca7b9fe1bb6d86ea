//! Praat TextGrid files, long or short text form: one tokeniser serves both.

use std::path::Path;

use super::labels::{MAX_SEGMENTS, RawInterval, finish, read_text, too_many};

/// Most tiers a TextGrid may declare.
const MAX_TIERS: usize = 1000;
use super::{PhoneMap, PhonemeError, Segment};

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

/// The tokens of a TextGrid's text, produced as the parser asks for them (never all at once:
/// an absurd file costs the memory of one token, not of millions).
struct Tokens<'a> {
    chars: std::iter::Peekable<std::str::Chars<'a>>,
    line: usize,
    path: &'a Path,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str, path: &'a Path) -> Self {
        Tokens {
            chars: text.chars().peekable(),
            line: 1,
            path,
        }
    }
}

impl Iterator for Tokens<'_> {
    type Item = Result<(Token, usize), PhonemeError>;

    fn next(&mut self) -> Option<Self::Item> {
        let (chars, path) = (&mut self.chars, self.path);
        while let Some(c) = chars.next() {
            let line = self.line;
            match c {
                '\n' => self.line += 1,
                '"' => {
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
                                    self.line += 1;
                                }
                                s.push(ch);
                            }
                            None => {
                                return Some(Err(PhonemeError::Parse {
                                    path: path.into(),
                                    line,
                                    reason: "unterminated string".into(),
                                }));
                            }
                        }
                    }
                    return Some(Ok((Token::Str(s), line)));
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
                    return Some(Ok((Token::Flag, line)));
                }
                '!' => {
                    // a comment to the end of the line
                    while chars.peek().is_some_and(|&ch| ch != '\n') {
                        chars.next();
                    }
                }
                c if c.is_ascii_digit() || c == '-' || c == '.' || c == '+' => {
                    let mut s = String::from(c);
                    while chars.peek().is_some_and(|ch| {
                        ch.is_ascii_alphanumeric() || matches!(ch, '.' | '-' | '+')
                    }) {
                        s.push(chars.next().unwrap_or_default());
                    }
                    return Some(match s.parse::<f64>() {
                        Ok(v) => Ok((Token::Num(v), line)),
                        Err(_) => Err(PhonemeError::Parse {
                            path: path.into(),
                            line,
                            reason: format!("bad number {s:?}"),
                        }),
                    });
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
        None
    }
}

/// Parses TextGrid text (long or short form); `path` names the source in errors.
pub fn parse_textgrid(
    text: &str,
    path: &Path,
    tier: Option<&str>,
    map: &PhoneMap,
) -> Result<Vec<Segment>, PhonemeError> {
    let mut it = Tokens::new(text, path);
    let mut last_line = 1;
    let mut next = |what: &str| -> Result<(Token, usize), PhonemeError> {
        let t = it.next().ok_or_else(|| PhonemeError::Parse {
            path: path.into(),
            line: last_line,
            reason: format!("file ends where {what} was expected"),
        })??;
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
    let (n_tiers, l) = number!("the tier count");
    if !(0.0..=MAX_TIERS as f64).contains(&n_tiers) {
        return Err(err(
            l,
            format!("{n_tiers} tiers (at most {MAX_TIERS} are read)"),
        ));
    }
    let mut names = Vec::new();
    let mut found = None;
    for _ in 0..n_tiers as usize {
        let (kind, _) = string!("the tier class");
        let (name, _) = string!("the tier name");
        number!("tier xmin");
        number!("tier xmax");
        let (n, l) = number!("the interval count");
        if !(0.0..=MAX_SEGMENTS as f64).contains(&n) {
            return Err(too_many(path, l));
        }
        let wanted = found.is_none()
            && match tier {
                Some(t) => name == t,
                None => matches!(name.to_ascii_lowercase().as_str(), "phones" | "phonemes"),
            };
        let mut raw = Vec::new();
        for _ in 0..n as usize {
            if kind == "IntervalTier" {
                let (start, line) = number!("interval xmin");
                let (end, _) = number!("interval xmax");
                let (label, _) = string!("interval text");
                if !wanted {
                    continue;
                }
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
            found = Some(raw);
        }
        names.push(name);
    }
    // The counts the file declares must be what it holds: a tier declaring 10 intervals
    // followed by 10⁵ more is damaged, not to be read as its first 10.
    if let Some(extra) = it.next() {
        return Err(err(
            extra.map_or(last_line, |(_, line)| line),
            format!(
                "more content after the {n_tiers} tiers the file declares (an interval or tier count that is too small)"
            ),
        ));
    }
    if let Some(raw) = found {
        return finish(path, raw, map);
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

/// A TextGrid interval tier: its name and `(start, end, text)` intervals covering `0…xmax`.
pub struct Tier<'a> {
    /// The tier's name (`words`, `phones`).
    pub name: &'a str,
    /// Intervals in order; gaps are filled with empty intervals when written.
    pub intervals: Vec<(f64, f64, String)>,
}

/// Praat's long text form with one interval tier per `tiers` entry, as the Montreal Forced
/// Aligner writes it (silence as empty intervals).
pub fn format_textgrid(tiers: &[Tier], xmax: f64) -> String {
    let quote = |s: &str| s.replace('"', "\"\"");
    let mut out = format!(
        "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\n\nxmin = 0\nxmax = {xmax}\ntiers? <exists>\nsize = {}\nitem []:\n",
        tiers.len()
    );
    for (k, tier) in tiers.iter().enumerate() {
        // Fill gaps so that the intervals tile 0…xmax.
        let mut filled: Vec<(f64, f64, &str)> = Vec::new();
        let mut t = 0.0;
        for (s, e, text) in &tier.intervals {
            if *s > t + 1e-9 {
                filled.push((t, *s, ""));
            }
            filled.push((*s, *e, text));
            t = *e;
        }
        if xmax > t + 1e-9 {
            filled.push((t, xmax, ""));
        }
        out.push_str(&format!(
            "    item [{}]:\n        class = \"IntervalTier\"\n        name = \"{}\"\n        xmin = 0\n        xmax = {xmax}\n        intervals: size = {}\n",
            k + 1,
            quote(tier.name),
            filled.len()
        ));
        for (i, (s, e, text)) in filled.iter().enumerate() {
            out.push_str(&format!(
                "        intervals [{}]:\n            xmin = {s}\n            xmax = {e}\n            text = \"{}\"\n",
                i + 1,
                quote(text)
            ));
        }
    }
    out
}
