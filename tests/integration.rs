//! The integration tests as one crate, so the library is linked once (issue 37): each file of
//! `tests/` is a module here, named as the file. Run one with its path, e.g.
//! `cargo test --release --test integration kill::`. The fuzz suite stays a binary of its
//! own (`--test fuzz`): it bounds the whole process's peak memory, which other tests would
//! share here.

/// One test thread more than the cores, unless `RUST_TEST_THREADS` or `--test-threads` says
/// otherwise: a fifth of this crate's time is spent waiting on real time (clips playing in
/// Chromium, live sessions paced at the sound's speed, killed runs waiting for their
/// moment), and the extra thread keeps the cores busy through it (2 cores: 137 s → 120 s,
/// BENCHMARKS.md). libtest reads the variable in `main`; this runs before it, on the only
/// thread.
#[cfg(target_os = "linux")]
#[used]
#[unsafe(link_section = ".init_array")]
static ONE_THREAD_MORE: extern "C" fn() = {
    extern "C" fn one_thread_more() {
        if std::env::var_os("RUST_TEST_THREADS").is_none() {
            let cores = std::thread::available_parallelism().map_or(1, usize::from);
            // SAFETY: before `main`, no other thread exists to read the environment.
            unsafe { std::env::set_var("RUST_TEST_THREADS", (cores + 1).to_string()) };
        }
    }
    one_thread_more
};

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
mod layers;
mod live;
mod live_page;
mod model;
mod mouths;
mod pca;
mod phonemes;
mod python;
mod readme;
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
