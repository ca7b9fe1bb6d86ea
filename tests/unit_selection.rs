//! Unit selection and the dynamic-phoneme graph (issue 13): a sentence of the codebook comes
//! back as itself; bad input is a clear error.
use crate::common;

use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::corpus::demo::{self as generator, CorpusOptions, Split};
use facespace::model::{FaceModel, load_training_set};
use facespace::phonemes::{Phone, Segment};
use facespace::synth::unit::{UnitSelection, UnitWeights};
use facespace::synth::{SynthError, Synthesiser};

fn demo_codebook() -> Codebook {
    let model = FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let generated = generator::generate(&model, &frames, &CorpusOptions::default()).unwrap();
    Codebook::build(
        generated.part(Split::Train),
        25.0,
        model.layout(),
        Some(model.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap()
}

/// With the phones and timings of a codebook sentence as the target, every frame of that
/// sentence costs nothing (M is 0 between equal phones, consecutive frames join for free), so
/// the cheapest path is the sentence itself: one segment as long as the sentence.
#[test]
fn unit_selection_returns_a_codebook_sentence_as_itself() {
    let cb = demo_codebook();
    let unit = UnitSelection::default();
    for k in [0, 17, 40] {
        let sentence = &cb.sentences[k];
        let s = unit.synthesise(&cb, &sentence.segments, cb.fps).unwrap();
        let stats = s.selection.as_ref().unwrap();
        assert_eq!(s.frames.len(), sentence.frames.len(), "{}", sentence.name);
        assert_eq!(
            s.frames.as_slice(),
            sentence.frames.as_slice(),
            "{}",
            sentence.name
        );
        assert_eq!(stats.segments.len(), 1, "{:?}", stats.segments);
        assert_eq!(stats.sl_avg, sentence.frames.len() as f64);
        assert_eq!(
            (stats.tc_avg, stats.vc_avg, stats.path_cost),
            (0.0, 0.0, 0.0)
        );
    }
}

#[test]
fn unit_selection_bad_input_is_a_clear_error() {
    let cb = demo_codebook();
    let unit = UnitSelection::default();
    assert_eq!(
        unit.synthesise(&cb, &[], 25.0).unwrap_err(),
        SynthError::Empty
    );
    let negative = UnitSelection {
        weights: UnitWeights {
            w_cc: -1.0,
            ..UnitWeights::default()
        },
        ..UnitSelection::default()
    };
    let err = negative
        .synthesise(&cb, &cb.sentences[0].segments, 25.0)
        .unwrap_err();
    assert!(err.to_string().contains("w_cc = -1"), "{err}");
    // A weights file must give all four weights.
    let missing = serde_json::from_str::<UnitWeights>(r#"{"w_tc": 1, "w_cc": 1, "w_ccf": 1}"#)
        .unwrap_err()
        .to_string();
    assert!(missing.contains("w_ccg"), "{missing}");
    // A phone whose viseme class the codebook lacks (/oy/ is alone in its class): every frame
    // is a candidate, and the report says so.
    let absent = Phone::parse("oy").unwrap();
    let without: Vec<_> = cb
        .sentences
        .iter()
        .filter(|s| s.segments.iter().all(|g| g.phone != absent))
        .cloned()
        .collect();
    let cb = Codebook::build(
        without,
        25.0,
        cb.layout,
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    assert!(cb.present().iter().all(|q| q.viseme() != absent.viseme()));
    let target = [
        Segment {
            start: 0.0,
            end: 0.2,
            phone: Phone::SIL,
        },
        Segment {
            start: 0.2,
            end: 0.4,
            phone: absent,
        },
    ];
    let s = unit.synthesise(&cb, &target, 25.0).unwrap();
    assert!(
        s.warnings.iter().any(|w| w.contains("no codebook frame")),
        "{:?}",
        s.warnings
    );
}

/// The graph likewise: a codebook sentence's own units chain with probability 1, and scaled
/// onto their own phone centres they give back the sentence's frames.
#[test]
fn graph_returns_a_codebook_sentence_as_itself() {
    let cb = demo_codebook();
    let graph = facespace::synth::graph::Graph::default();
    for k in [0, 17, 40] {
        let sentence = &cb.sentences[k];
        let s = graph.synthesise(&cb, &sentence.segments, cb.fps).unwrap();
        let stats = s.selection.as_ref().unwrap();
        assert_eq!(
            s.frames.as_slice(),
            sentence.frames.as_slice(),
            "{}",
            sentence.name
        );
        assert_eq!(stats.segments.len(), 1, "{:?}", stats.segments);
        assert_eq!(stats.path_cost, 0.0);
    }
}

/// Unit selection's path is the cheapest of all paths: on small random codebooks (every
/// candidate kept, no beam), every choice of frames of the target phones' viseme classes is
/// enumerated and costed with the same formula.
#[test]
fn unit_selection_finds_the_cheapest_of_every_path() {
    use facespace::corpus::Sentence;
    use facespace::facespace::{Frames, Layout};
    use facespace::synth::unit::{CodebookFrame, UnitConstants};
    let layout = Layout::new(1, 2);
    let ph = |s: &str| Phone::parse(s).unwrap();
    for seed in 0..12u64 {
        let mut rng = common::Rng::new(seed);
        let inventory = ["aa", "m", "iy", "s"];
        let sentences: Vec<Sentence> = (0..2)
            .map(|k| {
                let phones: Vec<&str> = (0..3)
                    .map(|_| inventory[(rng.uniform() * 4.0) as usize])
                    .collect();
                let segments: Vec<Segment> = phones
                    .iter()
                    .enumerate()
                    .map(|(i, p)| Segment {
                        start: 0.08 * i as f64,
                        end: 0.08 * (i + 1) as f64,
                        phone: ph(p),
                    })
                    .collect();
                let rows: Vec<f32> = (0..6)
                    .flat_map(|_| {
                        let mut r = vec![1.0, 0.0, 0.0, 0.0];
                        r.extend((0..3).map(|_| rng.range(-1.0, 1.0) as f32));
                        r
                    })
                    .collect();
                Sentence {
                    name: format!("s{k}"),
                    source: "random".into(),
                    frames: Frames::from_rows(layout, 25.0, rows).unwrap(),
                    segments,
                }
            })
            .collect();
        let cb = Codebook::build(
            sentences,
            25.0,
            layout,
            None,
            SimilarityOptions::default(),
            &mut facespace::no_progress,
        )
        .unwrap();
        let target: Vec<Segment> = (0..2)
            .map(|i| Segment {
                start: 0.08 * i as f64,
                end: 0.08 * (i + 1) as f64,
                phone: ph(inventory[(rng.uniform() * 4.0) as usize]),
            })
            .collect();
        let unit = UnitSelection {
            constants: UnitConstants {
                beam: 0,
                ..UnitConstants::default()
            },
            weights: UnitWeights {
                w_tc: rng.range(0.1, 3.0),
                w_cc: rng.range(0.1, 3.0),
                w_ccf: rng.range(0.1, 3.0),
                w_ccg: rng.range(0.1, 3.0),
            },
        };
        let (path, stats, _) = unit.select(&cb, &target, 25.0).unwrap();
        // Every frame of a matching viseme class (or every frame, when none matches).
        let frames: Vec<CodebookFrame> = (0..2u32)
            .flat_map(|s| {
                (0..6u32).map(move |f| CodebookFrame {
                    sentence: s,
                    frame: f,
                })
            })
            .collect();
        let pools: Vec<Vec<CodebookFrame>> = (0..path.len())
            .map(|i| {
                let p = facespace::codebook::phone_at(&target, i as f64 / 25.0);
                let same: Vec<_> = frames
                    .iter()
                    .copied()
                    .filter(|u| {
                        cb.frame_phones[u.sentence as usize][u.frame as usize].viseme()
                            == p.viseme()
                    })
                    .collect();
                if same.is_empty() {
                    frames.clone()
                } else {
                    same
                }
            })
            .collect();
        let mut best = f64::INFINITY;
        let mut choice = vec![0usize; pools.len()];
        'all: loop {
            let p: Vec<CodebookFrame> = choice
                .iter()
                .enumerate()
                .map(|(i, &c)| pools[i][c])
                .collect();
            best = best.min(unit.path_cost(&cb, &target, 25.0, &p));
            for i in 0..choice.len() {
                choice[i] += 1;
                if choice[i] < pools[i].len() {
                    continue 'all;
                }
                choice[i] = 0;
            }
            break;
        }
        let own = unit.path_cost(&cb, &target, 25.0, &path);
        assert!(
            (own - stats.path_cost).abs() < 1e-9,
            "seed {seed}: {own} vs {}",
            stats.path_cost
        );
        assert!(
            (own - best).abs() < 1e-9,
            "seed {seed}: found {own}, cheapest {best}"
        );
    }
}

/// Weights files: written and read back; a missing, unknown, negative or non-finite weight,
/// a truncated file and a missing file are errors naming the file.
#[test]
fn weights_files_round_trip_and_bad_ones_are_named() {
    use facespace::synth::unit::{UnitConstants, WeightsFile};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.json");
    let file = WeightsFile {
        weights: UnitWeights {
            w_tc: 0.5,
            w_cc: 2.0,
            w_ccf: 3.0,
            w_ccg: 0.25,
        },
        constants: UnitConstants {
            beam: 90,
            ..UnitConstants::default()
        },
        training: None,
    };
    file.write(&path).unwrap();
    assert_eq!(WeightsFile::read(&path).unwrap(), file);
    // Constants are optional: the defaults.
    std::fs::write(
        &path,
        r#"{"weights": {"w_tc": 1, "w_cc": 1, "w_ccf": 1, "w_ccg": 1}}"#,
    )
    .unwrap();
    assert_eq!(
        WeightsFile::read(&path).unwrap().constants,
        UnitConstants::default()
    );
    for (text, expect) in [
        (
            r#"{"weights": {"w_tc": 1, "w_cc": 1, "w_ccf": 1}}"#,
            "w_ccg",
        ),
        (
            r#"{"weights": {"w_tc": 1, "w_cc": 1, "w_ccf": 1, "w_ccg": 1, "w_x": 1}}"#,
            "w_x",
        ),
        (
            r#"{"weights": {"w_tc": 1, "w_cc": -2, "w_ccf": 1, "w_ccg": 1}}"#,
            "w_cc = -2",
        ),
        (
            r#"{"weights": {"w_tc": 1, "w_cc": 1, "w_ccf": 1, "w_ccg": 1}, "constants": {"p": 0}}"#,
            "p = 0",
        ),
        (r#"{"weights": {"w_tc": 1, "w_cc": 1, "#, "EOF"),
    ] {
        std::fs::write(&path, text).unwrap();
        let err = WeightsFile::read(&path).unwrap_err().to_string();
        assert!(
            err.contains("w.json") && err.contains(expect),
            "{text}: {err}"
        );
    }
    let err = WeightsFile::read(&dir.path().join("absent.json"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("absent.json"), "{err}");
}

/// Pareto training: deterministic for a seed, its front mutually non-dominated, the chosen
/// point on it, every front point evaluated; and a bad option is an error.
#[test]
fn pareto_training_is_deterministic_and_its_front_non_dominated() {
    use facespace::synth::pareto::{ParetoOptions, train};
    use facespace::synth::unit::UnitConstants;
    let model = FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let generated = generator::generate(&model, &frames, &CorpusOptions::default()).unwrap();
    let cb = demo_codebook();
    let validation = generated.part(Split::Validation);
    let options = ParetoOptions {
        population: 8,
        max_generations: 3,
        ..ParetoOptions::default()
    };
    let run = |options: &ParetoOptions| {
        train(
            &model,
            &cb,
            &validation[..2],
            UnitConstants::default(),
            options,
            facespace::no_progress,
        )
    };
    let a = run(&options).unwrap();
    let b = run(&options).unwrap();
    assert_eq!(a, b, "same seed, same training");
    let other = run(&ParetoOptions { seed: 7, ..options }).unwrap();
    assert_ne!(a.evaluated, other.evaluated, "another seed, another search");
    for p in &a.front {
        assert!(a.front.iter().all(|q| !q.dominates(p)));
        assert!(a.evaluated.contains(p));
    }
    assert!(a.front.contains(&a.chosen));
    assert!(a.generations <= 3 && a.evaluated.len() == 8 * (a.generations + 1));
    assert!((-1.0..=1.0).contains(&a.correlation.0));
    let err = run(&ParetoOptions {
        population: 1,
        ..options
    })
    .unwrap_err()
    .to_string();
    assert!(err.contains("population"), "{err}");
    assert!(
        train(
            &model,
            &cb,
            &[],
            UnitConstants::default(),
            &options,
            facespace::no_progress
        )
        .is_err()
    );
}
