//! Unit selection and the dynamic-phoneme graph on a 10 s utterance (excluding rendering),
//! over the demo codebook (48 sentences) and over a codebook of ≥ 30 000 frames (the demo
//! corpus generated with successive seeds, train splits merged); and Pareto training of the
//! weights on the demo codebook's 6 validation sentences. Before timing, the effect of the
//! beam on the path cost is printed (a measurement, not a timing).
//! Run: cargo bench --bench unit

use criterion::{Criterion, criterion_group, criterion_main};
use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::corpus::Sentence;
use facespace::corpus::demo::{self, CorpusOptions, Split};
use facespace::model::{FaceModel, load_training_set};
use facespace::phonemes::{self, Segment};
use facespace::synth::graph::Graph;
use facespace::synth::pareto::{self, ParetoOptions};
use facespace::synth::unit::{UnitConstants, UnitSelection, UnitWeights};
use facespace::synth::{Request, Smoothing, synthesise};

/// Train sentences of the demo corpus generated with seeds 2009, 2010, … until `frames`.
fn sentences(model: &FaceModel, root: &std::path::Path, frames: usize) -> Vec<Sentence> {
    let training = load_training_set(&root.join("models/demo/training"), None).unwrap();
    let mut out: Vec<Sentence> = Vec::new();
    let mut seed = 2009;
    while out.iter().map(|s| s.frames.len()).sum::<usize>() < frames {
        let options = CorpusOptions {
            seed,
            ..CorpusOptions::default()
        };
        let corpus = demo::generate(model, &training, &options).unwrap();
        out.extend(corpus.part(Split::Train).into_iter().map(|mut s| {
            s.name = format!("{}-{seed}", s.name);
            s
        }));
        seed += 1;
    }
    out
}

fn codebook(model: &FaceModel, sentences: Vec<Sentence>) -> Codebook {
    Codebook::build(
        sentences,
        25.0,
        model.layout(),
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap()
}

fn bench(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/demo/model")).unwrap();
    let small = codebook(&model, sentences(&model, root, 1));
    let large = codebook(&model, sentences(&model, root, 30_000));
    let frames = |cb: &Codebook| cb.sentences.iter().map(|s| s.frames.len()).sum::<usize>();
    // About 10 s of speech: sentences not in the corpus, back to back.
    let text = "The quiet violin played softly. A brave pilot found the hidden map. \
                Maybe the farmer will move both boats. Five boys ate the fresh bread by the window. Please come back soon.";
    let target: Vec<Segment> = phonemes::text_to_segments(text, &small.mean_durations()).unwrap();
    let seconds = target.last().unwrap().end;
    let training = load_training_set(&root.join("models/demo/training"), None).unwrap();
    let validation = demo::generate(&model, &training, &CorpusOptions::default())
        .unwrap()
        .part(Split::Validation);
    let train = || {
        pareto::train(
            &model,
            &small,
            &validation,
            UnitConstants::default(),
            &ParetoOptions::default(),
            facespace::no_progress,
        )
        .unwrap()
    };
    let trained = train().chosen.weights;
    // The beam's effect on the path cost (0 = every candidate kept), under the default and
    // the trained weights.
    for (weights_name, weights) in [("default", UnitWeights::default()), ("trained", trained)] {
        for (name, cb, beams) in [
            ("demo", &small, &[0usize, 480, 240, 120, 60, 30][..]),
            ("large", &large, &[960, 480, 240, 120, 60, 30][..]),
        ] {
            for &beam in beams {
                let unit = UnitSelection {
                    weights,
                    constants: UnitConstants {
                        beam,
                        ..UnitConstants::default()
                    },
                };
                let clock = std::time::Instant::now();
                let (_, stats, _) = unit.select(cb, &target, 25.0).unwrap();
                eprintln!(
                    "{weights_name} weights, beam {beam:>4}, {name} codebook ({} frames): path cost {:.3}, TC_avg {:.3}, SL_avg {:.2}, VC_avg {:.4} ({:.2} s)",
                    frames(cb),
                    stats.path_cost,
                    stats.tc_avg,
                    stats.sl_avg,
                    stats.vc_avg,
                    clock.elapsed().as_secs_f64()
                );
            }
        }
    }
    let mut group = c.benchmark_group("selection");
    group.sample_size(10);
    for (name, cb) in [("demo", &small), ("large", &large)] {
        group.bench_function(
            format!(
                "unit selection {seconds:.1} s, {name} codebook ({} frames), beam 60",
                frames(cb)
            ),
            |b| {
                b.iter(|| {
                    let request = Request::new(target.clone(), 25.0, Smoothing::Off);
                    synthesise(&UnitSelection::default(), cb, request).unwrap()
                })
            },
        );
    }
    group.bench_function(
        format!(
            "dynamic-phoneme graph {seconds:.1} s, demo codebook ({} frames)",
            frames(&small)
        ),
        |b| {
            b.iter(|| {
                let request = Request::new(target.clone(), 25.0, Smoothing::Off);
                synthesise(&Graph::default(), &small, request).unwrap()
            })
        },
    );
    let training = load_training_set(&root.join("models/demo/training"), None).unwrap();
    let validation = demo::generate(&model, &training, &CorpusOptions::default())
        .unwrap()
        .part(Split::Validation);
    group.bench_function(
        "Pareto training, demo codebook, 6 validation sentences",
        |b| {
            b.iter(|| {
                pareto::train(
                    &model,
                    &small,
                    &validation,
                    UnitConstants::default(),
                    &ParetoOptions::default(),
                    facespace::no_progress,
                )
                .unwrap()
            })
        },
    );
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
