//! AAM search on a 360×288 frame with the demo model (20 000-pixel reference frame,
//! 6 shape + 4 similarity parameters): one Gauss–Newton iteration, and a tracking-like fit
//! started 2 px from the answer. Run: cargo bench --bench fit

use criterion::{Criterion, criterion_group, criterion_main};
use facespace::fit::{FitOptions, Fitter};
use facespace::model::{FaceModel, load_training_set};
use facespace::shape::Landmarks;

fn bench(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/demo/model")).unwrap();
    let frames = load_training_set(&root.join("tests/data/demo-heldout"), None).unwrap();
    let frame = &frames[0];
    let start = Landmarks {
        points: frame
            .landmarks
            .points
            .iter()
            .map(|p| [p[0] + 2.0, p[1] - 1.0])
            .collect(),
    };
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for (name, iterations) in [("one iteration", 1), ("tracking-like fit", 40)] {
            let fitter = Fitter::new(
                &model,
                FitOptions {
                    max_iterations: iterations,
                    ..FitOptions::default()
                },
                1,
            )
            .unwrap();
            c.bench_function(&format!("fit {name}, 1 level, {threads} thread(s)"), |b| {
                b.iter(|| pool.install(|| fitter.fit(&frame.image, &start).unwrap()))
            });
        }
        let fitter = Fitter::new(&model, FitOptions::default(), 2).unwrap();
        c.bench_function(
            &format!("fit tracking-like, 2 levels, {threads} thread(s)"),
            |b| b.iter(|| pool.install(|| fitter.fit(&frame.image, &start).unwrap())),
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
