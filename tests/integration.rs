//! The integration tests as one crate, so the library is linked once (issue 37): each file of
//! `tests/` is a module here, named as the file. Run one with its path, e.g.
//! `cargo test --release --test integration kill::`. The fuzz suite stays a binary of its
//! own (`--test fuzz`): it bounds the whole process's peak memory, which other tests would
//! share here.

mod common;

mod align;
mod annotate;
mod blend;
mod cli;
mod codebook;
mod codec;
mod committed_models;
mod compositing;
mod concurrency;
mod corpus;
mod fallback;
mod fit;
mod gpu;
mod grid_demo;
mod hostile;
mod kill;
mod live;
mod live_page;
mod model;
mod mouths;
mod pca;
mod phonemes;
mod python;
mod region;
mod shape;
mod smooth;
mod speech;
mod study;
mod synthesis;
mod talker;
mod track;
mod trajectory;
mod unit_selection;
mod video;
mod visemes;
mod walkthrough;
mod warp;
