//! Validation of numeric options and manifest fields at the API boundary: every check names
//! the option, the value given and the range allowed, before any work starts.

use thiserror::Error;

/// An option or field outside its allowed range.
#[derive(Clone, Debug, Error, PartialEq)]
#[error("{name} = {value} is out of range: {allowed}")]
pub struct InvalidOption {
    /// What was given (an option or manifest field).
    pub name: String,
    /// The value, as given.
    pub value: String,
    /// The allowed range, in words.
    pub allowed: String,
}

impl InvalidOption {
    /// An option `name` whose `value` is not `allowed`.
    pub fn new(
        name: impl Into<String>,
        value: impl std::fmt::Display,
        allowed: impl Into<String>,
    ) -> Self {
        InvalidOption {
            name: name.into(),
            value: value.to_string(),
            allowed: allowed.into(),
        }
    }
}

/// `value` if it is finite and within `[lo, hi]`.
pub fn in_range(name: &str, value: f64, lo: f64, hi: f64) -> Result<f64, InvalidOption> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(value)
    } else {
        let lo_text = if lo == f64::MIN_POSITIVE {
            "> 0".to_owned()
        } else {
            format!("≥ {lo}")
        };
        Err(InvalidOption::new(
            name,
            readable(value),
            format!("a finite number {lo_text} and ≤ {hi}"),
        ))
    }
}

/// A number as a person reads it: scientific notation when very small or very large (Rust's
/// `{}` prints 1e-300 as three hundred digits).
fn readable(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e9).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// `value` if it is within `[lo, hi]`.
pub fn count_in(name: &str, value: usize, lo: usize, hi: usize) -> Result<usize, InvalidOption> {
    if (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(InvalidOption::new(
            name,
            value,
            format!("a whole number from {lo} to {hi}"),
        ))
    }
}

/// `s` for an error message: whole up to `max` characters, else its first `max` and its size,
/// so an error never echoes megabytes (a 1 MB "word", a 100 KB manifest field).
pub fn clipped(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_owned()
    } else {
        let head: String = s.chars().take(max).collect();
        format!("{head}… ({} bytes)", s.len())
    }
}

/// Words for an error message: each [`clipped`] to 40 characters, at most 20 of them, then
/// how many more.
pub fn clipped_list(words: &[String]) -> String {
    let mut shown: Vec<String> = words.iter().take(20).map(|w| clipped(w, 40)).collect();
    if words.len() > 20 {
        shown.push(format!("and {} more", words.len() - 20));
    }
    shown.join(", ")
}
