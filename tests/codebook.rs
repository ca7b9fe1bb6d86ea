//! Codebook: S and M against hand computations, save/load, corpus loading errors.
use crate::common;

use std::path::Path;

use common::Rng;
use facespace::codebook::{Codebook, CodebookError, SimilarityOptions};
use facespace::corpus::{self, CorpusError, Sentence};
use facespace::facespace::{FacespaceError, Frames, Layout};
use facespace::manifest::ManifestError;
use facespace::npy::{self, NpyError};
use facespace::phonemes::{self, Phone, PhoneMap, Segment};
use ndarray::Array2;

fn ph(name: &str) -> Phone {
    Phone::parse(name).unwrap()
}

const LAYOUT: Layout = Layout {
    shape: 1,
    appearance: 2,
};

fn frames(rows: Vec<f32>) -> Frames {
    Frames::from_rows(LAYOUT, 25.0, rows).unwrap()
}

/// A sentence of one phone whose frames hold `value` in every parameter dimension
/// (pose fixed), 10 frames at 25 fps.
fn constant_sentence(phone: &str, value: [f32; 3]) -> Sentence {
    let rows = (0..10)
        .flat_map(|_| [1.0, 0.0, 0.0, 0.0, value[0], value[1], value[2]])
        .collect();
    Sentence {
        name: phone.into(),
        source: "test".into(),
        frames: frames(rows),
        segments: vec![Segment {
            start: 0.0,
            end: 0.4,
            phone: ph(phone),
        }],
    }
}

/// With uniform weights and v = 1: `D_ab = (1/d) Σ_k 5 (c_a,k − c_b,k)²`, `S = exp(−γ D)`.
#[test]
fn similarity_matches_the_formula_on_constant_trajectories() {
    let values = [
        ("m", [0.0, 1.0, 2.0]),
        ("p", [0.1, 1.0, 2.0]),
        ("aa", [3.0, -1.0, 0.0]),
    ];
    let sentences = values
        .iter()
        .map(|(p, v)| constant_sentence(p, *v))
        .collect();
    let options = SimilarityOptions {
        gamma: Some(0.7),
        variance_weights: false,
        context_weights: false,
        ..Default::default()
    };
    let cb = Codebook::build(
        sentences,
        25.0,
        LAYOUT,
        None,
        options,
        &mut facespace::no_progress,
    )
    .unwrap();
    for (a, va) in &values {
        for (b, vb) in &values {
            let d: f64 = va
                .iter()
                .zip(vb)
                .map(|(x, y)| 5.0 * ((x - y) as f64).powi(2))
                .sum::<f64>()
                / 3.0;
            let s = cb.similarity(ph(a), ph(b));
            assert!(
                (s - (-0.7 * d).exp()).abs() < 1e-6,
                "S({a},{b}) = {s}, expected {}",
                (-0.7 * d).exp()
            );
        }
    }
    assert_eq!(cb.nearest(ph("m"), 1)[0].0, ph("p"));
    // Absent phones: similar only to themselves.
    assert_eq!(cb.similarity(ph("f"), ph("f")), 1.0);
    assert_eq!(cb.similarity(ph("f"), ph("m")), 0.0);
    assert_eq!(cb.present(), vec![ph("aa"), ph("m"), ph("p")]);
}

/// M (eq. 5 of [unitsel]) by hand: appearance means (1, 2) and (3, −1), K = min(12, 2) = 2,
/// γ_k = exp(0.1 |k − K|).
#[test]
fn distance_matches_equation_5() {
    let sentences = vec![
        constant_sentence("m", [9.0, 1.0, 2.0]),
        constant_sentence("aa", [0.0, 3.0, -1.0]),
    ];
    let cb = Codebook::build(
        sentences,
        25.0,
        LAYOUT,
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    let (g1, g2) = ((0.1f64 * 1.0).exp(), 1.0);
    let expected = ((g1 * 4.0 + g2 * 9.0) / (g1 + g2)).sqrt();
    assert!(
        (cb.distance(ph("m"), ph("aa")) - expected).abs() < 1e-6,
        "{} vs {expected}",
        cb.distance(ph("m"), ph("aa"))
    );
    assert_eq!(cb.distance(ph("m"), ph("m")), 0.0);
}

/// With more appearance components than K = 12, M uses the first K only, the leading ones
/// weighted most: phones differing only beyond K are at distance 0, and a difference in
/// component 1 weighs e^{1.1} times one in component 12.
#[test]
fn distance_uses_the_first_k_components_leading_first() {
    let layout = Layout::new(1, 15);
    let sentence = |phone: &str, k: Option<usize>| {
        let mut row = vec![1.0f32, 0.0, 0.0, 0.0, 0.0];
        row.extend((0..15).map(|j| if Some(j) == k { 1.0 } else { 0.0 }));
        Sentence {
            name: phone.into(),
            source: "test".into(),
            frames: Frames::from_rows(layout, 25.0, row.repeat(10)).unwrap(),
            segments: vec![Segment {
                start: 0.0,
                end: 0.4,
                phone: ph(phone),
            }],
        }
    };
    let cb = Codebook::build(
        vec![
            sentence("aa", None),
            sentence("ae", Some(0)),
            sentence("ah", Some(11)),
            sentence("ao", Some(12)),
            sentence("aw", Some(14)),
        ],
        25.0,
        layout,
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    let m = |a: &str, b: &str| cb.distance(ph(a), ph(b));
    let gsum: f64 = (1..=12).map(|k| (0.1 * (12.0 - k as f64)).exp()).sum();
    assert!((m("aa", "ae") - ((0.1f64 * 11.0).exp() / gsum).sqrt()).abs() < 1e-9);
    assert!((m("aa", "ah") - (1.0 / gsum).sqrt()).abs() < 1e-9);
    assert_eq!(m("aa", "ao"), 0.0, "component 13 is beyond K");
    assert_eq!(m("aa", "aw"), 0.0, "component 15 is beyond K");
}

/// S weighs shape and appearance as equals, each in its own units (DESIGN §7): two phones
/// that differ only in shape are as dissimilar as two that differ only in appearance by the
/// same fraction of their model's spread, though appearance values are 10⁵ times larger —
/// and the nearest phone changes when the shape is removed.
#[test]
fn similarity_counts_shape_in_its_own_units() {
    let build = |shape: [f32; 4]| {
        let app = [0.0, 0.0, 1000.0, 1000.0];
        let sentences = ["aa", "ae", "ah", "ao"]
            .iter()
            .enumerate()
            .map(|(i, p)| constant_sentence(p, [shape[i], app[i], 0.0]))
            .collect();
        Codebook::build(
            sentences,
            25.0,
            LAYOUT,
            None,
            SimilarityOptions::default(),
            &mut facespace::no_progress,
        )
        .unwrap()
    };
    let cb = build([0.0, 0.01, 0.0, 0.01]);
    let s = |a: &str, b: &str| cb.similarity(ph(a), ph(b));
    assert!(
        s("aa", "ae") < 0.9,
        "shape alone separates aa and ae: {}",
        s("aa", "ae")
    );
    assert!(
        (s("aa", "ae") - s("aa", "ah")).abs() < 1e-9,
        "a shape-only and an appearance-only difference of equal spread weigh alike: {} vs {}",
        s("aa", "ae"),
        s("aa", "ah")
    );
    let with_shape = build([0.0, 0.02, 0.0, 0.01]);
    let without = build([0.0; 4]);
    assert_eq!(with_shape.nearest(ph("aa"), 1)[0].0, ph("ah"));
    assert_eq!(without.nearest(ph("aa"), 1)[0].0, ph("ae"));
}

/// A coarticulated corpus in which /p b m/ share a lip-closure target and /f v/, /t d/
/// share theirs: S must rank them as each other's nearest.
fn coarticulated_corpus(n_sentences: usize, seed: u64) -> Vec<Sentence> {
    let mut rng = Rng::new(seed);
    let inventory = [
        "p", "b", "m", "f", "v", "t", "d", "aa", "iy", "uw", "s", "k", "l", "ow",
    ];
    let targets: Vec<[f64; 3]> = inventory
        .iter()
        .map(|p| match *p {
            "p" | "b" | "m" => [-2.0, 0.0, 1.0],
            "f" | "v" => [-1.0, 2.0, 0.0],
            "t" | "d" => [0.5, -1.5, -1.0],
            _ => [
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
                rng.range(-3.0, 3.0),
            ],
        })
        .collect();
    (0..n_sentences)
        .map(|i| {
            let mut segments = vec![];
            let mut t = 0.0;
            let mut seq = vec![0usize; 8];
            seq.iter_mut()
                .for_each(|s| *s = (rng.uniform() * inventory.len() as f64) as usize);
            for &k in &seq {
                let d = rng.range(0.06, 0.14);
                segments.push(Segment {
                    start: t,
                    end: t + d,
                    phone: ph(inventory[k]),
                });
                t += d;
            }
            let n = (t * 25.0).ceil() as usize;
            let rows = (0..n)
                .flat_map(|f| {
                    let time = f as f64 / 25.0;
                    // Dominance-weighted blend of the targets around this time.
                    let (mut acc, mut wsum) = ([0.0; 3], 0.0);
                    for g in &segments {
                        let c = 0.5 * (g.start + g.end);
                        let w = (-((time - c) / 0.05).powi(2)).exp() + 1e-9;
                        let target =
                            targets[inventory.iter().position(|p| ph(p) == g.phone).unwrap()];
                        (0..3).for_each(|k| acc[k] += w * target[k]);
                        wsum += w;
                    }
                    let mut row = vec![1.0f32, 0.0, 0.0, 0.0];
                    row.extend(acc.iter().map(|a| (a / wsum + 0.05 * rng.normal()) as f32));
                    row
                })
                .collect();
            Sentence {
                name: format!("s{i}"),
                source: "generated".into(),
                frames: frames(rows),
                segments,
            }
        })
        .collect()
}

#[test]
fn shared_targets_rank_nearest() {
    let cb = Codebook::build(
        coarticulated_corpus(60, 3),
        25.0,
        LAYOUT,
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    for (p, partners) in [
        ("p", vec!["b", "m"]),
        ("b", vec!["p", "m"]),
        ("m", vec!["p", "b"]),
    ] {
        let top: Vec<&str> = cb.nearest(ph(p), 2).iter().map(|(q, _)| q.name()).collect();
        assert!(
            partners.iter().all(|q| top.contains(q)),
            "{p}: nearest {top:?}"
        );
    }
    for (a, b) in [("f", "v"), ("t", "d")] {
        assert_eq!(cb.nearest(ph(a), 1)[0].0, ph(b), "{a}");
    }
    for a in cb.present() {
        for b in cb.present() {
            let (s, t) = (cb.similarity(a, b), cb.similarity(b, a));
            assert!(
                (s - t).abs() < 1e-12 && s > 0.0 && s <= 1.0,
                "S({a},{b}) = {s}"
            );
        }
    }
    // Mean durations come from the corpus.
    let d = cb.mean_durations()[ph("p").index()];
    assert!((0.06..0.14).contains(&d), "{d}");
}

#[test]
fn save_and_load_round_trip_and_validation() {
    let cb = Codebook::build(
        coarticulated_corpus(8, 4),
        25.0,
        LAYOUT,
        Some("abc".into()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cb");
    cb.save(&path).unwrap();
    let back = Codebook::load(&path).unwrap();
    assert!(
        back == cb,
        "loaded codebook differs (sentences equal: {})",
        back.sentences == cb.sentences
    );

    // A tampered similarity matrix is caught.
    let mut s = npy::read::<f64>(&path.join("similarity.npy")).unwrap();
    s[[1, 1]] += 0.5;
    npy::write(&path.join("similarity.npy"), s.view()).unwrap();
    assert!(
        Codebook::load(&path)
            .unwrap_err()
            .to_string()
            .contains("differ")
    );
    cb.save(&path).unwrap();
    // Truncated sentence array.
    let f = path.join("sentence_0003.npy");
    let bytes = std::fs::read(&f).unwrap();
    std::fs::write(&f, &bytes[..bytes.len() - 8]).unwrap();
    let err = Codebook::load(&path).unwrap_err();
    assert!(
        err.to_string().contains("sentence_0003.npy") && err.to_string().contains("truncated"),
        "{err}"
    );
    cb.save(&path).unwrap();
    let m = path.join("codebook.json");
    std::fs::write(
        &m,
        std::fs::read_to_string(&m)
            .unwrap()
            .replace("\"version\": 1", "\"version\": 7"),
    )
    .unwrap();
    assert!(matches!(
        Codebook::load(&path),
        Err(CodebookError::Manifest(ManifestError::Version { found, .. })) if found == "7"
    ));
    // Sentence files are plain names inside the folder: no absolute paths, no `..`, no
    // devices.
    cb.save(&path).unwrap();
    let text = std::fs::read_to_string(&m).unwrap();
    for name in ["/dev/zero", "../cb/sentence_0001.npy", "/etc/passwd"] {
        std::fs::write(&m, text.replace("sentence_0001.npy", name)).unwrap();
        let err = Codebook::load(&path).unwrap_err();
        assert!(
            matches!(err, CodebookError::Manifest(ManifestError::Escapes { .. })),
            "{name}: {err}"
        );
    }
    // A layout whose pose is not four values, or absurdly large, is refused as such.
    for (from, to) in [
        ("\"pose\": 4", "\"pose\": 41"),
        ("\"shape\": 1", "\"shape\": 18446744073709551615"),
    ] {
        std::fs::write(&m, text.replace(from, to)).unwrap();
        let err = Codebook::load(&path).unwrap_err();
        assert!(
            matches!(err, CodebookError::Manifest(ManifestError::Invalid { .. })),
            "{to}: {err}"
        );
    }
}

#[test]
fn bad_sentences_are_errors() {
    let mut s = constant_sentence("m", [0.0; 3]);
    s.segments[0].end = 2.0;
    let err = Codebook::build(
        vec![s],
        25.0,
        LAYOUT,
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap_err();
    assert!(err.to_string().contains("labels end at 2.000 s"), "{err}");
    let mut s = constant_sentence("m", [0.0; 3]);
    s.frames = s.frames.slice(0..1);
    assert!(matches!(
        Codebook::build(
            vec![s],
            25.0,
            LAYOUT,
            None,
            SimilarityOptions::default(),
            &mut facespace::no_progress
        ),
        Err(CodebookError::BadSentence { .. })
    ));
    let bad = SimilarityOptions {
        samples: 1,
        ..Default::default()
    };
    assert!(matches!(
        Codebook::build(vec![], 25.0, LAYOUT, None, bad, &mut facespace::no_progress),
        Err(CodebookError::Option(_))
    ));
    // Frames of another layout or rate than the codebook's.
    let s = constant_sentence("m", [0.0; 3]);
    let err = Codebook::build(
        vec![s.clone()],
        25.0,
        Layout::new(2, 1),
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap_err();
    assert!(matches!(err, CodebookError::Frames { .. }), "{err}");
    let err = Codebook::build(
        vec![s],
        50.0,
        LAYOUT,
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap_err();
    assert!(err.to_string().contains("25 fps"), "{err}");
}

fn write_sentence(dir: &Path, name: &str, frames: usize, label_end: f64) {
    npy::write(
        &dir.join(format!("{name}.npy")),
        Array2::<f32>::from_elem((frames, 7), 0.5).view(),
    )
    .unwrap();
    let segs = [
        Segment {
            start: 0.0,
            end: label_end / 2.0,
            phone: Phone::SIL,
        },
        Segment {
            start: label_end / 2.0,
            end: label_end,
            phone: ph("m"),
        },
    ];
    phonemes::write_labels(&dir.join(format!("{name}.lab")), &segs).unwrap();
}

#[test]
fn corpus_folder_loading() {
    let dir = tempfile::tempdir().unwrap();
    write_sentence(dir.path(), "a", 25, 1.0);
    write_sentence(dir.path(), "b", 50, 2.04);
    let load =
        |dir: &Path, layout: Layout| corpus::load(dir, 25.0, layout, None, &PhoneMap::default());
    let s = load(dir.path(), LAYOUT).unwrap();
    assert_eq!(s.len(), 2);
    assert_eq!(s[1].frames.len(), 50);

    write_sentence(dir.path(), "c", 25, 1.5);
    let err = load(dir.path(), LAYOUT).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, CorpusError::DurationMismatch { .. })
            && msg.contains("c.npy")
            && msg.contains("c.lab"),
        "{msg}"
    );
    std::fs::remove_file(dir.path().join("c.lab")).unwrap();
    assert!(matches!(
        load(dir.path(), LAYOUT),
        Err(CorpusError::MissingLabels { .. })
    ));
    std::fs::remove_file(dir.path().join("c.npy")).unwrap();
    let err = load(dir.path(), Layout::new(3, 2)).unwrap_err();
    assert!(
        matches!(
            &err,
            CorpusError::Frames {
                source: FacespaceError::Width { found: 7, .. },
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string().contains("a.npy: 7 values per frame"),
        "{err}"
    );
    // A one-dimensional array is no trajectory.
    npy::write(
        &dir.path().join("a.npy"),
        ndarray::Array1::<f32>::zeros(7).view(),
    )
    .unwrap();
    let err = load(dir.path(), LAYOUT).unwrap_err();
    assert!(
        matches!(err, CorpusError::Npy(NpyError::Shape { .. })),
        "{err}"
    );
    write_sentence(dir.path(), "a", 25, 1.0);
    let empty = tempfile::tempdir().unwrap();
    assert!(matches!(
        load(empty.path(), LAYOUT),
        Err(CorpusError::Empty { .. })
    ));
}

/// The median pose is, per pose value, the middle of every frame's values sorted (the upper
/// middle of an even count).
#[test]
fn the_median_pose_is_the_middle_of_every_frames_pose() {
    // GRID s1's recorded sentences: every pose value varies.
    let cb = Codebook::load(&common::root().join("models/grid/codebook")).unwrap();
    let median = cb.median_pose().to_array();
    for (k, &m) in median.iter().enumerate() {
        let mut all: Vec<f32> = cb
            .sentences
            .iter()
            .flat_map(|s| s.frames.values().column(k).to_vec())
            .collect();
        all.sort_by(f32::total_cmp);
        assert!(all[0] < all[all.len() - 1], "pose value {k} never varies");
        assert_eq!(m, f64::from(all[all.len() / 2]), "pose value {k}");
    }
}

/// Issue 67: what a codebook lacks — its absent phones, and the mouth shapes (viseme classes)
/// none of its phones shows. A codebook of /m/, /p/ and /aa/ lacks /b/ but shows the
/// lips-together shape (/b/ borrows from /m p/); it lacks every phone of the rounded /uw/'s
/// class, so that shape is absent whole.
#[test]
fn a_codebook_names_the_phones_and_mouth_shapes_it_lacks() {
    let sentences = [("m", [0.0, 1.0, 2.0]), ("p", [0.1, 1.0, 2.0]), ("aa", [3.0, -1.0, 0.0])]
        .iter()
        .map(|(p, v)| constant_sentence(p, *v))
        .collect();
    let cb = Codebook::build(sentences, 25.0, LAYOUT, None, SimilarityOptions::default(), &mut facespace::no_progress)
        .unwrap();
    let (phones, shapes) = cb.absent();
    assert!(phones.contains(&ph("b")) && !phones.contains(&ph("m")) && !phones.contains(&ph("aa")));
    assert_eq!(phones.len(), Phone::all().count() - 3 - usize::from(!cb.occurrences[Phone::SIL.index()].is_empty()));
    assert!(!shapes.iter().any(|c| c.contains(&ph("b"))), "/b/'s shape is shown by /m p/");
    assert!(shapes.iter().any(|c| c.contains(&ph("uw"))));
    for class in &shapes {
        assert!(class.iter().all(|p| phones.contains(p) && p.viseme() == class[0].viseme()));
    }
}
