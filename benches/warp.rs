//! Piecewise affine warp of a 720×576 RGB frame through the 68-landmark face mesh
//! (112 triangles), both directions, on one thread and on all threads.
//! Run: cargo bench --bench warp
//! For instruction counts (repeatable on a shared machine), `WARP_CALLS=N` runs each direction
//! N times on one thread outside criterion and exits, e.g. under
//! `valgrind --tool=callgrind --toggle-collect='*warp*_into*'`.

use criterion::{Criterion, criterion_group, criterion_main};
use facespace::mesh::{self, ReferenceFrame};
use facespace::shape::read_pts;
use facespace::warp;
use image::RgbImage;

/// Lenna scaled by 1.4 onto a 720×576 canvas (face ≈ 250×330 px), its landmarks, and a
/// 40 000-pixel reference frame of its own shape.
fn setup() -> (RgbImage, Vec<[f64; 2]>, ReferenceFrame) {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/models/faces/training");
    let lenna = image::open(format!("{dir}/lenna.png")).unwrap().to_rgb8();
    let big = image::imageops::resize(&lenna, 717, 717, image::imageops::FilterType::Triangle);
    let frame = image::imageops::crop_imm(&big, 0, 70, 720.min(big.width()), 576).to_image();
    let mut canvas = RgbImage::new(720, 576);
    image::imageops::replace(&mut canvas, &frame, 0, 0);
    let pts = read_pts(std::path::Path::new(&format!("{dir}/lenna.pts")))
        .unwrap()
        .points;
    let s = 717.0 / 512.0;
    let landmarks: Vec<[f64; 2]> = pts
        .iter()
        .map(|p| [(p[0] + 0.5) * s - 0.5, (p[1] + 0.5) * s - 0.5 - 70.0])
        .collect();
    let c = facespace::shape::centroid(&landmarks);
    let norm = landmarks
        .iter()
        .map(|p| (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2))
        .sum::<f64>()
        .sqrt();
    let mean: Vec<[f64; 2]> = landmarks
        .iter()
        .map(|p| [(p[0] - c[0]) / norm, (p[1] - c[1]) / norm])
        .collect();
    let (reference, _) =
        ReferenceFrame::fit_mean(&mean, mesh::delaunay(&mean).unwrap(), 40_000, 0.0).unwrap();
    (canvas, landmarks, reference)
}

fn bench(c: &mut Criterion) {
    let (image, landmarks, frame) = setup();
    let mut texture = vec![0f32; frame.n_pixels() * 3];
    warp::to_reference_into(&frame, &image, &landmarks, &mut texture).unwrap();
    let mut out = RgbImage::new(720, 576);
    if let Some(n) = std::env::var("WARP_CALLS")
        .ok()
        .and_then(|v| v.parse::<usize>().ok())
    {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        pool.install(|| {
            for _ in 0..n {
                warp::to_reference_into(&frame, &image, &landmarks, &mut texture).unwrap();
                warp::from_reference_into(&frame, &texture, &landmarks, &mut out).unwrap();
            }
        });
        std::process::exit(0);
    }
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        c.bench_function(
            &format!(
                "to_reference 720x576 -> {} px, {threads} thread(s)",
                frame.n_pixels()
            ),
            |b| {
                b.iter(|| {
                    pool.install(|| {
                        warp::to_reference_into(&frame, &image, &landmarks, &mut texture).unwrap()
                    })
                })
            },
        );
        c.bench_function(
            &format!(
                "from_reference {} px -> 720x576, {threads} thread(s)",
                frame.n_pixels()
            ),
            |b| {
                b.iter(|| {
                    pool.install(|| {
                        warp::from_reference_into(&frame, &texture, &landmarks, &mut out).unwrap()
                    })
                })
            },
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
