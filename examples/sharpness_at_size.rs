//! Mouth sharpness at full size (issue 33): each clip tracked with a model, its frames drawn
//! again from the model's fit (lips and jaw over the recorded frame, as `say` draws them),
//! and the mouth's sharpness (`eval::mouth::mouth_sharpness`) over the recorded frames' —
//! the codec's round trip, so only the model's resolution and its appearance space differ.
//!
//! `cargo run --release --example sharpness_at_size -- MODEL CLIP [MODEL CLIP …]` (CLIP: a
//! video or a folder of frames).

#[path = "common/track.rs"]
mod track;

use std::path::PathBuf;

use facespace::eval::mouth::mouth_sharpness;
use facespace::model::FaceModel;
use facespace::render::{Background, CpuRenderer, DEFAULT_FEATHER, Edge, Renderer};

fn main() {
    let args: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    println!(
        "| model | reference pixels | clip | frame size | mouth sharpness, drawn / recorded |"
    );
    println!("|---|---|---|---|---|");
    for pair in args.chunks(2) {
        let model = FaceModel::load(&pair[0]).unwrap();
        let (images, frames, marks) = track::tracked(&model, &pair[1]);
        let renderer = CpuRenderer::with_edge(&model, Edge::Articulators(DEFAULT_FEATHER));
        let size = images[0].dimensions();
        let drawn = facespace::render::images(
            &renderer as &dyn Renderer,
            &frames,
            Background::Loop {
                frames: images.clone(),
                next: 0,
            },
        )
        .unwrap();
        let drawn_marks = facespace::eval::landmarks(&model, &frames);
        let ratio = mouth_sharpness(&drawn, &drawn_marks) / mouth_sharpness(&images, &marks);
        println!(
            "| {} | {} | {} | {}×{} | {ratio:.2} |",
            pair[0].display(),
            model.frame.n_pixels(),
            pair[1].display(),
            size.0,
            size.1
        );
    }
}
