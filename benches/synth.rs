//! Blend synthesis of a 10 s utterance from the 54-sentence demo codebook (excluding
//! rendering): selection + time-warped blending, and the smoothing spline.
//! Run: cargo bench --bench synth

use criterion::{Criterion, criterion_group, criterion_main};
use facespace::codebook::{Codebook, Layout, SimilarityOptions};
use facespace::corpus::{self, CorpusOptions};
use facespace::model::{FaceModel, load_training_set};
use facespace::phonemes::{self, Segment};
use facespace::synth::blend::{self, BlendOptions};
use facespace::synth::smooth::SmoothingSpline;

fn bench(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/demo/model")).unwrap();
    let frames = load_training_set(&root.join("models/demo/training"), None).unwrap();
    let (train, _) = corpus::generate(&model, &frames, &CorpusOptions::default())
        .unwrap()
        .split();
    c.bench_function("codebook build, 54 demo sentences", |b| {
        b.iter(|| {
            Codebook::build(
                train.clone(),
                25.0,
                Layout::of(&model),
                None,
                SimilarityOptions::default(),
                &mut facespace::no_progress,
            )
            .unwrap()
        })
    });
    let cb = Codebook::build(
        train,
        25.0,
        Layout::of(&model),
        None,
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    // About 10 s of speech: four sentences not in the corpus, back to back.
    let text = "The quiet violin played softly. A brave pilot found the hidden map. \
                Maybe the farmer will move both boats. Five boys ate the fresh bread by the window. Please come back soon.";
    let target: Vec<Segment> = phonemes::text_to_segments(text, &cb.mean_durations()).unwrap();
    let seconds = target.last().unwrap().end;
    c.bench_function(&format!("blend {seconds:.1} s (C=1, N=3)"), |b| {
        b.iter(|| blend::blend(&cb, &target, &BlendOptions::default()).unwrap())
    });
    let s = blend::blend(&cb, &target, &BlendOptions::default()).unwrap();
    c.bench_function(&format!("blend + smooth {seconds:.1} s"), |b| {
        b.iter(|| {
            let s = blend::blend(&cb, &target, &BlendOptions::default()).unwrap();
            let mut f = s.frames.clone();
            SmoothingSpline::new(&s.times(), None, 1e-5)
                .unwrap()
                .smooth_rows(&mut f, s.dims)
                .unwrap();
            f
        })
    });
    drop(s);
}

criterion_group!(benches, bench);
criterion_main!(benches);
