//! Video through face-space at 720×576: encode (decode MP4 + track + project every frame)
//! and decode (render every frame + H.264 encode), 100 frames of the FGNet clip scaled ×2.
//! The input is written once to target/bench-codec/clip720.mp4 (first-frame landmarks beside
//! it), so the CLI of another build can be timed on the same file (BENCHMARKS.md).
//! Run: cargo bench --bench codec

use std::path::{Path, PathBuf};

use criterion::{Criterion, criterion_group, criterion_main};
use facespace::codec::{self, EncodeOptions};
use facespace::model::FaceModel;
use facespace::render::{Background, CpuRenderer};
use facespace::shape::{Landmarks, read_pts};
use facespace::video::{self, Sink, Source};

const FRAMES: usize = 100;

/// The clip's 50 frames scaled to 720×576, forwards then backwards, as an MP4; and the first
/// frame's landmarks at that scale.
fn input() -> (PathBuf, Landmarks) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("target/bench-codec");
    let path = dir.join("clip720.mp4");
    let clip = root.join("tests/data/clip");
    let files = video::frame_files(&clip).unwrap();
    if !path.is_file() {
        let mut sink = Sink::create(&path, 720, 576, 25.0, None).unwrap();
        for i in 0..FRAMES {
            let k = if i < files.len() {
                i
            } else {
                2 * files.len() - 1 - i
            };
            let f = video::read_frame(&files[k]).unwrap();
            let big = image::imageops::resize(&f, 720, 576, image::imageops::FilterType::Triangle);
            sink.write(&big).unwrap();
        }
        sink.finish().unwrap();
    }
    let pts = read_pts(&files[0].with_extension("pts")).unwrap();
    let init = Landmarks {
        points: pts
            .points
            .iter()
            .map(|p| [(p[0] + 0.5) * 2.0 - 0.5, (p[1] + 0.5) * 2.0 - 0.5])
            .collect(),
    };
    // The same start for the CLI of another build: `encode --init clip720.pts`.
    facespace::shape::write_pts(&dir.join("clip720.pts"), &init).unwrap();
    (path, init)
}

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/demo/model")).unwrap();
    let (path, init) = input();
    let options = EncodeOptions {
        init: Some(init),
        ..EncodeOptions::default()
    };
    let mut group = c.benchmark_group("codec 720x576");
    group.sample_size(10);
    group.bench_function(format!("encode {FRAMES} frames"), |b| {
        b.iter(|| {
            let source = Source::open(&path).unwrap();
            codec::encode(&model, source, &options, facespace::no_progress).unwrap()
        })
    });
    let clip = codec::encode(
        &model,
        Source::open(&path).unwrap(),
        &options,
        facespace::no_progress,
    )
    .unwrap()
    .clip;
    let out = tempfile::tempdir().unwrap();
    group.bench_function(format!("decode {FRAMES} frames to MP4"), |b| {
        b.iter(|| {
            let mut sink = Sink::create(&out.path().join("d.mp4"), 720, 576, 25.0, None).unwrap();
            let background = Background::Plain {
                width: 720,
                height: 576,
            };
            codec::decode(
                &CpuRenderer::new(&model),
                &clip,
                background,
                &mut sink,
                facespace::no_progress,
            )
            .unwrap();
            sink.finish().unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
