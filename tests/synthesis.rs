//! Blend synthesis on the demo corpus, evaluated honestly: λ chosen on the validation split,
//! every system scored on the test split with the same smoothing (DESIGN §9).
mod common;

use facespace::corpus::demo::Split;
use facespace::eval::systems::{LAMBDA_GRID, choose_smoothing};
use facespace::eval::{System, evaluate};
use facespace::synth::blend::Blend;

#[test]
fn blend_beats_fair_baselines_on_the_test_split() {
    let (model, generated, cb) = common::demo_corpus_codebook();
    let validation = generated.part(Split::Validation);
    let test = generated.part(Split::Test);
    assert!(
        validation
            .iter()
            .all(|v| test.iter().all(|t| t.name != v.name))
    );
    let choice =
        choose_smoothing(&model, &cb, &validation, Blend::default(), &LAMBDA_GRID).unwrap();
    let table = evaluate(
        &model,
        &cb,
        &test,
        &System::comparison(choice.lambda, Default::default()),
    )
    .unwrap();
    for row in &table {
        let m = row.mean;
        eprintln!(
            "{:<42} r_pca {:.3}  DTW {:.1}  mouth sd {:.3} px",
            row.system, m.r_pca, m.dtw, m.mouth_sd_px
        );
    }
    let row = |name: &str| {
        table
            .iter()
            .find(|r| r.system == name)
            .unwrap_or_else(|| panic!("no row {name}"))
            .mean
    };
    let l = format!("{:e}", choice.lambda);
    for suffix in [format!("smoothed λ={l}"), "unsmoothed".into()] {
        let n3 = row(&format!("blend C=1 N=3, {suffix}"));
        for other in ["blend C=1 N=1", "per-phoneme mean", "random lips"] {
            let o = row(&format!("{other}, {suffix}"));
            assert!(
                n3.r_pca > o.r_pca && n3.dtw < o.dtw,
                "{suffix}: N=3 (r_pca {:.3}, DTW {:.1}) vs {other} (r_pca {:.3}, DTW {:.1})",
                n3.r_pca,
                n3.dtw,
                o.r_pca,
                o.dtw
            );
        }
    }
    // Smoothing lowers the articulation amplitude (std of mouth height).
    let (smoothed, raw) = (
        row(&format!("blend C=1 N=3, smoothed λ={l}")),
        row("blend C=1 N=3, unsmoothed"),
    );
    assert!(smoothed.mouth_sd_px < raw.mouth_sd_px);
}
