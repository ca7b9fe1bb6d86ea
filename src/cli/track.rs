//! `facespace track`: AAM search on every frame, each frame started from the last.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::codec::{self, EncodeOptions};
use facespace::fit::FitOptions;
use facespace::model::FaceModel;
use facespace::shape::{self, Landmarks};
use facespace::{npy, video};

#[derive(Args)]
pub struct TrackArgs {
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/demo/model"))]
    model: PathBuf,
    /// A folder of frames (png, jpg), an MP4 or Y4M, or any video a system ffmpeg reads.
    input: PathBuf,
    #[command(flatten)]
    tracking: TrackingArgs,
    /// Output: a folder of .pts files (one per frame), or a .npy (frames × landmarks × 2).
    #[arg(short, long)]
    output: PathBuf,
}

/// How frames are tracked (shared by `track` and `encode`).
#[derive(Args)]
pub struct TrackingArgs {
    /// Landmarks of the first frame; without it the first frame is searched on a grid.
    #[arg(long)]
    init: Option<PathBuf>,
    /// Pyramid levels.
    #[arg(long, default_value_t = 2)]
    levels: usize,
    /// Residual RMS (grey levels) above which a frame is re-initialised.
    #[arg(long, default_value_t = DEFAULT_REINIT)]
    reinit_error: f64,
    /// Alternating-refinement steps per frame after the project-out search (slower, more
    /// accurate when the appearance is far from the mean; 0 = off).
    #[arg(long, default_value_t = 0)]
    refine: usize,
}

/// Default re-initialisation threshold (grey levels): well above the residuals of good fits
/// on the demo clip (see BENCHMARKS.md).
pub const DEFAULT_REINIT: f64 = 25.0;

impl TrackingArgs {
    pub fn options(&self, model: &FaceModel) -> Result<EncodeOptions> {
        let init = match &self.init {
            Some(p) => {
                let l = shape::read_pts(p)?;
                l.validate(Some(model.shape.n_landmarks()), &p.display().to_string())?;
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
        })
    }
}

/// One line on the tracking record.
pub fn summary(tracking: &[codec::FrameTrack], seconds: f64) -> String {
    let n = tracking.len().max(1) as f64;
    let mean = tracking.iter().map(|t| t.fit_error).sum::<f64>() / n;
    let max = tracking.iter().map(|t| t.fit_error).fold(0.0, f64::max);
    let reinits = tracking.iter().filter(|t| t.reinitialised).count();
    format!(
        "{} frames in {seconds:.2} s ({:.0} fps incl. decoding): residual mean {mean:.2}, max {max:.2} grey levels; {reinits} re-initialised",
        tracking.len(),
        tracking.len() as f64 / seconds,
    )
}

pub fn run(a: TrackArgs) -> Result<()> {
    let model = FaceModel::load(&a.model)
        .with_context(|| format!("loading model {}", a.model.display()))?;
    let options = a.tracking.options(&model)?;
    let source = video::Source::open(&a.input)?;
    let names: Option<Vec<String>> = a.input.is_dir().then(|| {
        video::frame_files(&a.input)
            .unwrap_or_default()
            .iter()
            .map(|f| {
                f.file_stem()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect()
    });
    let (bar, progress) = super::progress_bar();
    let clock = std::time::Instant::now();
    let mut landmarks: Vec<Landmarks> = Vec::new();
    let tracking = codec::track(&model, source, &options, progress, |_, t| {
        landmarks.push(t.landmarks.clone());
        Ok(())
    })
    .with_context(|| format!("tracking {}", a.input.display()))?;
    bar.finish_and_clear();
    let seconds = clock.elapsed().as_secs_f64();
    if a.output.extension().is_some_and(|e| e == "npy") {
        let l = model.shape.n_landmarks();
        let flat: Vec<f32> = landmarks.iter().flat_map(|lm| lm.to_flat()).collect();
        npy::write(&a.output, &[landmarks.len(), l, 2], &flat)?;
    } else {
        for (i, lm) in landmarks.iter().enumerate() {
            let name = names
                .as_ref()
                .and_then(|n| n.get(i).cloned())
                .unwrap_or_else(|| format!("{i:06}"));
            shape::write_pts(&a.output.join(format!("{name}.pts")), lm)?;
        }
    }
    println!(
        "tracked {} → {}",
        summary(&tracking, seconds),
        a.output.display()
    );
    Ok(())
}
