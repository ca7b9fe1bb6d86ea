//! `facespace study create | serve | analyse`: the subjective evaluation kit.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use facespace::codebook::Codebook;
use facespace::study::analyse::write_report;
use facespace::study::create::load_heldout;
use facespace::study::serve::Event;
use facespace::study::{self, Condition, CreateOptions, StudyServer, Task};
use facespace::synth::DEFAULT_SMOOTHING;
use facespace::synth::unit::{UnitSelection, WeightsFile};

use super::{RendererArg, load_model, progress_bar};

#[derive(Subcommand)]
pub enum StudyCommand {
    /// Render the stimuli of held-out sentences under each condition, with each viewer's
    /// randomised, counter-balanced order → a study folder.
    #[command(
        after_help = "Example: facespace study create --model models/demo/model --codebook out/codebook --heldout out/corpus/heldout -o out/study"
    )]
    Create(CreateArgs),
    /// Serve the study to viewers on a local page; answers are stored as they are given.
    #[command(after_help = "Example: facespace study serve out/study")]
    Serve(ServeArgs),
    /// Wilcoxon, Kruskal–Wallis and Turing-test tables and a box plot from the answers.
    #[command(after_help = "Example: facespace study analyse out/study -o out/study-report")]
    Analyse(AnalyseArgs),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TaskArg {
    /// A/B rating of pairs (DSCQS, 1–50).
    Rating,
    /// Real or synthetic? (needs the original).
    Turing,
    /// The Turing test first, then the ratings.
    Both,
}

#[derive(Args)]
pub struct CreateArgs {
    /// A talker folder (`talker build`): its model, codebook and λ are the defaults (its N is
    /// a condition as `blend-nN`); the flags override them.
    #[arg(long)]
    talker: Option<PathBuf>,
    /// The face model of the codebook and the held-out sentences (default: the talker's, else
    /// the demo model).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The codebook the synthetic conditions draw on (no held-out sentence in it; default: the
    /// talker's).
    #[arg(long, required_unless_present = "talker")]
    codebook: Option<PathBuf>,
    /// Held-out sentences (NAME.npy or NAME.fsp/ with NAME.lab; NAME.m4a is muxed in), none
    /// of them in the codebook.
    #[arg(long)]
    heldout: PathBuf,
    /// Conditions: original, blend-nN, random-lips, unit, smoothed, unsmoothed (the default
    /// blend C=1 N=3 with and without smoothing). Default: original, blend-n1, blend-n3,
    /// blend-n5, random-lips, unit, smoothed, unsmoothed, and with --talker its blend-nN.
    #[arg(long, value_delimiter = ',')]
    conditions: Option<Vec<String>>,
    /// Viewers, each with their own order and link.
    #[arg(long, default_value_t = 10)]
    viewers: usize,
    /// Which tests.
    #[arg(long, value_enum, default_value_t = TaskArg::Both)]
    task: TaskArg,
    /// Smoothing weight λ of every smoothed condition (default: the talker's, else 3e-5;
    /// choose it with `eval --validation`).
    #[arg(long)]
    smoothing: Option<f64>,
    /// Unit-selection weights (a `train-weights` file; default: all weights 1).
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Seed of the orders.
    #[arg(long, default_value_t = 16)]
    seed: u64,
    /// Which renderer draws the stimuli.
    #[arg(long, value_enum, default_value_t)]
    renderer: RendererArg,
    /// The study folder to write (stimuli/, study.json).
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct ServeArgs {
    /// The study folder.
    dir: PathBuf,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8018")]
    listen: String,
    /// Allow a non-loopback address (viewers on other machines; each still needs their link).
    #[arg(long)]
    allow_remote: bool,
}

#[derive(Args)]
pub struct AnalyseArgs {
    /// The study folder.
    dir: PathBuf,
    /// Report folder: report.json, report.md, scores.png.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(c: StudyCommand) -> Result<()> {
    match c {
        StudyCommand::Create(a) => create(a),
        StudyCommand::Serve(a) => serve(a),
        StudyCommand::Analyse(a) => analyse(a),
    }
}

/// The conditions of a study when none are named.
const DEFAULT_CONDITIONS: [&str; 8] = [
    "original",
    "blend-n1",
    "blend-n3",
    "blend-n5",
    "random-lips",
    "unit",
    "smoothed",
    "unsmoothed",
];

fn create(a: CreateArgs) -> Result<()> {
    // A talker lends its model, codebook and settings (its manifest checked as a talker's).
    let manifest = a.talker.as_deref().map(facespace::talker::read_manifest).transpose()?;
    let part = |name: &str| facespace::manifest::member(a.talker.as_deref().expect("a talker"), name);
    let lent = |name: Option<&String>| name.map(|n| part(n)).transpose();
    let model_path = a
        .model
        .clone()
        .or(lent(manifest.as_ref().map(|m| &m.model))?)
        .unwrap_or_else(|| super::committed_path(super::DEMO_MODEL_SHOWN).expect("infallible"));
    let codebook = a
        .codebook
        .clone()
        .or(lent(manifest.as_ref().map(|m| &m.codebook))?)
        .context("give --codebook (or --talker)")?;
    let smoothing = a
        .smoothing
        .or(manifest.as_ref().map(|m| m.settings.smoothing))
        .unwrap_or(DEFAULT_SMOOTHING);
    let mut inputs = vec![model_path.as_path(), codebook.as_path(), a.heldout.as_path()];
    inputs.extend(a.talker.as_deref());
    inputs.extend(a.weights.as_deref());
    super::check_output(&a.output, &inputs)?;
    let model = load_model(&model_path)?;
    let cb = Codebook::load(&codebook)
        .with_context(|| format!("loading codebook {}", codebook.display()))?;
    cb.check_model(&model)?;
    let mut names = a.conditions.clone().unwrap_or_else(|| {
        DEFAULT_CONDITIONS.iter().map(|c| c.to_string()).collect()
    });
    if let (None, Some(m)) = (&a.conditions, &manifest) {
        let own = format!("blend-n{}", m.settings.top_n);
        if !names.contains(&own) {
            names.push(own);
        }
    }
    let conditions = names
        .iter()
        .map(|s| s.parse::<Condition>().map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()?;
    let heldout = load_heldout(&a.heldout, &cb, &model.hash())?;
    let unit = match &a.weights {
        Some(p) => WeightsFile::read(p)?.unit_selection(),
        None => UnitSelection::default(),
    };
    let options = CreateOptions {
        conditions,
        viewers: a.viewers,
        task: match a.task {
            TaskArg::Rating => Task::Rating,
            TaskArg::Turing => Task::Turing,
            TaskArg::Both => Task::Both,
        },
        smoothing,
        unit,
        seed: a.seed,
    };
    let renderer = a
        .renderer
        .make(&model, Some(facespace::render::DEFAULT_FEATHER))?;
    let (bar, progress) = progress_bar();
    let manifest = study::create(
        &a.output,
        &model,
        &cb,
        &heldout,
        renderer.as_ref(),
        &options,
        progress,
    )
    .with_context(|| format!("creating study {}", a.output.display()))?;
    bar.finish_and_clear();
    let with_sound = manifest.stimuli.iter().filter(|s| s.audio).count();
    println!(
        "{}: {} stimuli ({} sentences × {} conditions, {with_sound} with sound), {} viewers × {} trials",
        a.output.display(),
        manifest.stimuli.len(),
        manifest.sentences.len(),
        manifest.conditions.len(),
        manifest.viewers.len(),
        manifest.viewers.first().map_or(0, |v| v.trials.len()),
    );
    println!(
        "each clip {}×{}, centred on the face ({:.0} % of its side), drawn over {}",
        manifest.canvas[0],
        manifest.canvas[1],
        100.0 * facespace::study::create::FACE_SHARE,
        if manifest.over_recordings {
            "each sentence's own recording (NAME.mp4 beside it)"
        } else {
            "plain grey (put NAME.mp4 beside each held-out sentence to draw it over its recording)"
        }
    );
    println!(
        "serve it with: facespace study serve {}",
        a.output.display()
    );
    Ok(())
}

fn serve(a: ServeArgs) -> Result<()> {
    let (mut server, note) = StudyServer::bind(&a.dir, &a.listen, a.allow_remote)
        .with_context(|| format!("serving study {}", a.dir.display()))?;
    if let Some(note) = note {
        eprintln!("note: {note}");
    }
    println!(
        "study {} at {} — each viewer's link:",
        a.dir.display(),
        server.url()
    );
    for (viewer, link) in server.links() {
        println!("  {viewer}: {link}");
    }
    println!("(Ctrl+C to stop; every answer is on disk before the page moves on)");
    let mut refusals = super::Refusals::default();
    server.run(
        |event| match event {
            Event::Stored(viewer, trial) => println!("stored {viewer} trial {trial}"),
            Event::Refused(path, why) => refusals.log(&path, &why),
            Event::Notice(what) => eprintln!("note: {what}"),
        },
        || false,
    );
    Ok(())
}

fn analyse(a: AnalyseArgs) -> Result<()> {
    super::check_output(&a.output, &[&a.dir])?;
    let report =
        study::analyse(&a.dir).with_context(|| format!("analysing {}", a.dir.display()))?;
    write_report(&a.output, &report)
        .with_context(|| format!("writing report {}", a.output.display()))?;
    print!("{}", report.markdown());
    println!(
        "\nwritten: {}/report.{{json,md}}, scores.png",
        a.output.display()
    );
    Ok(())
}
