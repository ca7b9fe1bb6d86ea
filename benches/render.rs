//! Renderers at 720×576: a batch of 32 frames of the demo model (its face at twice the size
//! of the recorded one, over a real frame, feathered edge) by the CPU renderer on 1 and 2
//! threads and by the GPU renderer on every adapter found (with and without reading the
//! frames back). Throughput is in frames.
//! Run: cargo bench --bench render

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use facespace::facespace::Frames;
use facespace::model::{FaceModel, load_training_set};
use facespace::render::{CpuRenderer, DEFAULT_FEATHER, Renderer};
use image::RgbImage;

const BATCH: usize = 32;

fn bench(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/demo/model")).unwrap();
    let training = load_training_set(&root.join("models/demo/training"), None).unwrap();
    let mut rows = Vec::new();
    for k in 0..BATCH {
        let f = &training[k % training.len()];
        let mut row = model.project(&f.image, &f.landmarks).unwrap();
        row[..4].iter_mut().for_each(|v| *v *= 2.0);
        rows.extend(row);
    }
    let frames = Frames::from_rows(model.layout(), 25.0, rows).unwrap();
    let background = image::imageops::resize(
        &training[0].image,
        720,
        576,
        image::imageops::FilterType::Triangle,
    );
    let canvases = vec![background; BATCH];
    let mut group = c.benchmark_group("render 720x576");
    group.throughput(Throughput::Elements(BATCH as u64));
    group.sample_size(10);
    let cpu = CpuRenderer::feathered(&model, DEFAULT_FEATHER);
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        group.bench_function(format!("CPU, {threads} thread(s)"), |b| {
            b.iter(|| {
                let mut out: Vec<RgbImage> = canvases.clone();
                pool.install(|| cpu.render_batch(&frames, 0, &mut out).unwrap());
                out
            })
        });
    }
    #[cfg(feature = "gpu")]
    {
        use facespace::render::gpu::{Backends, Gpu, GpuRenderer};
        for backends in [Backends::Gl, Backends::Vulkan] {
            let gpu = match Gpu::new(backends) {
                Ok(g) => g,
                Err(e) => {
                    eprintln!("{backends:?}: {e}");
                    continue;
                }
            };
            let renderer = GpuRenderer::new(&gpu, &model, Some(DEFAULT_FEATHER)).unwrap();
            group.bench_function(format!("GPU {}, with readback", gpu.describe()), |b| {
                b.iter(|| {
                    let mut out: Vec<RgbImage> = canvases.clone();
                    renderer.render_batch(&frames, 0, &mut out).unwrap();
                    out
                })
            });
            group.bench_function(format!("GPU {}, no readback", gpu.describe()), |b| {
                b.iter(|| renderer.render_batch_on_gpu(&frames, 0, &canvases).unwrap())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
