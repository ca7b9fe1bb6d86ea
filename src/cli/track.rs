//! `facespace track`: AAM search on every frame, each frame started from the last.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use facespace::fit::{FitOptions, Fitter, Tracker};
use facespace::model::FaceModel;
use facespace::shape::{self, Landmarks};
use facespace::{npy, video};

#[derive(Args)]
pub struct TrackArgs {
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model"))]
    model: PathBuf,
    /// A folder of frames (png, jpg), or a video file (decoded with a system ffmpeg).
    input: PathBuf,
    /// Landmarks of the first frame; without it the first frame is searched on a grid.
    #[arg(long)]
    init: Option<PathBuf>,
    /// Pyramid levels.
    #[arg(long, default_value_t = 2)]
    levels: usize,
    /// Residual RMS (grey levels) above which a frame is re-initialised.
    #[arg(long, default_value_t = DEFAULT_REINIT)]
    reinit_error: f64,
    /// Output: a folder of .pts files (one per frame), or a .npy (frames × landmarks × 2).
    #[arg(short, long)]
    output: PathBuf,
}

/// Default re-initialisation threshold (grey levels): well above the residuals of good fits
/// on the demo clip (see BENCHMARKS.md).
pub const DEFAULT_REINIT: f64 = 25.0;

pub fn run(a: TrackArgs) -> Result<()> {
    let model = FaceModel::load(&a.model)
        .with_context(|| format!("loading model {}", a.model.display()))?;
    let tmp = tempfile::tempdir()?;
    let files = if a.input.is_dir() {
        video::frame_files(&a.input)?
    } else if a.input.is_file() {
        video::decode_with_ffmpeg(&a.input, tmp.path())?
    } else {
        bail!("{}: no such file or folder", a.input.display());
    };
    let fitter = Fitter::new(&model, FitOptions::default(), a.levels)?;
    let first = video::read_frame(&files[0])?;
    let start = match &a.init {
        Some(p) => {
            let l = shape::read_pts(p)?;
            l.validate(Some(model.shape.n_landmarks()), &p.display().to_string())?;
            l
        }
        None => fitter
            .search_start(&first)
            .context("searching the first frame")?,
    };
    let mut tracker = Tracker::new(fitter, start, a.reinit_error)?;
    let (bar, mut progress) = super::progress_bar();
    let clock = std::time::Instant::now();
    let mut frames: Vec<(String, Landmarks)> = Vec::with_capacity(files.len());
    let (mut errors, mut reinits) = (Vec::new(), 0);
    for (i, f) in files.iter().enumerate() {
        let image = if i == 0 {
            first.clone()
        } else {
            video::read_frame(f)?
        };
        let t = tracker
            .track(&image)
            .with_context(|| format!("fitting {}", f.display()))?;
        errors.push(t.error);
        reinits += t.reinitialised as usize;
        frames.push((
            f.file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned(),
            t.landmarks,
        ));
        progress(facespace::Progress {
            stage: "tracking",
            done: i + 1,
            total: files.len(),
        });
    }
    bar.finish_and_clear();
    let seconds = clock.elapsed().as_secs_f64();
    if a.output.extension().is_some_and(|e| e == "npy") {
        let l = model.shape.n_landmarks();
        let flat: Vec<f32> = frames.iter().flat_map(|(_, lm)| lm.to_flat()).collect();
        npy::write(&a.output, &[frames.len(), l, 2], &flat)?;
    } else {
        for (name, lm) in &frames {
            shape::write_pts(&a.output.join(format!("{name}.pts")), lm)?;
        }
    }
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let max = errors.iter().cloned().fold(0.0, f64::max);
    println!(
        "tracked {} frames in {seconds:.2} s ({:.0} fps incl. decoding): residual mean {mean:.2}, max {max:.2} grey levels; {reinits} re-initialised → {}",
        frames.len(),
        frames.len() as f64 / seconds,
        a.output.display()
    );
    Ok(())
}
