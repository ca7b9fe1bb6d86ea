//! Issue 26, item 2: a phone whose whole viseme class is missing from the codebook is
//! borrowed from the nearest class present (by mouth shape), with a warning naming both —
//! by blend (the default) as by unit selection; `--strict` refuses instead.
use crate::common;

use facespace::corpus::demo::Split;
use facespace::phonemes::Phone;

#[test]
fn missing_viseme_classes_are_borrowed_and_named() {
    let (_, generated, cb) = common::demo_corpus_codebook();
    let v = Phone::parse("v").unwrap().viseme();
    let ow = Phone::parse("ow").unwrap().viseme();
    let kept: Vec<_> = generated
        .part(Split::Train)
        .into_iter()
        .filter(|s| {
            s.segments
                .iter()
                .all(|g| g.phone.viseme() != v && g.phone.viseme() != ow)
        })
        .collect();
    assert!(
        kept.len() >= 5,
        "{} sentences without /v/ or /ow/ classes",
        kept.len()
    );
    let without = common::codebook_like(&cb, kept);
    for p in ["v", "f", "ow"] {
        assert!(
            !without.present().contains(&Phone::parse(p).unwrap()),
            "{p} present"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let cb_dir = dir.path().join("cb");
    without.save(&cb_dir).unwrap();
    for mode in ["blend", "unit"] {
        let out = dir.path().join(mode);
        let o = common::facespace(&[
            "synth",
            "--codebook",
            cb_dir.to_str().unwrap(),
            "--text",
            "Move the big boat.",
            "--mode",
            mode,
            "-o",
            out.to_str().unwrap(),
        ]);
        let t = common::text(&o);
        assert!(o.status.success(), "{mode}: {t}");
        assert!(out.join("video.mp4").is_file(), "{mode}: no video");
        assert!(
            t.contains("/v/") && t.contains("/ow/"),
            "{mode}: substitutes not named: {t}"
        );
        assert!(
            t.contains("no --background"),
            "{mode}: no warning about the plain background: {t}"
        );
    }
    let o = common::facespace(&[
        "synth",
        "--codebook",
        cb_dir.to_str().unwrap(),
        "--text",
        "Move the big boat.",
        "--strict",
        "-o",
        dir.path().join("strict").to_str().unwrap(),
    ]);
    let t = common::text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("--strict") && t.contains("/v/") && t.contains("/ow/"),
        "{t}"
    );
    assert!(!dir.path().join("strict").exists());
}

/// Issue 26, item 8: `synth` lists the files it wrote, `utterance.lab` (the target's phone
/// timings) among them.
#[test]
fn synth_lists_its_files_and_writes_the_phone_timings() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let o = common::facespace(&[
        "synth",
        "--model",
        common::root().join("models/grid/model").to_str().unwrap(),
        "--codebook",
        common::root()
            .join("models/grid/codebook")
            .to_str()
            .unwrap(),
        "--text",
        "bin blue at f two now",
        "-o",
        out.to_str().unwrap(),
    ]);
    let t = common::text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("wrote to") && t.contains("utterance.lab") && t.contains("video.mp4"),
        "{t}"
    );
    let labels = facespace::phonemes::read_labels(
        &out.join("utterance.lab"),
        None,
        &facespace::phonemes::PhoneMap::default(),
    )
    .unwrap();
    assert!(
        labels.iter().any(|s| s.phone == Phone::parse("b").unwrap()),
        "{labels:?}"
    );
}
