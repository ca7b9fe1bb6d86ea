//! Subcommands: each parses its arguments, makes one library call with a progress bar, and
//! prints what came back. No library logic lives here.

mod align;
mod annotate;
mod codebook;
mod codec;
mod corpus;
mod demo;
mod eval;
mod frames;
mod model;
mod say;
mod serve;
mod study;
mod synth;
mod talker;
mod track;
mod visemes;
mod weights;

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand, ValueEnum};
use facespace::codec::{EncodeOptions, TrackingSummary};
use facespace::fit::{DEFAULT_REINIT_ERROR, FitOptions};
use facespace::model::FaceModel;
use facespace::{Progress, shape};
use indicatif::{ProgressBar, ProgressStyle};

/// The committed demo model, the default of every `--model`.
const DEMO_MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model");

/// The demo model as `--help` shows it: relative to the source tree ([`committed_path`]).
const DEMO_MODEL_SHOWN: &str = "models/demo/model";

/// A path argument that, relative and absent from the working folder, names the committed
/// file or folder of that name in the source tree (`models/demo/model`, `models/grid/model`)
/// — so defaults show as the README writes them and work from any folder.
fn committed_path(s: &str) -> Result<PathBuf, std::convert::Infallible> {
    let given = PathBuf::from(s);
    let committed = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(&given);
    Ok(
        if given.is_relative() && !given.exists() && committed.exists() {
            committed
        } else {
            given
        },
    )
}

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
#[allow(clippy::large_enum_variant)] // parsed once per run: boxing `synth`'s arguments buys nothing
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
    /// Export frames spread over a video (PNG), to mark landmarks on for a model of your own.
    #[command(after_help = "Example: facespace frames talker.mp4 --count 40 -o out/frames")]
    Frames(frames::FramesArgs),
    /// Forced alignment: a recording and its words → word and phone timings (.TextGrid, .lab).
    #[command(
        after_help = "Example: facespace align tests/data/grid/bbbf9a.wav --text \"bin blue by f nine again\" -o out/bbbf9a.TextGrid"
    )]
    Align(align::AlignArgs),
    /// Mark or correct the 68 landmarks of a folder of frames in a local web page.
    #[command(
        after_help = "Example: facespace annotate out/frames --fit   (then open the printed address)"
    )]
    Annotate(annotate::AnnotateArgs),
    /// Track faces through a video or frame folder by AAM search.
    #[command(after_help = "Example: facespace track models/demo/background.mp4 -o out/tracked")]
    Track(track::TrackArgs),
    /// Encode a video through face-space: track + project every frame → a clip folder.
    #[command(after_help = "Example: facespace encode models/demo/background.mp4 -o out/clip.fsp")]
    Encode(codec::EncodeArgs),
    /// Decode a clip folder: reconstruct and render every frame → a video.
    #[command(after_help = "Example: facespace decode out/clip.fsp -o out/decoded.mp4")]
    Decode(codec::DecodeArgs),
    /// PSNR / SSIM inside the face mask and bytes per frame of a clip against its input.
    #[command(
        after_help = "Example: facespace codec-report models/demo/background.mp4 out/clip.fsp -o out/report.json"
    )]
    CodecReport(codec::ReportArgs),
    /// Synthesise a face-space trajectory and video from phonemes or text (top-N blending, unit selection or the phoneme graph).
    #[command(
        after_help = "Example: facespace synth --model models/grid/model --codebook models/grid/codebook --audio tests/data/grid/bbbs7a.mp4 --transcript tests/data/grid/bbbs7a.txt --background tests/data/grid/bbbs7a.mp4 --top-n 5 -o out/bbbs7a"
    )]
    Synth(synth::SynthArgs),
    /// Train the unit-selection weights on validation sentences (Pareto front of lip sync,
    /// segment length and smoothness) → a weights file for `synth --weights`.
    #[command(
        after_help = "Example: facespace train-weights --codebook out/codebook --validation out/corpus/validation -o out/weights.json"
    )]
    TrainWeights(weights::TrainWeightsArgs),
    /// Score synthesis against held-out sentences (r_pca, r_h, RMSE, DTW) with baselines.
    #[command(
        after_help = "Example: facespace eval --codebook out/codebook --heldout out/corpus/heldout --validation out/corpus/validation"
    )]
    Eval(eval::EvalArgs),
    /// Subjective evaluation: A/B rating and Turing tests in the browser, with their statistics.
    #[command(subcommand)]
    Study(study::StudyCommand),
    /// The whole pipeline on committed data: GRID talker s1 (default) — a held-out recording
    /// aligned from its sound and synthesised from his codebook, with that sound, beside the
    /// real recording — or the FGNet talker over a generated corpus (--talker fgnet).
    Demo(demo::DemoArgs),
    /// A talker speaks: text (text-to-speech in its voice), a recording with its words, or
    /// phone labels → one MP4 with sound, the face over the talker's own living footage.
    Say(say::SayArgs),
    /// Make talker folders (`talker build`).
    #[command(subcommand)]
    Talker(talker::TalkerCommand),
    /// Speech → a mouth-shape track for 2D rigs in Rhubarb Lip Sync's shapes (A–F, G, H, X)
    /// and formats (TSV, JSON, Moho .dat).
    #[command(
        after_help = "Example: facespace visemes tests/data/grid/bbbf9a.wav --transcript tests/data/grid/bbbf9a.txt -f json -o out/bbbf9a.json"
    )]
    Visemes(visemes::VisemesArgs),
    /// The live page: the talker's face speaks typed sentences or the microphone's speech,
    /// rendered in the browser (WebGL2) from face-space as it arrives.
    Serve(serve::ServeArgs),
}

pub fn run() -> Result<()> {
    match Cli::parse().command {
        Command::Model(c) => model::run(c),
        Command::Codebook(c) => codebook::run(c),
        Command::Corpus(c) => corpus::run(c),
        Command::Frames(a) => frames::run(a),
        Command::Align(a) => align::run(a),
        Command::Annotate(a) => annotate::run(a),
        Command::Track(a) => track::run(a),
        Command::Encode(a) => codec::encode(a),
        Command::Decode(a) => codec::decode(a),
        Command::CodecReport(a) => codec::report(a),
        Command::Synth(a) => synth::run(a),
        Command::TrainWeights(a) => weights::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Study(c) => study::run(c),
        Command::Demo(a) => demo::run(a),
        Command::Say(a) => say::run(a),
        Command::Visemes(a) => visemes::run(a),
        Command::Talker(c) => talker::run(c),
        Command::Serve(a) => serve::run(a),
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal) and the callback that
/// drives it.
fn progress_bar() -> (ProgressBar, impl FnMut(Progress)) {
    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {prefix}{msg:<18} [{bar:30}] {pos}/{len} {elapsed}",
        )
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

/// `--renderer`: which renderer draws.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
enum RendererArg {
    /// A hardware GPU when there is one, else the CPU.
    #[default]
    Auto,
    /// The GPU on the best adapter found, software ones (llvmpipe, lavapipe) included.
    Gpu,
    /// The CPU.
    Cpu,
}

impl RendererArg {
    fn choice(self) -> facespace::render::RendererChoice {
        use facespace::render::RendererChoice;
        match self {
            RendererArg::Auto => RendererChoice::Auto,
            RendererArg::Gpu => RendererChoice::Gpu,
            RendererArg::Cpu => RendererChoice::Cpu,
        }
    }

    /// The renderer, saying on stderr why the CPU draws when the GPU was hoped for.
    fn make<'m>(
        self,
        model: &'m FaceModel,
        edge: impl Into<facespace::render::Edge>,
    ) -> Result<Box<dyn facespace::render::Renderer + 'm>> {
        let chosen = facespace::render::choose_renderer(self.choice(), model, edge)?;
        if let Some(note) = chosen.note.as_deref().filter(|n| first_time_told(n)) {
            eprintln!("note: {note} (said once on this machine)");
        }
        Ok(chosen.renderer)
    }
}

/// Whether `note` is told for the first time on this machine: a note about the machine (its
/// only GPU is a software one) is worth one reading, not one on every run. Remembered as an
/// empty file named by the note's hash in `$XDG_CACHE_HOME/facespace` (or `~/.cache`); where
/// nothing can be remembered, every time.
fn first_time_told(note: &str) -> bool {
    let Some(cache) = std::env::var_os("XDG_CACHE_HOME")
        .map(std::path::PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| std::path::Path::new(&h).join(".cache")))
    else {
        return true;
    };
    let hash = note
        .bytes()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3));
    let marker = cache.join("facespace").join(format!("told-{hash:016x}"));
    if marker.exists() {
        return false;
    }
    let _ = std::fs::create_dir_all(cache.join("facespace")).and_then(|()| std::fs::write(&marker, b""));
    true
}

/// Refuses `output` before any work when it is one of `inputs` (links resolved), a folder
/// holding one, or an existing device or FIFO (issue 39): a command never runs to then write
/// over its own input or `/dev/null`.
fn check_output(output: &std::path::Path, inputs: &[&std::path::Path]) -> Result<()> {
    Ok(facespace::atomic::check_destination(output, inputs)?)
}

/// Loads a model, naming it in the error.
fn load_model(path: &std::path::Path) -> Result<FaceModel> {
    use anyhow::Context;
    FaceModel::load(path).with_context(|| format!("loading model {}", path.display()))
}

/// How frames are tracked (shared by `track` and `encode`).
#[derive(Args)]
struct TrackingArgs {
    /// Landmarks of the first frame (.pts or menpo .ljson); without it the first frame is
    /// searched on a grid.
    #[arg(long)]
    init: Option<PathBuf>,
    /// Pyramid levels.
    #[arg(long, default_value_t = 2)]
    levels: usize,
    /// Residual RMS (grey levels) above which a frame is re-initialised.
    #[arg(long, default_value_t = DEFAULT_REINIT_ERROR)]
    reinit_error: f64,
    /// Alternating-refinement steps per frame after the project-out search (slower, more
    /// accurate when the appearance is far from the mean; 0 = off).
    #[arg(long, default_value_t = 0)]
    refine: usize,
    /// Keep the result when the first frame has no face the model explains or the face is
    /// lost on most frames (otherwise an error: usually a model of someone else).
    #[arg(long)]
    allow_lost: bool,
}

impl TrackingArgs {
    fn options(&self, bits: Option<u32>) -> Result<EncodeOptions> {
        let init = match &self.init {
            Some(p) => {
                let l = shape::read_landmarks(p)?;
                // A face has extent: points that coincide (or lie so far out that adding their
                // offsets changes nothing) are refused here, naming the file.
                let (lo, hi) = l.bounds();
                let extent = (hi[0] - lo[0]).min(hi[1] - lo[1]);
                if !(extent.is_finite() && extent >= 1.0 && lo[0].abs().max(hi[0].abs()) < 1e6) {
                    anyhow::bail!(
                        "{}: the landmarks span {extent} px from ({}, {}): not a face in an image",
                        p.display(),
                        lo[0],
                        lo[1]
                    );
                }
                Some(l)
            }
            None => None,
        };
        Ok(EncodeOptions {
            levels: self.levels,
            reinit_error: self.reinit_error,
            init,
            fit: FitOptions {
                refine_iterations: self.refine,
                ..FitOptions::default()
            },
            bits,
            allow_lost: self.allow_lost,
            early_verdict: None,
        })
    }
}

/// Context for a failed tracking command: `what` (e.g. "tracking") and the input's path,
/// unless the error names it already; when the face was lost, the `remedy` that command's
/// flags offer.
fn tracking_context<'a>(
    what: &'a str,
    input: &'a std::path::Path,
    remedy: &'a str,
) -> impl Fn(anyhow::Error) -> anyhow::Error + 'a {
    move |e| {
        let named = format!("{e:#}").contains(&input.display().to_string());
        let head = if named {
            what.to_owned()
        } else {
            format!("{what} {}", input.display())
        };
        let lost = e.chain().any(|c| {
            c.downcast_ref::<facespace::codec::CodecError>()
                .is_some_and(|c| c.is_lost_face())
        });
        if lost {
            e.context(format!("{head} ({remedy})"))
        } else {
            e.context(head)
        }
    }
}

/// The remedies [`TrackingArgs`] offer for a lost face.
const TRACKING_REMEDY: &str =
    "give the first frame's landmarks with --init, or pass --allow-lost to keep the result anyway";

/// One line on a tracking record.
fn tracking_line(s: &TrackingSummary, seconds: f64) -> String {
    format!(
        "{} frames in {seconds:.2} s ({:.0} fps incl. decoding): residual mean {:.2}, median {:.2}, max {:.2} grey levels; {} re-initialised, {} lost",
        s.frames,
        s.frames as f64 / seconds,
        s.mean_error,
        s.median_error,
        s.max_error,
        s.reinitialised,
        s.lost,
    )
}

/// A path as a user reads it: relative to the working folder when it lies below it.
fn shown(path: &std::path::Path) -> String {
    let here = std::env::current_dir().ok();
    here.and_then(|h| path.strip_prefix(h).ok().map(|p| p.display().to_string()))
        .unwrap_or_else(|| path.display().to_string())
}

/// A server's refusals on standard error, at most ten a second: a flood of bad requests
/// cannot grow the log without bound (the number left out is said with the next line).
#[derive(Default)]
struct Refusals {
    second: Option<std::time::Instant>,
    shown: u32,
    left_out: u64,
}

impl Refusals {
    fn log(&mut self, path: &str, why: &str) {
        let now = std::time::Instant::now();
        if self
            .second
            .is_none_or(|s| now.duration_since(s).as_secs() >= 1)
        {
            self.second = Some(now);
            self.shown = 0;
        }
        if self.shown >= 10 {
            self.left_out += 1;
            return;
        }
        self.shown += 1;
        let path: String = path.chars().take(200).collect();
        let why: String = why.chars().take(300).collect();
        if self.left_out > 0 {
            eprintln!("({} more refusals not shown)", self.left_out);
            self.left_out = 0;
        }
        eprintln!("refused {path:?}: {why}");
    }
}

/// The speech a command line asks for (`say` and `synth --talker` read it the same way):
/// phone labels (with a recording under them, or silent), a recording with its words (given,
/// or in a transcript file), a recording alone, or text; `None` when none is given.
pub fn speech_of(
    labels: Option<&std::path::Path>,
    tier: Option<&str>,
    phone_map: Option<&std::path::Path>,
    audio: Option<&std::path::Path>,
    text: Option<&str>,
    transcript: Option<&std::path::Path>,
) -> Result<Option<facespace::talker::Speech>> {
    use facespace::talker::Speech;
    Ok(Some(match (labels, audio, text, transcript) {
        (Some(labels), audio, ..) => Speech::Labels {
            labels: labels.into(),
            tier: tier.map(str::to_owned),
            map: match phone_map {
                Some(p) => facespace::phonemes::PhoneMap::read(p)?,
                None => facespace::phonemes::PhoneMap::default(),
            },
            audio: audio.map(Into::into),
        },
        (None, Some(audio), Some(words), _) => Speech::Recording {
            audio: audio.into(),
            words: words.to_owned(),
        },
        (None, Some(audio), None, Some(t)) => Speech::Recording {
            audio: audio.into(),
            words: facespace::safe_read::read_regular_string(t)
                .with_context(|| format!("reading the transcript {}", t.display()))?,
        },
        (None, Some(audio), None, None) => Speech::Sound(audio.into()),
        (None, None, Some(text), _) => Speech::Text(text.to_owned()),
        (None, None, None, _) => return Ok(None),
    }))
}
