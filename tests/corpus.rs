//! The generated demo corpus: determinism, split, labels, and S on it.
mod common;

use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::corpus::demo::{self as corpus, CorpusOptions, HELD_OUT, SENTENCES};
use facespace::model::{FaceModel, load_training_set};
use facespace::phonemes::Phone;

fn demo() -> (FaceModel, Vec<corpus::GeneratedSentence>) {
    let model = FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let sentences = corpus::generate(&model, &frames, &CorpusOptions::default())
        .unwrap()
        .sentences;
    (model, sentences)
}

#[test]
fn generation_is_deterministic_and_split() {
    let (model, a) = demo();
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let b = corpus::generate(&model, &frames, &CorpusOptions::default())
        .unwrap()
        .sentences;
    assert!(a == b, "same seed, same corpus, bit for bit");
    let other = corpus::generate(
        &model,
        &frames,
        &CorpusOptions {
            seed: 7,
            ..Default::default()
        },
    )
    .unwrap()
    .sentences;
    assert!(
        other[0].sentence.frames != a[0].sentence.frames,
        "another seed, another corpus"
    );
    assert_eq!(a.len(), SENTENCES.len());
    assert_eq!(a.iter().filter(|s| s.held_out).count(), HELD_OUT);
    assert!(a[..SENTENCES.len() - HELD_OUT].iter().all(|s| !s.held_out));
    for g in &a {
        let s = &g.sentence;
        assert_eq!(s.frames.layout(), model.layout());
        let n = s.frames.len();
        assert!(
            (s.segments.last().unwrap().end - n as f64 / 25.0).abs() < 1e-9,
            "{}: labels end with the frames",
            s.name
        );
        assert_eq!(s.segments[0].phone, Phone::SIL);
        for w in s.segments.windows(2) {
            assert!((w[0].end - w[1].start).abs() < 1e-12 && w[0].duration() > 0.0);
        }
        // The head is still: every frame has the same pose.
        assert!(s.frames.iter().all(|p| p.pose == s.frames.params(0).pose));
    }
}

/// The source paper's sanity facts on S, checked on the demo corpus. Ranks seen with the
/// default seed (2009), most similar first:
///   p: m 0.995, b 0.990 · b: m 0.996, p 0.990 · m: b 0.996, p 0.995
///   f: v 0.957 (first)  · t: n 0.977, d 0.948 (d second: t, d and n share one viseme
///   target in the generator, and n shares t's durations and word-final contexts)
#[test]
fn similarity_on_the_demo_corpus_ranks_viseme_partners() {
    let model = FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let (sentences, _) = corpus::generate(&model, &frames, &CorpusOptions::default())
        .unwrap()
        .split();
    let cb = Codebook::build(
        sentences,
        25.0,
        model.layout(),
        Some(model.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    let ph = |s: &str| Phone::parse(s).unwrap();
    let top = |p: &str, k: usize| -> Vec<&'static str> {
        cb.nearest(ph(p), k).iter().map(|(q, _)| q.name()).collect()
    };
    for p in ["p", "b", "m"] {
        let t = top(p, 2);
        eprintln!("{p}: {:?}", cb.nearest(ph(p), 3));
        assert!(
            ["p", "b", "m"]
                .iter()
                .filter(|q| **q != p)
                .all(|q| t.contains(q)),
            "{p}: {t:?}"
        );
    }
    eprintln!("f: {:?}", cb.nearest(ph("f"), 3));
    assert_eq!(top("f", 1), ["v"]);
    eprintln!("t: {:?}", cb.nearest(ph("t"), 3));
    assert!(top("t", 2).contains(&"d"), "t: {:?}", top("t", 3));
}
