//! Tracking speed on GRID s1 (issue 37): the talker's model tracks recorded test clips on one
//! core — frame t from frame t−1's fit, 2 pyramid levels, the defaults of `track` — with the
//! frames decoded beforehand, so only tracking is timed. Prints frames per second, the mean
//! residual and iterations; with `--save FILE` writes every frame's landmarks, and with
//! `--compare FILE` the mean and worst landmark distance to a saved run (accuracy unchanged
//! within noise across a change of the tracker).
//!
//! `cargo run --release --example grid_track -- ../shared/data/grid-s1 [LIMIT] [SPLIT] [--save F | --compare F]`

#[path = "common/grid.rs"]
mod grid;

use std::time::{Duration, Instant};

use facespace::codec::EncodeOptions;
use facespace::fit::{Fitter, Tracker};
use facespace::video::Source;

fn main() {
    let argv: Vec<String> = std::env::args().collect();
    let flag = |name: &str| argv.iter().position(|a| a == name).map(|i| argv[i + 1].clone());
    let (grid, limit, split) = grid::args();
    let split = if split.starts_with("--") { "test".into() } else { split };
    let talker = facespace::talker::Talker::load("models/grid".as_ref()).unwrap();
    let model = talker.model.tracker();
    let options = EncodeOptions::default();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let ids = grid::split(&grid, &split, limit.min(20));
    let (mut spent, mut frames, mut error, mut iterations) = (Duration::ZERO, 0usize, 0f64, 0usize);
    let mut all: Vec<Vec<[f64; 2]>> = Vec::new();
    for id in &ids {
        let images: Vec<image::RgbImage> = Source::open(&grid.join(format!("clips/{id}.mp4")))
            .unwrap()
            .map(Result::unwrap)
            .collect();
        let fitter = Fitter::new(model, options.fit, options.levels).unwrap();
        let start = fitter.search_start(&images[0]).unwrap();
        let mut tracker = Tracker::new(fitter, start, options.reinit_error).unwrap();
        pool.install(|| {
            let t = Instant::now();
            for image in &images {
                let f = tracker.track(image).unwrap();
                error += f.error;
                iterations += f.iterations;
                all.push(f.landmarks.points);
            }
            spent += t.elapsed();
        });
        frames += images.len();
    }
    println!(
        "GRID s1 {split}: {} clips, {frames} frames tracked on one core: {:.0} fps ({:.2} ms a frame), mean residual {:.3} grey levels, {:.2} iterations a frame",
        ids.len(),
        frames as f64 / spent.as_secs_f64(),
        spent.as_secs_f64() * 1e3 / frames as f64,
        error / frames as f64,
        iterations as f64 / frames as f64,
    );
    if let Some(path) = flag("--save") {
        std::fs::write(&path, serde_json::to_string(&all).unwrap()).unwrap();
    }
    if let Some(path) = flag("--compare") {
        let before: Vec<Vec<[f64; 2]>> = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(before.len(), all.len(), "the same clips");
        let d: Vec<f64> = before
            .iter()
            .zip(&all)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])))
            .collect();
        println!(
            "landmarks against {path}: mean {:.4} px, worst {:.3} px",
            d.iter().sum::<f64>() / d.len() as f64,
            d.iter().fold(0f64, |m, &x| m.max(x))
        );
    }
}
