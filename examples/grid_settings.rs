//! Every trial of a talker's settings choice (`synth::systems::choose_settings`, what
//! `talker build --validation` runs) on a validation corpus, as a table (BENCHMARKS "Say").
//!
//! `cargo run --release --example grid_settings -- TALKER VALIDATION_CORPUS`

use std::path::PathBuf;

use facespace::synth::systems::{SETTINGS_LAMBDA_GRID, TOP_N_GRID, choose_settings};
use facespace::talker::Talker;
use facespace::talker::build::Validation;

fn main() {
    let mut args = std::env::args().skip(1);
    let talker = Talker::load(&PathBuf::from(args.next().expect("a talker folder"))).unwrap();
    let dir = PathBuf::from(args.next().expect("a validation corpus"));
    let v = Validation::load(&dir, &talker.model, talker.codebook.fps).unwrap();
    let choice = choose_settings(
        &talker.model,
        &talker.codebook,
        &v.sentences,
        &TOP_N_GRID,
        &SETTINGS_LAMBDA_GRID,
    )
    .unwrap()
    .expect("a 68-point face");
    println!("| N | λ | r_pca eq. 16 | r_h inner | inner s.d. × real | lip motion × real |");
    println!("|---|---|---|---|---|---|");
    for t in &choice.trials {
        let m = &t.mouth;
        let mark = if t == &choice.chosen {
            " **chosen**"
        } else {
            ""
        };
        println!(
            "| {} | {:e} | {:.3} | {:.3} | {:.3} | {:.3}{mark} |",
            t.top_n, t.smoothing, m.r_pca_mouth, m.r_h_inner, m.inner_sd_ratio, m.lip_motion_ratio
        );
    }
    println!("\n{}", choice.describe("validation"));
}
