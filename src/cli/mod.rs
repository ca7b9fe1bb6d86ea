//! Subcommands, progress bars and human-readable reports.

mod codebook;
mod codec;
mod corpus;
mod demo;
mod model;
mod synth;
mod track;

use clap::{Parser, Subcommand};
use facespace::Progress;
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Parser)]
#[command(
    name = "facespace",
    version,
    about = "Talking-face animation from independent shape and appearance models"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build, inspect and test face models.
    #[command(subcommand)]
    Model(model::ModelCommand),
    /// Build, inspect and plot synthesis codebooks.
    #[command(subcommand)]
    Codebook(codebook::CodebookCommand),
    /// Generate corpora.
    #[command(subcommand)]
    Corpus(corpus::CorpusCommand),
    /// Track faces through a video or frame folder by AAM search.
    Track(track::TrackArgs),
    /// Encode a video through face-space: track + project every frame → a clip folder.
    Encode(codec::EncodeArgs),
    /// Decode a clip folder: reconstruct and render every frame → a video.
    Decode(codec::DecodeArgs),
    /// PSNR / SSIM inside the face mask and bytes per frame of a clip against its input.
    CodecReport(codec::ReportArgs),
    /// Synthesise a face-space trajectory and video from phonemes or text (top-N blending).
    Synth(synth::SynthArgs),
    /// Score synthesis against held-out sentences (r_pca, r_h, RMSE, DTW) with baselines.
    Eval(synth::EvalArgs),
    /// Build a model from the bundled faces and write reconstructions to out/demo.
    Demo(demo::DemoArgs),
}

pub fn run() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Model(c) => model::run(c),
        Command::Codebook(c) => codebook::run(c),
        Command::Corpus(c) => corpus::run(c),
        Command::Track(a) => track::run(a),
        Command::Encode(a) => codec::encode(a),
        Command::Decode(a) => codec::decode(a),
        Command::CodecReport(a) => codec::report(a),
        Command::Synth(a) => synth::synth(a),
        Command::Eval(a) => synth::evaluate(a),
        Command::Demo(a) => demo::run(a),
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal) and the callback that
/// drives it.
pub fn progress_bar() -> (ProgressBar, impl FnMut(Progress)) {
    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg:<18} [{bar:30}] {pos}/{len} {elapsed}")
            .expect("valid template"),
    );
    let handle = bar.clone();
    let callback = move |p: Progress| {
        handle.set_length(p.total as u64);
        handle.set_position(p.done as u64);
        handle.set_message(p.stage);
    };
    (bar, callback)
}
