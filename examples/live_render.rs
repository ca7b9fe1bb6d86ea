//! Live frames rendered on the server's CPU, on one core (issue 35's "≥ 25 fps including
//! rendering"): GRID s1 test clips' sound in 40 ms chunks through a live session (phones
//! recognised as the sound comes, or the clip's aligned phones given ahead), each frame placed
//! on the talker's living frame (`live::Stage`) and drawn by the CPU renderer over its footage
//! frame, decoded in order — at the footage's 360×288 and at 720×576 (the footage frame scaled
//! up, the face drawn at twice the pose). Prints frames per second of the whole loop and the
//! share of each part; with the talker's recorded mouths (issue 38) as well.
//!
//! `cargo run --release --example live_render -- ../shared/data/grid-s1 [LIMIT] [SPLIT]`

#[path = "common/grid.rs"]
mod grid;

use std::time::{Duration, Instant};

use facespace::live::{Session, Stage};
use facespace::render::{CpuRenderer, DEFAULT_FEATHER, Edge};
use facespace::talker::Talker;

fn main() {
    let (grid, limit, split) = grid::args();
    let limit = limit.min(10);
    let talker = Talker::load("models/grid".as_ref()).unwrap();
    let aligner = facespace::align::Aligner::load_default(&[]).unwrap();
    let stage = Stage::new(&talker, 0).unwrap();
    let renderer = CpuRenderer::with_edge(&talker.model, Edge::Articulators(DEFAULT_FEATHER));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let ids = grid::split(&grid, &split, limit);
    println!("GRID s1 {split}: {} clips, one core", ids.len());
    let mouths = talker.mouths().unwrap();
    let runs = [(true, false), (false, false), (true, true)];
    for (heard, recorded) in runs.into_iter().filter(|r| !r.1 || mouths.is_some()) {
        for scale in [1u32, 2] {
            let mut chooser = mouths.map(|m| facespace::mouths::Chooser::new(m, &talker.model));
            let (mut session_t, mut place_t, mut decode_t, mut render_t) =
                (Duration::ZERO, Duration::ZERO, Duration::ZERO, Duration::ZERO);
            let (mut frames_done, mut seconds) = (0usize, 0f64);
            pool.install(|| {
                for id in &ids {
                    let clip = grid.join(format!("clips/{id}.mp4"));
                    let sound = facespace::audio::read(&clip, 16_000, 60.0).unwrap();
                    seconds += sound.samples.len() as f64 / 16_000.0;
                    let mut session = if heard {
                        Session::new(&talker)
                    } else {
                        let phones = aligner
                            .align(&sound.samples, sound.rate, &grid::words(&grid, id))
                            .unwrap()
                            .segments();
                        let mut s = Session::with_given_phones(&talker);
                        s.push_phones(&phones).unwrap();
                        s
                    };
                    let mut footage = talker.footage.shown(stage.plan());
                    let mut chunks = sound.samples.chunks(640).peekable();
                    while let Some(chunk) = chunks.next() {
                        let t = Instant::now();
                        session.push_audio(chunk, 16_000).unwrap();
                        let mut frames = session.pull().unwrap();
                        if chunks.peek().is_none() {
                            frames.extend(session.finish().unwrap());
                        }
                        session_t += t.elapsed();
                        let t = Instant::now();
                        stage.place(&mut frames).unwrap();
                        place_t += t.elapsed();
                        for mut f in frames {
                            let t = Instant::now();
                            let mut canvas = footage.next_frame().unwrap();
                            if scale > 1 {
                                let (w, h) = canvas.dimensions();
                                canvas = image::imageops::resize(
                                    &canvas,
                                    w * scale,
                                    h * scale,
                                    image::imageops::FilterType::Triangle,
                                );
                                // The face at the scaled pose: the similarity's a, b, tx, ty.
                                for v in &mut f.values[..4] {
                                    *v *= scale as f32;
                                }
                            }
                            decode_t += t.elapsed();
                            let t = Instant::now();
                            let params = talker.model.layout().split(&f.values).unwrap();
                            let pick = chooser.as_mut().filter(|_| recorded).map(|c| c.next(params));
                            match mouths.zip(pick.as_ref()) {
                                Some((m, pick)) => renderer.render_with(params, m.drawing(pick), &mut canvas),
                                None => renderer.render_with(params, |_| Ok(()), &mut canvas),
                            }
                            .unwrap();
                            render_t += t.elapsed();
                            frames_done += 1;
                        }
                    }
                }
            });
            let total = session_t + place_t + decode_t + render_t;
            let per = |d: Duration| d.as_secs_f64() * 1000.0 / frames_done as f64;
            println!(
                "{}{} {}×{}: {frames_done} frames ({seconds:.1} s of sound) at {:.0} fps on one core — per frame: session {:.2} ms, placing {:.2} ms, footage {:.2} ms, rendering {:.2} ms",
                if heard { "phones heard" } else { "phones given" },
                if recorded { ", recorded mouths" } else { "" },
                360 * scale,
                288 * scale,
                frames_done as f64 / total.as_secs_f64(),
                per(session_t),
                per(place_t),
                per(decode_t),
                per(render_t),
            );
        }
    }
}
