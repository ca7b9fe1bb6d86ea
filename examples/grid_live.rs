//! Live synthesis against offline (issue 35) on GRID s1's test split: each clip's sound in
//! 20 ms chunks at 48 kHz through a live session on the committed talker — phones recognised
//! as the sound comes, or the clip's aligned phones given ahead as a text-to-speech engine
//! gives its timings — against the offline synthesis of the same phones (recognised from the
//! whole clip, or aligned) with the same settings; both at the codebook's median pose, neither
//! anchored to footage, scored against the clip tracked with the talker's model: mouth r_pca
//! (eq. 16 of \[unitsel\]) and inner-mouth r_h. Also the wait of each frame: the sound's time
//! when the frame leaves the session minus the frame's own time (the sound's arrival; the
//! computing time is the benchmark's).
//!
//! `cargo run --release --example grid_live -- ../shared/data/grid-s1 [LIMIT|all] [SPLIT]`

#[path = "common/grid.rs"]
mod grid;
#[path = "common/track.rs"]
mod track;

use std::path::Path;

use facespace::align::frontend::SAMPLE_RATE;
use facespace::eval::mouth::{MouthPc, inner_mouth_height};
use facespace::eval::pearson;
use facespace::facespace::Frames;
use facespace::live::{LiveFrame, Session};
use facespace::phonemes::Segment;
use facespace::synth::{Request, Smoothing};
use facespace::talker::Talker;

const CHUNK_RATE: u32 = 48_000;
const CHUNK: usize = 960;

fn main() {
    let (grid, limit, split) = grid::args();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let talker = Talker::load(&root.join("models/grid")).unwrap();
    let ids = grid::split(&grid, &split, limit);
    let aligner = facespace::align::Aligner::load_default(&[]).unwrap();
    let lm = aligner.phone_loop(
        facespace::align::PHONE_WEIGHT,
        facespace::align::PHONE_PENALTY,
    );
    let settings = &talker.manifest.settings;
    let synthesiser = settings.synthesiser();
    let layout = talker.model.layout();
    let fps = talker.footage.fps;
    let offline = |target: &[Segment]| -> Frames {
        let req = Request::new(target.to_vec(), fps, Smoothing::On(settings.smoothing));
        let u = facespace::synth::synthesise(synthesiser.as_ref(), &talker.codebook, req).unwrap();
        u.variants()[0].1.clone()
    };
    let as_frames = |frames: &[LiveFrame]| -> Frames {
        assert!(frames.iter().enumerate().all(|(i, f)| f.index == i));
        Frames::from_rows(
            layout,
            fps,
            frames.iter().flat_map(|f| f.values.iter().copied()).collect(),
        )
        .unwrap()
    };
    let systems = [
        "offline, aligned words",
        "live, aligned words given ahead",
        "live, words given with their start times as the sound reaches them",
        "offline, phones recognised from the whole clip",
        "live, phones recognised as the sound comes",
        "offline synthesis of the phones recognised live",
        "live synthesis of the phones recognised from the whole clip, given ahead",
    ];
    let (mut reals, mut rows) = (Vec::new(), Vec::new());
    let mut waits: Vec<f64> = Vec::new();
    // Seconds each chunk's push and pull took, live from sound.
    let mut calls = Vec::new();
    let (mut spent, mut sound) = (0.0, 0.0);
    for id in &ids {
        let clip = grid.join(format!("clips/{id}.mp4"));
        let (_, real, _) = track::tracked(&talker.model, &clip);
        let audio = facespace::audio::read(&clip, CHUNK_RATE, 600.0).unwrap();
        let speech16 = facespace::audio::resample(&audio, SAMPLE_RATE);
        let aligned = aligner
            .align(&speech16.samples, SAMPLE_RATE, &grid::words(&grid, id))
            .unwrap()
            .segments();
        let recognised =
            facespace::align::segments(&aligner.recognise(&speech16.samples, SAMPLE_RATE, &lm).unwrap());
        // The frames, the seconds the session took, and each chunk's push and pull.
        let live = |given: Option<&[Segment]>, waits: &mut Vec<f64>| -> (Frames, f64, Vec<f64>) {
            let clock = std::time::Instant::now();
            let mut session = match given {
                Some(phones) => {
                    let mut s = Session::with_given_phones(&talker);
                    s.push_phones(phones).unwrap();
                    s
                }
                None => Session::new(&talker),
            };
            let (mut frames, mut calls) = (Vec::new(), Vec::new());
            for chunk in audio.samples.chunks(CHUNK) {
                let call = std::time::Instant::now();
                session.push_audio(chunk, CHUNK_RATE).unwrap();
                let pulled = session.pull().unwrap();
                let took = call.elapsed().as_secs_f64();
                for f in pulled {
                    // The sound's own wait, plus the time this chunk took to compute.
                    waits.push(session.seconds() - f.time + took);
                    frames.push(f);
                }
                calls.push(took);
            }
            frames.extend(session.finish().unwrap());
            (as_frames(&frames), clock.elapsed().as_secs_f64(), calls)
        };
        let (given, _, _) = live(Some(&aligned), &mut Vec::new());
        // The words with the corpus's start times, each given when the sound reaches it.
        let read = {
            let mut words = grid::timed_words(&grid, id).into_iter().peekable();
            let mut session = Session::with_given_words(&talker);
            let mut frames = Vec::new();
            for (k, chunk) in audio.samples.chunks(CHUNK).enumerate() {
                let now = ((k + 1) * CHUNK) as f64 / f64::from(CHUNK_RATE);
                while let Some(w) = words.next_if(|w| w.1 <= now) {
                    session.push_words(&[w]).unwrap();
                }
                session.push_audio(chunk, CHUNK_RATE).unwrap();
                frames.extend(session.pull().unwrap());
            }
            frames.extend(session.finish().unwrap());
            as_frames(&frames)
        };
        // Only the session from sound is timed.
        let (heard, took, heard_calls) = live(None, &mut waits);
        calls.extend(heard_calls);
        spent += took;
        sound += audio.seconds();
        let mut recogniser = aligner.recogniser(SAMPLE_RATE, &lm).unwrap();
        let mut phones = Vec::new();
        for chunk in speech16.samples.chunks(320) {
            phones.extend(recogniser.push(chunk).unwrap());
        }
        phones.extend(recogniser.finish().unwrap());
        let live_phones = facespace::align::segments(&facespace::align::merge_pieces(phones));
        let (given_recognised, _, _) = live(Some(&recognised), &mut Vec::new());
        rows.push([
            offline(&aligned),
            given,
            read,
            offline(&recognised),
            heard,
            offline(&live_phones),
            given_recognised,
        ]);
        reals.push(real);
        eprint!(".");
    }
    eprintln!();
    let real_refs: Vec<&Frames> = reals.iter().collect();
    let pc = MouthPc::fit(&talker.model, &real_refs).expect("a 68-point model");
    let height = |f: &Frames| -> Vec<f64> {
        facespace::eval::landmarks(&talker.model, f)
            .iter()
            .map(|p| inner_mouth_height(p))
            .collect()
    };
    println!(
        "GRID s1 {split} split (recorded), {} sentences, the talker's settings (blend N={}, C={}, λ={:e}):\n",
        ids.len(),
        settings.top_n,
        settings.context,
        settings.smoothing
    );
    // Mean change of the inner-mouth height from frame to frame: jumps between batches show.
    let change = facespace::eval::mean_step;
    println!("| system | r_pca eq. 16 | r_h inner | frame-to-frame change of r_h's height × real |");
    println!("|---|---|---|---|");
    for (k, name) in systems.iter().enumerate() {
        let (mut r_pca, mut r_h, mut moved, mut real_moved) = (0.0, 0.0, 0.0, 0.0);
        for (row, real) in rows.iter().zip(&reals) {
            let n = row[k].len().min(real.len());
            let (a, b) = (row[k].slice(0..n), real.slice(0..n));
            let (ha, hb) = (height(&a), height(&b));
            r_pca += pearson(&pc.series(&a), &pc.series(&b));
            r_h += pearson(&ha, &hb);
            moved += change(&ha);
            real_moved += change(&hb);
        }
        let m = rows.len() as f64;
        println!("| {name} | {:.3} | {:.3} | {:.2} |", r_pca / m, r_h / m, moved / real_moved);
    }
    let quantiles = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let q = |f: f64| 1000.0 * v[((v.len() - 1) as f64 * f) as usize];
        format!("{:.0} / {:.0} / {:.0} ms", q(0.5), q(0.95), q(1.0))
    };
    println!(
        "\nlive from sound, 20 ms chunks: sound in to frame out (the sound's wait plus the chunk's computing) median / 95 % / most {}; each chunk's push and pull {}; the session computes at {:.0}× real time (one thread)",
        quantiles(&mut waits),
        quantiles(&mut calls),
        sound / spent
    );
}
