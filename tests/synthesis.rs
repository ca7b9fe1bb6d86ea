//! Blend synthesis on the demo corpus: it must beat the baselines on the held-out split.
mod common;

use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::corpus::demo::{self as corpus, CorpusOptions};
use facespace::eval::{System, evaluate};
use facespace::model::{FaceModel, load_training_set};
use facespace::synth::DEFAULT_SMOOTHING;
use facespace::synth::blend::Blend;

#[test]
fn blend_beats_baselines_on_held_out_sentences() {
    let model = FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let frames = load_training_set(&common::root().join("models/demo/training"), None).unwrap();
    let (train, held) = corpus::generate(&model, &frames, &CorpusOptions::default())
        .unwrap()
        .split();
    let cb = Codebook::build(
        train,
        25.0,
        model.layout(),
        Some(model.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    let systems = [
        System::new(Blend::default(), Some(DEFAULT_SMOOTHING)),
        System::new(Blend::default(), None),
        System::new(
            Blend {
                top_n: 1,
                ..Default::default()
            },
            None,
        ),
        System::new(Blend::PHONE_MEAN, None),
    ];
    let table = evaluate(&model, &cb, &held, &systems).unwrap();
    let means: Vec<(f64, f64, f64)> = table
        .iter()
        .map(|row| {
            let m = row.mean;
            eprintln!(
                "{:<40} r_pca {:.3}  DTW {:.1}  mouth sd {:.3} px",
                row.system, m.r_pca, m.dtw, m.mouth_sd_px
            );
            (m.r_pca, m.dtw, m.mouth_sd_px)
        })
        .collect();
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
