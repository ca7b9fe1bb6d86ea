//! `facespace train-weights`: Pareto training of the unit-selection weights on a validation
//! split.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use facespace::codebook::Codebook;
use facespace::corpus;
use facespace::phonemes::PhoneMap;
use facespace::synth::pareto::{self, ParetoOptions};
use facespace::synth::unit::{UnitConstants, WeightsFile};

use super::{load_model, progress_bar};

#[derive(Args)]
pub struct TrainWeightsArgs {
    /// The face model of the codebook and the validation sentences.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// The codebook unit selection draws on.
    #[arg(long)]
    codebook: PathBuf,
    /// Validation sentences (NAME.npy with NAME.lab), disjoint from any test split: the
    /// weights are trained on them.
    #[arg(long, alias = "heldout")]
    validation: PathBuf,
    /// Start from these constants (a weights file); default: [unitsel]'s.
    #[arg(long)]
    constants: Option<PathBuf>,
    /// Seed: same seed, same weights.
    #[arg(long, default_value_t = ParetoOptions::default().seed)]
    seed: u64,
    /// Weight vectors per generation.
    #[arg(long, default_value_t = ParetoOptions::default().population)]
    population: usize,
    /// Generations at most (training stops earlier once the front is stable).
    #[arg(long, default_value_t = ParetoOptions::default().max_generations)]
    generations: usize,
    /// The weights file to write (a plot of the front is written beside it, `.png`).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: TrainWeightsArgs) -> Result<()> {
    let mut inputs = vec![
        a.model.as_path(),
        a.codebook.as_path(),
        a.validation.as_path(),
    ];
    inputs.extend(a.constants.as_deref());
    super::check_output(&a.output, &inputs)?;
    super::check_output(&a.output.with_extension("png"), &inputs)?;
    let model = load_model(&a.model)?;
    let cb = Codebook::load(&a.codebook)
        .with_context(|| format!("loading codebook {}", a.codebook.display()))?;
    cb.check_model(&model)?;
    let validation = corpus::load(&a.validation, cb.fps, cb.layout, None, &PhoneMap::default())
        .with_context(|| format!("reading sentences {}", a.validation.display()))?;
    if validation.is_empty() {
        bail!(
            "no sentences (NAME.npy with NAME.lab) in {}",
            a.validation.display()
        );
    }
    let constants = match &a.constants {
        Some(p) => WeightsFile::read(p)?.constants,
        None => UnitConstants::default(),
    };
    let options = ParetoOptions {
        seed: a.seed,
        population: a.population,
        max_generations: a.generations,
        ..ParetoOptions::default()
    };
    let clock = std::time::Instant::now();
    let (bar, progress) = progress_bar();
    let training = pareto::train(&model, &cb, &validation, constants, &options, progress)?;
    bar.finish_and_clear();
    let c = training.chosen;
    println!(
        "{} weight vectors over {} generations on {} validation sentences in {:.1} s; front of {}",
        training.evaluated.len(),
        training.generations,
        validation.len(),
        clock.elapsed().as_secs_f64(),
        training.front.len()
    );
    println!(
        "chosen: w_tc {:.3}, w_cc {:.3}, w_ccf {:.3}, w_ccg {:.3} → TC_avg {:.4}, SL_avg {:.2}, VC_avg {:.4}; r_pca {:.3}, r_h {:.3}",
        c.weights.w_tc,
        c.weights.w_cc,
        c.weights.w_ccf,
        c.weights.w_ccg,
        c.tc_avg,
        c.sl_avg,
        c.vc_avg,
        training.correlation.0,
        training.correlation.1
    );
    let file = WeightsFile {
        weights: c.weights,
        constants,
        training: Some(serde_json::json!({
            "codebook": a.codebook,
            "validation": a.validation,
            "sentences": validation.len(),
            "options": training.options,
            "generations": training.generations,
            "chosen": training.chosen,
            "correlation": { "r_pca": training.correlation.0, "r_h": training.correlation.1 },
            "front": training.front,
        })),
    };
    file.write(&a.output)?;
    let plot = a.output.with_extension("png");
    facespace::video::write_png(&plot, &training.plot())?;
    println!("→ {} and {}", a.output.display(), plot.display());
    Ok(())
}
