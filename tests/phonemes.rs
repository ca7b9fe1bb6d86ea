//! Phoneme timing files and text → phonemes.
use std::path::{Path, PathBuf};

use facespace::phonemes::{
    self, DEFAULT_DURATIONS, Phone, PhoneMap, PhonemeError, Segment, format_htk, format_tsv,
    parse_htk, parse_textgrid, parse_tsv, read_labels,
};
use proptest::prelude::*;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/labels")
        .join(name)
}

fn names(segments: &[Segment]) -> Vec<&'static str> {
    segments.iter().map(|s| s.phone.name()).collect()
}

#[test]
fn reads_an_mfa_textgrid() {
    let s = read_labels(
        &data("mfa_hello_world.TextGrid"),
        None,
        &PhoneMap::default(),
    )
    .unwrap();
    assert_eq!(
        names(&s),
        ["sil", "hh", "ah", "l", "ow", "w", "er", "l", "d", "sil"]
    );
    assert!((s[4].start - 0.4).abs() < 1e-12 && (s[4].end - 0.52).abs() < 1e-12);
    // Another tier by name.
    let words = read_labels(
        &data("mfa_hello_world.TextGrid"),
        Some("words"),
        &PhoneMap::default(),
    );
    assert!(
        matches!(words, Err(PhonemeError::UnknownLabel { ref label, .. }) if label == "hello"),
        "{words:?}"
    );
}

#[test]
fn reads_a_short_form_textgrid_skipping_point_tiers() {
    let s = read_labels(&data("praat_short.TextGrid"), None, &PhoneMap::default()).unwrap();
    assert_eq!(names(&s), ["sil", "m", "aa", "sil"]);
    let err = read_labels(
        &data("praat_short.TextGrid"),
        Some("nope"),
        &PhoneMap::default(),
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("\"events\"") && err.to_string().contains("\"phonemes\""),
        "{err}"
    );
}

#[test]
fn reads_an_hvite_label_file() {
    let s = read_labels(&data("hvite_hello.lab"), None, &PhoneMap::default()).unwrap();
    assert_eq!(names(&s), ["sil", "hh", "ah", "l", "ow", "sil"]);
    assert!((s[1].start - 0.17).abs() < 1e-12 && (s[5].end - 0.7).abs() < 1e-12);
}

#[test]
fn writers_round_trip() {
    let s = read_labels(
        &data("mfa_hello_world.TextGrid"),
        None,
        &PhoneMap::default(),
    )
    .unwrap();
    let back = parse_htk(&format_htk(&s), Path::new("x.lab"), &PhoneMap::default()).unwrap();
    assert_eq!(
        back, s,
        "HTK keeps 100 ns resolution, the file's times are multiples of 10 ms"
    );
    let back = parse_tsv(&format_tsv(&s), Path::new("x.tsv"), &PhoneMap::default()).unwrap();
    assert_eq!(back, s);
    let dir = tempfile::tempdir().unwrap();
    for name in ["a.lab", "a.tsv"] {
        phonemes::write_labels(&dir.path().join(name), &s).unwrap();
        assert_eq!(
            read_labels(&dir.path().join(name), None, &PhoneMap::default()).unwrap(),
            s
        );
    }
}

#[test]
fn phone_map_translates_other_sets() {
    let dir = tempfile::tempdir().unwrap();
    let map_path = dir.path().join("ipa.map");
    std::fs::write(&map_path, "# IPA to ARPAbet\nə ah\nʃ sh\n").unwrap();
    let map = PhoneMap::read(&map_path).unwrap();
    let s = parse_tsv(
        "0\t0.1\tə\n0.1\t0.2\tʃ\n0.2\t0.3\tm\n",
        Path::new("ipa.tsv"),
        &map,
    )
    .unwrap();
    assert_eq!(names(&s), ["ah", "sh", "m"]);
    std::fs::write(&map_path, "ə\n").unwrap();
    assert!(
        PhoneMap::read(&map_path)
            .unwrap_err()
            .to_string()
            .contains("ipa.map:1")
    );
    std::fs::write(&map_path, "ə qq\n").unwrap();
    assert!(
        PhoneMap::read(&map_path)
            .unwrap_err()
            .to_string()
            .contains("not an ARPAbet phone")
    );
}

#[test]
fn malformed_input_names_file_and_line() {
    let m = PhoneMap::default();
    let cases: Vec<(Result<Vec<Segment>, PhonemeError>, &str)> = vec![
        (
            parse_tsv("0 0.2 sil\n0.1 0.3 m\n", Path::new("o.tsv"), &m),
            "o.tsv:2: interval 0.1–0.3 overlaps",
        ),
        (
            parse_tsv("0.5 0.6 m\n0.1 0.3 aa\n", Path::new("u.tsv"), &m),
            "u.tsv:2: intervals out of order",
        ),
        (
            parse_tsv("-0.1 0.2 m\n", Path::new("n.tsv"), &m),
            "n.tsv:1: negative time",
        ),
        (
            parse_tsv("0.3 0.2 m\n", Path::new("r.tsv"), &m),
            "r.tsv:1: interval ends",
        ),
        (
            parse_tsv("0 0.2 xyz\n", Path::new("k.tsv"), &m),
            "k.tsv:1: unknown phone label \"xyz\"",
        ),
        (
            parse_tsv("start end label\n", Path::new("e.tsv"), &m),
            "e.tsv: no phone intervals",
        ),
        (
            parse_htk("0 100000\n", Path::new("h.lab"), &m),
            "h.lab:1: expected `start end label`",
        ),
        (
            parse_htk("0 1.5e5 m\n", Path::new("f.lab"), &m),
            "f.lab:1: bad time",
        ),
        (
            parse_textgrid(
                "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\n0\n1\n<exists>\n1\n\"IntervalTier\"\n\"phones\"\n0\n1\n0\n",
                Path::new("empty.TextGrid"),
                None,
                &m,
            ),
            "empty.TextGrid: no phone intervals",
        ),
        (
            parse_textgrid(
                "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\n0\n1\n<exists>\n1\n\"IntervalTier\"\n\"phones\"\n0\n1\n2\n0\n0.5\n\"m\"\n",
                Path::new("cut.TextGrid"),
                None,
                &m,
            ),
            "cut.TextGrid:14: file ends",
        ),
        (
            parse_textgrid(
                "File type = \"ooTextFile\"\nObject class = \"Sound\"\n",
                Path::new("s.TextGrid"),
                None,
                &m,
            ),
            "s.TextGrid:2: object class",
        ),
    ];
    for (result, needle) in cases {
        let msg = result.unwrap_err().to_string();
        assert!(msg.contains(needle), "expected {needle:?} in {msg:?}");
    }
}

#[test]
fn utf16_textgrid_with_bom() {
    let text = std::fs::read_to_string(data("praat_short.TextGrid")).unwrap();
    let mut bytes = vec![0xFF, 0xFE];
    bytes.extend(text.encode_utf16().flat_map(|u| u.to_le_bytes()));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("u16.TextGrid");
    std::fs::write(&path, bytes).unwrap();
    assert_eq!(
        names(&read_labels(&path, None, &PhoneMap::default()).unwrap()),
        ["sil", "m", "aa", "sil"]
    );
}

#[test]
fn text_to_phonemes_uses_the_dictionary() {
    let s = phonemes::text_to_segments("Hello, world!", &DEFAULT_DURATIONS).unwrap();
    assert_eq!(
        names(&s),
        [
            "sil", "hh", "ah", "l", "ow", "sil", "w", "er", "l", "d", "sil"
        ]
    );
    for w in s.windows(2) {
        assert_eq!(w[0].end, w[1].start, "contiguous");
    }
    assert_eq!(
        s[1].duration(),
        DEFAULT_DURATIONS[Phone::parse("hh").unwrap().index()]
    );
    let err = phonemes::text_to_segments("hello zzyzzx qwrtpz", &DEFAULT_DURATIONS).unwrap_err();
    assert_eq!(
        err.to_string(),
        "words not in the pronouncing dictionary: zzyzzx, qwrtpz"
    );
    assert!(matches!(
        phonemes::text_to_segments(" ,. ", &DEFAULT_DURATIONS),
        Err(PhonemeError::NoWords)
    ));
}

proptest! {
    #[test]
    fn tsv_and_htk_parsers_never_panic(text in "([-0-9.e ]{0,10}[\t ][-0-9.e]{0,8}[\t ][a-zA-Z0-9]{0,4}\n){0,6}") {
        let _ = parse_tsv(&text, Path::new("f.tsv"), &PhoneMap::default());
        let _ = parse_htk(&text, Path::new("f.lab"), &PhoneMap::default());
    }

    #[test]
    fn textgrid_parser_never_panics(text in "(File type = \"ooTextFile\"\nObject class = \"TextGrid\"\n)?([-0-9.]{0,5}|\"[a-z]{0,3}\"?|<exists>|\\[|item \\[1\\]:|\n| ){0,40}") {
        let _ = parse_textgrid(&text, Path::new("f.TextGrid"), None, &PhoneMap::default());
    }

    #[test]
    fn textgrid_parser_never_panics_on_corrupted_real_file(cut in 0usize..2000, junk in "[\"<>\\[\\]0-9a-z =\n]{0,5}") {
        let text = std::fs::read_to_string(data("mfa_hello_world.TextGrid")).unwrap();
        let cut = cut.min(text.len());
        let cut = (0..=cut).rev().find(|&i| text.is_char_boundary(i)).unwrap_or(0);
        let corrupted = format!("{}{}{}", &text[..cut], junk, &text[cut..]);
        let _ = parse_textgrid(&corrupted, Path::new("f.TextGrid"), None, &PhoneMap::default());
    }
}
