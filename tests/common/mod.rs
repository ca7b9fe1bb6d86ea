//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use facespace::model::{BuildOptions, FaceModel, TrainingExample, load_training_set};

#[allow(unused_imports)]
pub use facespace::rng::Rng;

pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// The four real annotated faces shipped under `models/faces/training`.
pub fn faces_dir() -> PathBuf {
    root().join("models/faces/training")
}

pub fn faces() -> Vec<TrainingExample> {
    load_training_set(&faces_dir(), None).expect("bundled faces load")
}

/// A model of the bundled faces with a small reference frame (fast to build).
pub fn small_model() -> FaceModel {
    let options = BuildOptions {
        pixels: 6_000,
        ..BuildOptions::default()
    };
    FaceModel::build(&faces(), &options, &mut facespace::no_progress).expect("model builds")
}
