//! `facespace model build | info | reconstruct | suggest`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use facespace::mesh::{Region, Triangle};
use facespace::model::{BuildOptions, FaceModel, load_marked};
use facespace::pca::Components;
use facespace::shape::read_pts;
use facespace::video;

use super::{load_model, progress_bar};

#[derive(Subcommand)]
pub enum ModelCommand {
    /// Build a model from images with iBUG .pts landmarks of the same file stem.
    #[command(
        after_help = "Example: facespace model build --images models/demo/training --pixels 20000 -o out/model"
    )]
    Build(BuildArgs),
    /// Print a model's counts, variance explained and sizes.
    #[command(after_help = "Example: facespace model info models/grid/model")]
    Info {
        /// Model folder.
        model: PathBuf,
    },
    /// Project an image to face-space, reconstruct it, and write original | reconstruction.
    #[command(
        after_help = "Example: facespace model reconstruct out/model --image tests/data/demo-heldout/f00804.jpg -o out/f00804.png"
    )]
    Reconstruct(ReconstructArgs),
    /// The frames of a video the model explains worst (fit residual, appearance outside the
    /// training span), spread over time, with the fitted landmarks as starting .pts: mark
    /// them, add them to the training set, rebuild.
    #[command(
        after_help = "Example: facespace model suggest --model out/model talker.mp4 -n 10 -o out/suggested"
    )]
    Suggest(SuggestArgs),
}

#[derive(Args)]
pub struct SuggestArgs {
    /// The current model.
    #[arg(long, default_value = super::DEMO_MODEL_SHOWN, value_parser = super::committed_path)]
    model: PathBuf,
    /// The talker's video (or frame folder).
    input: PathBuf,
    /// How many frames.
    #[arg(short = 'n', long, default_value_t = 10)]
    count: usize,
    #[command(flatten)]
    tracking: super::TrackingArgs,
    /// Output folder of NNNNNN.png + NNNNNN.pts.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct BuildArgs {
    /// Folder of training images (png, jpg, ppm).
    #[arg(long)]
    images: PathBuf,
    /// Folder of .pts files (default: the images folder).
    #[arg(long)]
    landmarks: Option<PathBuf>,
    /// Approximate pixel count of the reference frame (default: the faces' own size in the
    /// training images — the median area their landmarks cover — so the model draws the face
    /// at the resolution it was recorded at; GRID s1 and FGNet: about 20 000).
    #[arg(long)]
    pixels: Option<usize>,
    /// Fraction of shape variance to keep.
    #[arg(long, default_value_t = 0.95)]
    shape_var: f64,
    /// Fraction of appearance variance to keep.
    #[arg(long, default_value_t = 0.98)]
    appearance_var: f64,
    /// At most this many appearance parameters.
    #[arg(long, default_value_t = 80)]
    appearance_max: usize,
    /// JSON file with a fixed triangle list `[[i, j, k], …]` instead of Delaunay.
    #[arg(long)]
    triangles: Option<PathBuf>,
    /// Reference-frame pixels next to the mesh boundary left out of the appearance model
    /// (background that outlines let in; rendering fills the rim from the background).
    #[arg(long, default_value_t = facespace::model::DEFAULT_MARGIN)]
    margin: f64,
    /// Leave out images that have no landmarks yet (frames not marked on the annotate page)
    /// instead of stopping at the first.
    #[arg(long)]
    skip_unmarked: bool,
    /// Model only a face region's appearance: `lower-face` (iBUG-68 jaw, nose base, lips) or
    /// a JSON file listing landmark indices `[i, j, …]`.
    #[arg(long)]
    region: Option<String>,
    /// Output model folder.
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Args)]
pub struct ReconstructArgs {
    /// Model folder.
    model: PathBuf,
    /// The image to reconstruct.
    #[arg(long)]
    image: PathBuf,
    /// Its landmarks (default: the .pts beside the image).
    #[arg(long)]
    landmarks: Option<PathBuf>,
    /// Output PNG: original and reconstruction side by side, cropped to the face.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(command: ModelCommand) -> Result<()> {
    match command {
        ModelCommand::Build(a) => build(a),
        ModelCommand::Info { model } => info(&model),
        ModelCommand::Reconstruct(a) => reconstruct(a),
        ModelCommand::Suggest(a) => suggest(a),
    }
}

fn suggest(a: SuggestArgs) -> Result<()> {
    super::check_output(&a.output, &[&a.model, &a.input])?;
    let model = load_model(&a.model)?;
    let options = a.tracking.options(None)?;
    let (bar, progress) = progress_bar();
    let chosen =
        facespace::suggest::suggest(&model, &a.input, a.count, &a.output, &options, progress)
            .map_err(|e| {
                super::tracking_context("suggesting frames of", &a.input, super::TRACKING_REMEDY)(
                    e.into(),
                )
            })?;
    bar.finish_and_clear();
    for s in &chosen {
        println!(
            "  frame {:6}: residual {:.2} grey levels, largest parameter {:.1} σ",
            s.index, s.residual, s.largest_sd
        );
    }
    println!(
        "{} frames with their fitted landmarks → {} (correct the .pts, add them to the training images, rebuild)",
        chosen.len(),
        a.output.display()
    );
    Ok(())
}

fn build(a: BuildArgs) -> Result<()> {
    let mut inputs = vec![a.images.as_path()];
    inputs.extend(a.landmarks.as_deref());
    inputs.extend(a.triangles.as_deref());
    inputs.extend(a.region.as_deref().map(std::path::Path::new));
    super::check_output(&a.output, &inputs)?;
    let triangles = match &a.triangles {
        Some(path) => {
            let text = facespace::safe_read::read_regular_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            Some(
                serde_json::from_str::<Vec<Triangle>>(&text)
                    .with_context(|| format!("{}: expected [[i, j, k], …]", path.display()))?,
            )
        }
        None => None,
    };
    let region = match a.region.as_deref() {
        None => None,
        Some("lower-face") => Some(Region::LowerFace),
        Some(path) => {
            let text = facespace::safe_read::read_regular_string(std::path::Path::new(path))
                .with_context(|| format!("reading region file {path}"))?;
            Some(Region::Landmarks(
                serde_json::from_str(&text).with_context(|| {
                    format!("{path}: expected `lower-face` or a JSON list of landmark indices")
                })?,
            ))
        }
    };
    let mut options = BuildOptions {
        pixels: a.pixels.unwrap_or(0),
        shape: Components::Variance {
            fraction: a.shape_var,
            max: None,
        },
        appearance: Components::Variance {
            fraction: a.appearance_var,
            max: Some(a.appearance_max),
        },
        triangles,
        region,
        margin: a.margin,
    };
    let (examples, unmarked) = load_marked(&a.images, a.landmarks.as_deref(), a.skip_unmarked)
        .map_err(|e| {
            let hint = match e {
                facespace::model::ModelError::MissingLandmarks { .. } => {
                    " (--skip-unmarked leaves images without landmarks out)"
                }
                _ => "",
            };
            anyhow::Error::from(e).context(format!(
                "loading training images from {}{hint}",
                a.images.display()
            ))
        })?;
    if !unmarked.is_empty() {
        eprintln!(
            "left out {} image(s) without landmarks (--skip-unmarked), e.g. {}",
            unmarked.len(),
            unmarked[0].display()
        );
    }
    if a.pixels.is_none() {
        options.pixels = facespace::model::face_pixels(&examples);
        println!(
            "reference frame of about {} pixels: the faces' own size in these images (--pixels overrides)",
            options.pixels
        );
    }
    let (bar, mut progress) = progress_bar();
    let model =
        FaceModel::build(&examples, &options, &mut progress).context("building the model")?;
    bar.finish_and_clear();
    model
        .save(&a.output)
        .with_context(|| format!("saving the model to {}", a.output.display()))?;
    println!(
        "built {} from {} images",
        a.output.display(),
        examples.len()
    );
    print_summary(&model);
    Ok(())
}

fn print_summary(model: &FaceModel) {
    let f = &model.frame;
    println!("  landmarks        {}", model.shape.n_landmarks());
    println!("  triangles        {}", f.triangles.len());
    println!(
        "  reference frame  {}×{} px, {} pixels inside the mesh",
        f.width,
        f.height,
        f.n_pixels()
    );
    for (name, pca) in [
        ("shape", &model.shape.pca),
        ("appearance", &model.appearance.pca),
    ] {
        let total = pca.total_variance;
        let ratios: Vec<String> = pca
            .variances
            .iter()
            .take(5)
            .map(|v| format!("{:.1}%", 100.0 * *v as f64 / total))
            .collect();
        println!(
            "  {name:<16} {} parameters, {:.1}% of variance (first: {}{})",
            pca.n_components(),
            100.0 * pca.variance_ratio(),
            ratios.join(", "),
            if pca.n_components() > 5 { ", …" } else { "" }
        );
    }
    println!(
        "  face-space       {} values per frame {}",
        model.layout().dims(),
        model.layout()
    );
}

fn info(dir: &Path) -> Result<()> {
    let model = load_model(dir)?;
    println!("model {}", dir.display());
    print_summary(&model);
    println!("  training images  {}", model.source.len());
    match (&model.region, &model.tracker) {
        (Some(_), Some(t)) => println!(
            "  tracker          the whole face it was cut from ({} shape, {} appearance parameters, tracker/)",
            t.shape.n_params(),
            t.appearance.n_params()
        ),
        (Some(_), None) => println!(
            "  tracker          none: built before region models carried one; rebuild it, or give synth --track-model"
        ),
        _ => {}
    }
    let mut total = 0;
    let mut files: Vec<_> = std::fs::read_dir(dir)?.filter_map(|e| e.ok()).collect();
    files.sort_by_key(|e| e.file_name());
    for e in files {
        let len = e.metadata()?.len();
        total += len;
        println!(
            "    {:<28} {:>10}",
            e.file_name().to_string_lossy(),
            human_bytes(len)
        );
    }
    println!("  on disk          {}", human_bytes(total));
    Ok(())
}

fn human_bytes(n: u64) -> String {
    match n {
        n if n >= 1 << 20 => format!("{:.1} MiB", n as f64 / (1u64 << 20) as f64),
        n if n >= 1 << 10 => format!("{:.1} KiB", n as f64 / 1024.0),
        n => format!("{n} B"),
    }
}

fn reconstruct(a: ReconstructArgs) -> Result<()> {
    let mut inputs = vec![a.model.as_path(), a.image.as_path()];
    inputs.extend(a.landmarks.as_deref());
    super::check_output(&a.output, &inputs)?;
    let model = load_model(&a.model)?;
    let image = video::read_frame(&a.image)?;
    let pts = a
        .landmarks
        .clone()
        .unwrap_or_else(|| a.image.with_extension("pts"));
    let landmarks =
        read_pts(&pts).with_context(|| format!("reading landmarks for {}", a.image.display()))?;
    let (pair, psnr) = model
        .reconstruction_pair(&image, &landmarks)
        .with_context(|| {
            format!(
                "reconstructing {} with {}",
                a.image.display(),
                pts.display()
            )
        })?;
    video::write_png(&a.output, &pair)?;
    println!(
        "wrote {} (original | reconstruction); texture PSNR {psnr:.1} dB",
        a.output.display()
    );
    Ok(())
}
