//! `facespace eval`: synthesis scored against held-out sentences, with fair baselines.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::codebook::Codebook;
use facespace::synth::systems::{LAMBDA_GRID, choose_smoothing, real_mouth_sd};
use facespace::synth::systems::{System, evaluate};
use facespace::phonemes::PhoneMap;
use facespace::synth::DEFAULT_SMOOTHING;
use facespace::synth::blend::Blend;
use facespace::synth::unit::{UnitSelection, WeightsFile};
use facespace::{atomic, corpus};

use super::load_model;

#[derive(Args)]
pub struct EvalArgs {
    /// The face model of the codebook and the held-out sentences.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// The codebook synthesis draws on (built from training sentences only).
    #[arg(long)]
    codebook: PathBuf,
    /// Test sentences, reported: NAME.npy (real trajectory) with NAME.lab.
    #[arg(long)]
    heldout: PathBuf,
    /// Validation sentences (disjoint from the test ones, never reported): λ is chosen on
    /// them over a grid. Without them, --smoothing is used as given.
    #[arg(long)]
    validation: Option<PathBuf>,
    /// Smoothing weight λ when no validation split is given.
    #[arg(long, default_value_t = DEFAULT_SMOOTHING)]
    smoothing: f64,
    /// Unit-selection weights and constants (a `train-weights` file; default: all weights 1).
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Write the table (and the λ choice) as JSON here.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

pub fn run(a: EvalArgs) -> Result<()> {
    if let Some(out) = &a.output {
        let mut inputs = vec![a.model.as_path(), a.codebook.as_path(), a.heldout.as_path()];
        inputs.extend(a.validation.as_deref());
        inputs.extend(a.weights.as_deref());
        super::check_output(out, &inputs)?;
    }
    let model = load_model(&a.model)?;
    let cb = Codebook::load(&a.codebook)
        .with_context(|| format!("loading codebook {}", a.codebook.display()))?;
    cb.check_model(&model)?;
    let load = |dir: &PathBuf| {
        corpus::load(dir, cb.fps, cb.layout, None, &PhoneMap::default())
            .with_context(|| format!("reading sentences {}", dir.display()))
    };
    let heldout = load(&a.heldout)?;
    let choice = match &a.validation {
        Some(dir) => {
            let validation = load(dir)?;
            let choice =
                choose_smoothing(&model, &cb, &validation, Blend::default(), &LAMBDA_GRID)?;
            println!(
                "λ chosen on {} validation sentences (blend C=1 N=3, lowest mean DTW):",
                validation.len()
            );
            for (l, s) in &choice.grid {
                println!("  λ={l:e}: r_pca {:.3}, DTW {:.1}", s.r_pca, s.dtw);
            }
            println!("  → λ = {:e}", choice.lambda);
            Some(choice)
        }
        None => {
            println!(
                "λ = {:e} as given (no validation split: not tuned here)",
                a.smoothing
            );
            None
        }
    };
    let lambda = choice.as_ref().map_or(a.smoothing, |c| c.lambda);
    let unit = match &a.weights {
        Some(p) => WeightsFile::read(p)?.unit_selection(),
        None => UnitSelection::default(),
    };
    let table = evaluate(&model, &cb, &heldout, &System::comparison(lambda, unit))?;
    println!("{} test sentences; mean over sentences", heldout.len());
    println!(
        "{:<46} {:>6} {:>6} {:>8} {:>7} {:>8} {:>7} {:>6} {:>7}",
        "system", "r_pca", "r_h", "RMSE px", "DTW", "mouth sd", "TC_avg", "SL_avg", "VC_avg"
    );
    for row in &table {
        let m = row.mean;
        let sel = row.selection.map_or_else(
            || format!("{:>7} {:>6} {:>7}", "—", "—", "—"),
            |s| format!("{:>7.4} {:>6.1} {:>7.4}", s.tc_avg, s.sl_avg, s.vc_avg),
        );
        println!(
            "{:<46} {:>6.3} {:>6.3} {:>8.3} {:>7.1} {:>8.3} {sel}",
            row.system, m.r_pca, m.r_h, m.rmse_px, m.dtw, m.mouth_sd_px
        );
    }
    println!(
        "{:<46} {:>6} {:>6} {:>8} {:>7} {:>8.3}",
        "real (reference)",
        "",
        "",
        "",
        "",
        real_mouth_sd(&model, &heldout)
    );
    if table.iter().any(|r| r.mouth.is_some()) {
        println!(
            "\nmouth measures ([unitsel] §7): r_pca = eq. 16, first PC of the photometrically normalised mouth region (fitted on the test frames); r_h on the inner-mouth height; flicker = synthesised / real within-sentence s.d. per appearance parameter"
        );
        println!(
            "{:<46} {:>10} {:>10} {:>11} {:>13} {:>13}",
            "system", "r_pca eq16", "r_h inner", "inner sd ×", "lip motion ×", "flicker worst"
        );
        for row in &table {
            if let Some(m) = &row.mouth {
                println!(
                    "{:<46} {:>10.3} {:>10.3} {:>11.3} {:>13.3} {:>13.2}",
                    row.system,
                    m.r_pca_mouth,
                    m.r_h_inner,
                    m.inner_sd_ratio,
                    m.lip_motion_ratio,
                    m.flicker_worst
                );
            }
        }
    }
    if let Some(out) = &a.output {
        let json = serde_json::json!({ "smoothing": choice, "lambda": lambda, "table": table });
        atomic::write_file(out, serde_json::to_string_pretty(&json)?.as_bytes())
            .with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}
