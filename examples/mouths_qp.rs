//! The recorded mouths' detail as decoded, for choosing the video's quantiser (issue 38;
//! BENCHMARKS.md "Recorded mouths"): writes the detail of a mouths folder's first 300 frames
//! (frames × region pixels, grey levels) to an `.npy`, to compare folders kept at different
//! `mouths::QP` against the least one.
//!
//! `cargo run --release --example mouths_qp -- TALKER/mouths OUT.npy`

use std::path::Path;

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = facespace::model::FaceModel::load(&root.join("models/grid/model")).unwrap();
    let m = facespace::mouths::Mouths::load(Path::new(&a[0]), &model).unwrap();
    let (n, k) = (m.pixels.len(), 300.min(m.len()));
    let detail: Vec<f32> = (0..k).flat_map(|i| m.detail(i).unwrap().iter().map(|&d| f32::from(d))).collect();
    let detail = ndarray::Array2::from_shape_vec((k, n), detail).unwrap();
    facespace::npy::write(Path::new(&a[1]), detail.view()).unwrap();
}
