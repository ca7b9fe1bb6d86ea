//! The ceiling row of the GRID evaluation (recorded speech): the same test sentences tracked
//! twice — the default project-out search, and again with 3 steps of alternating refinement per
//! frame (`corpus from-videos --refine 3`) — scored against each other with `eval`'s measures.
//! What a synthesis could at best reach, given how exactly tracking measures the face.
//!
//! `cargo run --release --example grid_ceiling -- MODEL TEST_CORPUS RETRACKED_CORPUS`

use std::path::PathBuf;

use facespace::corpus;
use facespace::eval::mouth::{MouthPc, flicker, inner_mouth_height};
use facespace::eval::{landmarks, mean_scores, pearson, score, standard_deviation};
use facespace::model::FaceModel;
use facespace::phonemes::PhoneMap;

fn main() {
    let a: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let model = FaceModel::load(&a[0]).unwrap();
    let load =
        |p: &PathBuf| corpus::load(p, 25.0, model.layout(), None, &PhoneMap::default()).unwrap();
    let (tracked, again) = (load(&a[1]), load(&a[2]));
    let frames: Vec<_> = tracked.iter().map(|s| &s.frames).collect();
    let pc = MouthPc::fit(&model, &frames).unwrap();
    let inner = |f: &facespace::facespace::Frames| -> Vec<f64> {
        landmarks(&model, f)
            .iter()
            .map(|p| inner_mouth_height(p))
            .collect()
    };
    let (mut r_pca, mut r_h, mut sd_ratio, mut worst) =
        (0.0, 0.0, 0.0, vec![0.0; model.layout().appearance]);
    let mut scores = Vec::new();
    let n = tracked.len() as f64;
    for (s, t) in tracked.iter().zip(&again) {
        assert_eq!(s.name, t.name);
        r_pca += pearson(&pc.series(&t.frames), &pc.series(&s.frames)) / n;
        let (hi_t, hi_s) = (inner(&t.frames), inner(&s.frames));
        r_h += pearson(&hi_t, &hi_s) / n;
        sd_ratio += standard_deviation(&hi_t) / standard_deviation(&hi_s).max(1e-9) / n;
        for (w, f) in worst.iter_mut().zip(flicker(&t.frames, &s.frames)) {
            *w += f / n;
        }
        scores.push(score(&model, &t.frames, &s.frames));
    }
    let m = mean_scores(&scores);
    println!(
        "ceiling (re-tracked with --refine 3 vs tracked), {} test sentences: r_pca (eq. 16) {r_pca:.3}, inner r_h {r_h:.3}, inner s.d. {sd_ratio:.2}×, flicker worst {:.2}; whole-face r_pca {:.3}, outer r_h {:.3}, RMSE {:.3} px, DTW {:.1}",
        tracked.len(),
        worst.iter().cloned().fold(0.0, f64::max),
        m.r_pca,
        m.r_h,
        m.rmse_px,
        m.dtw
    );
}
