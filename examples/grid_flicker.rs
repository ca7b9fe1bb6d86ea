//! Flicker on GRID speaker 1 (recorded speech): the within-sentence s.d. of each appearance
//! parameter of blend synthesis (C=1, N=3, default λ) of every test sentence, from its own
//! phone labels, against the real sentence's — with the codebook as tracked and with each
//! sentence's appearance re-centred on the corpus mean (`codebook build --photometric sentence`).
//!
//! `cargo run --release --example grid_flicker -- MODEL TRAIN_CORPUS TEST_CORPUS`
//! (corpora from `corpus from-videos` over `../shared/data/grid-s1`'s splits).

use std::path::PathBuf;

use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::corpus::{self, Photometric};
use facespace::eval::mouth::flicker;
use facespace::model::FaceModel;
use facespace::phonemes::PhoneMap;
use facespace::synth::{self, DEFAULT_SMOOTHING, Request, Smoothing, blend::Blend};

fn main() {
    let a: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let model = FaceModel::load(&a[0]).unwrap();
    let range = model.layout().appearance_range();
    let test = corpus::load(&a[2], 25.0, model.layout(), None, &PhoneMap::default()).unwrap();
    for photometric in [Photometric::None, Photometric::Sentence] {
        let cb = Codebook::from_corpus(
            &a[1],
            &model,
            25.0,
            None,
            &PhoneMap::default(),
            SimilarityOptions::default(),
            photometric,
            corpus::DEFAULT_TOLERANCE,
            &mut facespace::no_progress,
        )
        .unwrap();
        let mut ratio_sum = vec![0f64; range.len()];
        for s in &test {
            let u = synth::synthesise(
                &Blend::default(),
                &cb,
                Request::new(s.segments.clone(), 25.0, Smoothing::On(DEFAULT_SMOOTHING)),
            )
            .unwrap();
            let n = u.synthesis.frames.len().min(s.frames.len());
            let ratios = flicker(&u.synthesis.frames.slice(0..n), &s.frames.slice(0..n));
            ratio_sum.iter_mut().zip(&ratios).for_each(|(t, r)| *t += r);
        }
        let ratios: Vec<f64> = ratio_sum.iter().map(|x| x / test.len() as f64).collect();
        let worst = ratios.iter().cloned().fold(0f64, f64::max);
        let over = ratios.iter().filter(|&&x| x > 1.5).count();
        println!(
            "{photometric:?}: synthesised / real within-sentence s.d., mean over {} test sentences: b_a1 {:.2}, b_a2 {:.2}, b_a3 {:.2}; worst parameter {:.2}; {} of {} parameters above 1.5×",
            test.len(),
            ratios[0],
            ratios[1],
            ratios[2],
            worst,
            over,
            ratios.len()
        );
    }
}
