//! `facespace eval`: synthesis scored against held-out sentences, with baselines.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::codebook::Codebook;
use facespace::eval::{System, evaluate, systems::real_mouth_sd};
use facespace::phonemes::PhoneMap;
use facespace::synth::DEFAULT_SMOOTHING;
use facespace::synth::blend::Blend;
use facespace::{atomic, corpus};

use super::{DEMO_MODEL, load_model};

#[derive(Args)]
pub struct EvalArgs {
    #[arg(long, default_value = DEMO_MODEL)]
    model: PathBuf,
    #[arg(long)]
    codebook: PathBuf,
    /// Held-out sentences: NAME.npy (real trajectory) with NAME.lab.
    #[arg(long)]
    heldout: PathBuf,
    #[arg(long, default_value_t = DEFAULT_SMOOTHING)]
    smoothing: f64,
    /// Also report blend + smoothing over a grid of λ.
    #[arg(long)]
    lambda_grid: bool,
    /// Write the table as JSON here.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

pub fn run(a: EvalArgs) -> Result<()> {
    let model = load_model(&a.model)?;
    let cb = Codebook::load(&a.codebook)
        .with_context(|| format!("loading codebook {}", a.codebook.display()))?;
    cb.check_model(&model)?;
    let heldout = corpus::load(&a.heldout, cb.fps, cb.layout, None, &PhoneMap::default())
        .with_context(|| format!("reading held-out sentences {}", a.heldout.display()))?;
    let mut systems = System::standard(a.smoothing);
    if a.lambda_grid {
        for l in [1e-6, 1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 1e-2] {
            systems.push(System::new(Blend::default(), Some(l)));
        }
    }
    let table = evaluate(&model, &cb, &heldout, &systems)?;
    println!("{} held-out sentences; mean over sentences", heldout.len());
    println!(
        "{:<40} {:>7} {:>7} {:>9} {:>8} {:>12}",
        "system", "r_pca", "r_h", "RMSE px", "DTW", "mouth sd px"
    );
    for row in &table {
        let m = row.mean;
        println!(
            "{:<40} {:>7.3} {:>7.3} {:>9.3} {:>8.3} {:>12.3}",
            row.system, m.r_pca, m.r_h, m.rmse_px, m.dtw, m.mouth_sd_px
        );
    }
    println!(
        "{:<40} {:>7} {:>7} {:>9} {:>8} {:>12.3}",
        "real (reference)",
        "",
        "",
        "",
        "",
        real_mouth_sd(&model, &heldout)
    );
    if let Some(out) = &a.output {
        atomic::write_file(out, serde_json::to_string_pretty(&table)?.as_bytes())
            .with_context(|| format!("writing {}", out.display()))?;
    }
    Ok(())
}
