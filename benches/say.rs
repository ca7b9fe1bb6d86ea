//! The talker pipeline on the committed GRID s1 talker (issue 33): loading the talker folder,
//! planning its living frame, and `say` of a 3-second sentence into an MP4 — from text (Festival speaks, the aligner
//! times it; skipped without an engine) and from a recording with its words.
//! Run: cargo bench --bench say

use criterion::{Criterion, criterion_group, criterion_main};
use facespace::render::RendererChoice;
use facespace::talker::{SayRequest, Speech, Talker};

fn bench(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("models/grid");
    let mut group = c.benchmark_group("talker");
    group.sample_size(10);
    group.bench_function("load the GRID s1 talker", |b| {
        b.iter(|| Talker::load(&dir).unwrap())
    });
    let talker = Talker::load(&dir).unwrap();
    for n in [92, 1199] {
        group.bench_function(format!("living frame for {n} frames (best of 16 starts)"), |b| {
            b.iter(|| talker.footage.best_plan(n, 0))
        });
    }
    let out = tempfile::tempdir().unwrap();
    let video = out.path().join("say.mp4");
    let data = root.join("tests/data/grid");
    let recording = SayRequest {
        renderer: RendererChoice::Cpu,
        ..SayRequest::new(Speech::Recording {
            audio: data.join("bbbs7a.wav"),
            words: std::fs::read_to_string(data.join("bbbs7a.txt")).unwrap(),
        })
    };
    group.bench_function("say a 3 s recording with its words → MP4 (CPU)", |b| {
        b.iter(|| talker.say(&recording, &video, facespace::no_progress).unwrap())
    });
    if facespace::tts::available().is_some() {
        let text = SayRequest {
            renderer: RendererChoice::Cpu,
            ..SayRequest::new(Speech::Text(
                "Please call me tomorrow morning about the shipment.".into(),
            ))
        };
        group.bench_function("say a 3.7 s sentence from text → MP4 (CPU)", |b| {
            b.iter(|| talker.say(&text, &video, facespace::no_progress).unwrap())
        });
    } else {
        eprintln!("no text-to-speech engine: the text benchmark is skipped");
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
