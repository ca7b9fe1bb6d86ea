//! Unit selection and the dynamic-phoneme graph (issue 13): a sentence of the codebook comes
//! back as itself; bad input is a clear error.
mod common;

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
