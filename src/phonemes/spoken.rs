//! Text as it is spoken (issue 66): numbers, money, percentages, ordinals, clock times and
//! years written out in words, so that text as agents and people write it ("paid $1,250 for
//! 3 maps on March 14th, 2024 at 7:30 pm") can be spoken by a text-to-speech engine and
//! aligned by the pronouncing dictionary, both hearing the same words. American English
//! readings: "$3.50" → "three dollars and fifty cents", "1999" → "nineteen ninety nine",
//! "2005" → "two thousand five", "7:05" → "seven oh five". Anything else passes unchanged.

const ONES: [&str; 20] = [
    "zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
    "eleven", "twelve", "thirteen", "fourteen", "fifteen", "sixteen", "seventeen", "eighteen",
    "nineteen",
];
const TENS: [&str; 10] = [
    "", "", "twenty", "thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety",
];
const SCALES: [(u64, &str); 4] = [
    (1_000_000_000_000, "trillion"),
    (1_000_000_000, "billion"),
    (1_000_000, "million"),
    (1_000, "thousand"),
];

/// `n` in words ("one thousand two hundred fifty").
pub fn cardinal(n: u64) -> String {
    if n < 20 {
        return ONES[n as usize].to_owned();
    }
    if n < 100 {
        let (t, o) = (n / 10, n % 10);
        return if o == 0 {
            TENS[t as usize].to_owned()
        } else {
            format!("{} {}", TENS[t as usize], ONES[o as usize])
        };
    }
    if n < 1000 {
        let rest = n % 100;
        let head = format!("{} hundred", ONES[(n / 100) as usize]);
        return if rest == 0 { head } else { format!("{head} {}", cardinal(rest)) };
    }
    for (scale, name) in SCALES {
        if n >= scale {
            let rest = n % scale;
            let head = format!("{} {name}", cardinal(n / scale));
            return if rest == 0 { head } else { format!("{head} {}", cardinal(rest)) };
        }
    }
    unreachable!("n ≥ 1000 has a scale")
}

/// The ordinal of `n` in words ("fourteenth", "twenty first", "one hundredth").
pub fn ordinal(n: u64) -> String {
    let words = cardinal(n);
    let (head, last) = match words.rsplit_once(' ') {
        Some((h, l)) => (format!("{h} "), l.to_owned()),
        None => (String::new(), words.clone()),
    };
    let last = match last.as_str() {
        "one" => "first".to_owned(),
        "two" => "second".to_owned(),
        "three" => "third".to_owned(),
        "five" => "fifth".to_owned(),
        "eight" => "eighth".to_owned(),
        "nine" => "ninth".to_owned(),
        "twelve" => "twelfth".to_owned(),
        l if l.ends_with('y') => format!("{}ieth", &l[..l.len() - 1]),
        l => format!("{l}th"),
    };
    format!("{head}{last}")
}

/// A year as said: "nineteen ninety nine", "two thousand five", "twenty twenty four".
pub fn year(n: u64) -> String {
    let (century, rest) = (n / 100, n % 100);
    if !(11..=20).contains(&century) || (century % 10 == 0 && rest < 10) {
        return cardinal(n);
    }
    match rest {
        0 => format!("{} hundred", cardinal(century)),
        1..=9 => format!("{} oh {}", cardinal(century), ONES[rest as usize]),
        _ => format!("{} {}", cardinal(century), cardinal(rest)),
    }
}

/// Digits, with thousands commas, as a number (`None` past a trillion trillion or if not a
/// number).
fn integer(s: &str) -> Option<u64> {
    let plain: String = s.chars().filter(|&c| c != ',').collect();
    if plain.is_empty() || !plain.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    // Commas only as thousands separators.
    if s.contains(',') {
        let groups: Vec<&str> = s.split(',').collect();
        let well_formed = (1..=3).contains(&groups[0].len()) && groups[1..].iter().all(|g| g.len() == 3);
        if !well_formed {
            return None;
        }
    }
    plain.parse().ok()
}

/// Digits after a decimal point, said one by one ("point five oh").
fn decimals(s: &str) -> String {
    s.chars()
        .map(|c| if c == '0' { "oh" } else { ONES[c.to_digit(10).unwrap_or(0) as usize] })
        .collect::<Vec<_>>()
        .join(" ")
}

/// A number written with digits (and maybe a decimal part) in words; `year_like` reads four
/// digits without a comma as a year.
fn number(s: &str, year_like: bool) -> Option<String> {
    let (whole, fraction) = match s.split_once('.') {
        Some((w, f)) if !f.is_empty() && f.chars().all(|c| c.is_ascii_digit()) => (w, Some(f)),
        Some(_) => return None,
        None => (s, None),
    };
    let n = integer(whole)?;
    let head = if year_like && fraction.is_none() && whole.len() == 4 && !whole.contains(',') && (1100..2100).contains(&n) {
        year(n)
    } else {
        cardinal(n)
    };
    Some(match fraction {
        Some(f) => format!("{head} point {}", decimals(f)),
        None => head,
    })
}

/// Money: "$1,250" → "one thousand two hundred fifty dollars", "$3.50" → "three dollars and
/// fifty cents" (pounds and pence, euros and cents alike).
fn money(amount: &str, unit: (&str, &str), cents: (&str, &str)) -> Option<String> {
    let (whole, fraction) = match amount.split_once('.') {
        Some((w, f)) if f.len() == 2 && f.chars().all(|c| c.is_ascii_digit()) => (w, Some(f)),
        Some(_) => return None,
        None => (amount, None),
    };
    let n = integer(whole)?;
    let plural = |k: u64, (one, many): (&str, &str)| format!("{} {}", cardinal(k), if k == 1 { one } else { many });
    let c = fraction.map_or(0, |f| f.parse::<u64>().unwrap_or(0));
    Some(match (n, c) {
        (_, 0) => plural(n, unit),
        (0, c) => plural(c, cents),
        (n, c) => format!("{} and {}", plural(n, unit), plural(c, cents)),
    })
}

/// A clock time "7:30" → "seven thirty", "7:05" → "seven oh five", "7:00" → "seven o'clock".
fn clock(s: &str) -> Option<String> {
    let (h, m) = s.split_once(':')?;
    let (h, m): (u64, u64) = (h.parse().ok()?, m.parse().ok()?);
    if h > 24 || m > 59 || s.split_once(':')?.1.len() != 2 {
        return None;
    }
    Some(match m {
        0 => format!("{} o'clock", cardinal(h)),
        1..=9 => format!("{} oh {}", cardinal(h), ONES[m as usize]),
        _ => format!("{} {}", cardinal(h), cardinal(m)),
    })
}

/// One whitespace-separated token with digits in words, its surrounding punctuation kept;
/// `None` when it is not one this module reads.
fn token(t: &str) -> Option<String> {
    let start = t.find(|c: char| c.is_ascii_digit() || "$£€-".contains(c))?;
    let end = t.rfind(|c: char| c.is_ascii_alphanumeric() || c == '%')? + 1;
    if end <= start {
        return None;
    }
    let (before, core, after) = (&t[..start], &t[start..end], &t[end..]);
    let said = if let Some(rest) = core.strip_prefix('$') {
        money(rest, ("dollar", "dollars"), ("cent", "cents"))?
    } else if let Some(rest) = core.strip_prefix('£') {
        money(rest, ("pound", "pounds"), ("penny", "pence"))?
    } else if let Some(rest) = core.strip_prefix('€') {
        money(rest, ("euro", "euros"), ("cent", "cents"))?
    } else if let Some(rest) = core.strip_suffix('%') {
        format!("{} percent", number(rest, false)?)
    } else if let Some(rest) = core.strip_prefix('-') {
        format!("minus {}", number(rest, false)?)
    } else if core.contains(':') {
        clock(core)?
    } else if let Some(digits) = ["st", "nd", "rd", "th"].iter().find_map(|s| core.strip_suffix(s)) {
        ordinal(integer(digits)?)
    } else {
        number(core, true)?
    };
    Some(format!("{before}{said}{after}"))
}

/// `text` with every number this module reads written out in words (see the module docs);
/// "am" and "pm" after a clock time become the letters "a m" and "p m". Text without digits
/// comes back unchanged.
pub fn written_out(text: &str) -> String {
    if !text.chars().any(|c| c.is_ascii_digit()) {
        return text.to_owned();
    }
    let mut out: Vec<String> = Vec::new();
    let mut after_clock = false;
    for t in text.split_whitespace() {
        let bare = t.trim_matches(|c: char| !c.is_alphanumeric()).to_ascii_lowercase();
        if after_clock && (bare == "am" || bare == "pm") {
            out.push(t.to_ascii_lowercase().replacen(&bare, &format!("{} m", &bare[..1]), 1));
            after_clock = false;
            continue;
        }
        after_clock = t.contains(':') && t.chars().any(|c| c.is_ascii_digit());
        out.push(token(t).unwrap_or_else(|| t.to_owned()));
    }
    out.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_as_they_are_said() {
        assert_eq!(cardinal(0), "zero");
        assert_eq!(cardinal(15), "fifteen");
        assert_eq!(cardinal(40), "forty");
        assert_eq!(cardinal(99), "ninety nine");
        assert_eq!(cardinal(100), "one hundred");
        assert_eq!(cardinal(1_250), "one thousand two hundred fifty");
        assert_eq!(cardinal(2_000_017), "two million seventeen");
        assert_eq!(ordinal(1), "first");
        assert_eq!(ordinal(14), "fourteenth");
        assert_eq!(ordinal(21), "twenty first");
        assert_eq!(ordinal(30), "thirtieth");
        assert_eq!(ordinal(100), "one hundredth");
        assert_eq!(ordinal(112), "one hundred twelfth");
        assert_eq!(year(1999), "nineteen ninety nine");
        assert_eq!(year(1905), "nineteen oh five");
        assert_eq!(year(1900), "nineteen hundred");
        assert_eq!(year(2000), "two thousand");
        assert_eq!(year(2005), "two thousand five");
        assert_eq!(year(2024), "twenty twenty four");
    }

    #[test]
    fn text_as_agents_write_it() {
        assert_eq!(
            written_out("I paid $1,250 for 3 maps on March 14th, 2024 at 7:30 pm."),
            "I paid one thousand two hundred fifty dollars for three maps on March fourteenth, twenty twenty four at seven thirty p m."
        );
        assert_eq!(written_out("$3.50, £1 or €0.99"), "three dollars and fifty cents, one pound or ninety nine cents");
        assert_eq!(written_out("Up 12.5% to -4 at 9:05 am"), "Up twelve point five percent to minus four at nine oh five a m");
        assert_eq!(written_out("(1,000,000)"), "(one million)");
        // Not numbers this module reads: left as they are for the dictionary to judge.
        assert_eq!(written_out("B2B 3D 1,00 I am"), "B2B 3D 1,00 I am");
        assert_eq!(written_out("no digits here"), "no digits here");
        // Every word it writes is a plain word.
        let said = written_out("0 1 2 3 4 5 6 7 8 9 10 11 12 13 20 47 100 1001 7th 2nd 3rd 22nd 10:00");
        assert!(said.split_whitespace().all(|w| w.chars().all(|c| c.is_ascii_lowercase() || c == '\'')), "{said}");
    }
}
