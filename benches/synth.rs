//! Blend synthesis of a 10 s utterance from the 54-sentence demo codebook (excluding
//! rendering): selection + time-warped blending, and the smoothing spline.
//! Run: cargo bench --bench synth

use criterion::{Criterion, criterion_group, criterion_main};
use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::corpus::demo::{self, CorpusOptions};
use facespace::model::{FaceModel, load_training_set};
use facespace::phonemes::{self, Segment};
use facespace::synth::blend::Blend;
use facespace::synth::{DEFAULT_SMOOTHING, Request, Smoothing, synthesise};

fn bench(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/demo/model")).unwrap();
    let frames = load_training_set(&root.join("models/demo/training"), None).unwrap();
    let train = demo::generate(&model, &frames, &CorpusOptions::default())
        .unwrap()
        .part(demo::Split::Train);
    let build = |train| {
        Codebook::build(
            train,
            25.0,
            model.layout(),
            None,
            SimilarityOptions::default(),
            &mut facespace::no_progress,
        )
        .unwrap()
    };
    c.bench_function("codebook build, 54 demo sentences", |b| {
        b.iter(|| build(train.clone()))
    });
    let cb = build(train);
    // About 10 s of speech: four sentences not in the corpus, back to back.
    let text = "The quiet violin played softly. A brave pilot found the hidden map. \
                Maybe the farmer will move both boats. Five boys ate the fresh bread by the window. Please come back soon.";
    let target: Vec<Segment> = phonemes::text_to_segments(text, &cb.mean_durations()).unwrap();
    let seconds = target.last().unwrap().end;
    for (name, smoothing) in [
        ("blend", Smoothing::Off),
        ("blend + smooth", Smoothing::On(DEFAULT_SMOOTHING)),
    ] {
        c.bench_function(&format!("{name} {seconds:.1} s (C=1, N=3)"), |b| {
            b.iter(|| {
                let request = Request::new(target.clone(), 25.0, smoothing);
                synthesise(&Blend::default(), &cb, request).unwrap()
            })
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
