//! `facespace demo`: the README's first command. Until the demo corpus lands (issue 3) it
//! builds a model from the four bundled annotated faces and shows what the model does.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use facespace::model::{BuildOptions, FaceModel, FaceParams, load_training_set};
use facespace::shape::Similarity;
use image::RgbImage;

use super::model::{print_summary, reconstruct_pair, save_png};

#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(short, long, default_value = "out/demo")]
    output: PathBuf,
    /// Training images with .pts landmarks.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/models/faces/training"))]
    training: PathBuf,
}

pub fn run(a: DemoArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let examples = load_training_set(&a.training, None)
        .with_context(|| format!("loading {}", a.training.display()))?;
    let (bar, mut progress) = super::progress_bar();
    let model = FaceModel::build(&examples, &BuildOptions::default(), &mut progress)?;
    bar.finish_and_clear();
    let model_dir = a.output.join("model");
    model.save(&model_dir)?;
    println!(
        "model of {} faces → {}",
        examples.len(),
        model_dir.display()
    );
    print_summary(&model);
    // Each face reconstructed by a model of the other faces: what the model generalises to.
    println!("leave-one-out reconstructions (model of the other faces):");
    for (i, e) in examples.iter().enumerate() {
        let others: Vec<_> = examples
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, x)| x.clone())
            .collect();
        let held_out = FaceModel::build(
            &others,
            &BuildOptions::default(),
            &mut facespace::no_progress,
        )?;
        let (pair, psnr) = reconstruct_pair(&held_out, &e.image, &e.landmarks)?;
        let stem = std::path::Path::new(&e.name)
            .file_stem()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let path = a.output.join(format!("reconstruct-{stem}.png"));
        save_png(&pair, &path)?;
        println!("  {:<40} texture PSNR {psnr:5.1} dB", path.display());
    }
    // The first appearance mode at −2σ, mean, +2σ, drawn at the mean shape.
    let sd = model.appearance.pca.variances[0].sqrt();
    let pose = Similarity {
        a: model.placement.scale,
        b: 0.0,
        tx: model.placement.offset[0],
        ty: model.placement.offset[1],
    };
    let (w, h) = (model.frame.width as u32, model.frame.height as u32);
    let mut strip = RgbImage::new(3 * w, h);
    for (i, k) in [-2.0f32, 0.0, 2.0].iter().enumerate() {
        let mut appearance = vec![0.0; model.appearance.n_params()];
        appearance[0] = k * sd;
        let params = FaceParams {
            pose,
            shape: vec![0.0; model.shape.n_params()],
            appearance,
        };
        let mut tile = RgbImage::new(w, h);
        model.render_into(&params, &mut tile)?;
        image::imageops::replace(&mut strip, &tile, (i as u32 * w) as i64, 0);
    }
    let path = a.output.join("appearance-mode1.png");
    save_png(&strip, &path)?;
    println!(
        "  {:<40} first appearance mode at −2σ, mean, +2σ",
        path.display()
    );
    println!("done in {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}
