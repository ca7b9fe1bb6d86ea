//! Does the talker's face choose the mouth's opening as the recorded face does? (issue 34)
//! `visemes --talker` without words cuts its cues from the phones the talker's ear hears, then
//! lets a performance choose each B, C or D by how far its mouth opens
//! (`visemes::open_by_face`). Over a GRID s1 split: the recorded face's own choice (each clip
//! tracked with the talker's model) against the choice of the performance from the sound (the
//! talker's sound-to-face map, as the command does) and of the same phones performed as
//! labels — the share of B/C/D centiseconds that agree, the tracks held as the command holds
//! them (`visemes::hold`).
//!
//! `cargo run --release --example grid_openings -- ../shared/data/grid-s1 SPLIT [LIMIT]`

#[path = "common/grid.rs"]
mod grid;
use std::path::PathBuf;
use facespace::codec::{self, EncodeOptions};
use facespace::facespace::Frames;
use facespace::talker::{SayRequest, Speech, Talker};
use facespace::visemes::{self, Extended, Shape};
use facespace::phonemes::PhoneMap;
fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let g = PathBuf::from(&args[0]);
    let ids = grid::split(&g, &args[1], args.get(2).and_then(|n| n.parse().ok()).unwrap_or(usize::MAX));
    let talker = Talker::load(std::path::Path::new("models/grid")).unwrap();
    let levels = visemes::face_levels(&talker.model, &talker.codebook).unwrap();
    let staging = tempfile::tempdir().unwrap();
    let (mut agree, mut total) = ([0usize; 2], 0usize);
    for id in &ids {
        let clip = g.join(format!("clips/{id}.mp4"));
        let speech = facespace::audio::read(&clip, 16_000, 60.0).unwrap();
        let p = talker.perform(&SayRequest::new(Speech::Sound(clip.clone())), staging.path()).unwrap();
        let segments = p.target.clone();
        let cues = visemes::cues(&segments, speech.seconds(), Extended::default()).unwrap();
        let mut rows = Vec::new();
        let source = facespace::video::Source::open(&clip).unwrap();
        codec::track(&talker.model, source, &EncodeOptions::default(), facespace::no_progress, |image, t| {
            rows.extend(talker.model.project(&image, &t.landmarks)?);
            Ok(())
        })
        .unwrap();
        let real = Frames::from_rows(talker.model.layout(), 25.0, rows).unwrap();
        let opening = visemes::openings(&talker.model, &real);
        let truth = visemes::open_by_face(&cues, levels, |s, e| visemes::mean_opening(&opening, real.fps(), s, e));
        let labels = staging.path().join("x.lab");
        facespace::phonemes::write_labels(&labels, &segments).unwrap();
        let as_labels = Speech::Labels { labels, tier: None, map: PhoneMap::default(), audio: None };
        let q = talker.perform(&SayRequest::new(as_labels), staging.path()).unwrap();
        let track = |perf: &facespace::talker::Performance| {
            let frames = perf.utterance.variants()[0].1.clone();
            let o = visemes::openings(&talker.model, &frames);
            let fps = frames.fps();
            let chosen = visemes::open_by_face(&cues, levels, |s, e| visemes::mean_opening(&o, fps, s, e));
            visemes::hold(&chosen, Extended::default())
        };
        let tracks = [track(&p), track(&q)];
        let shape_at = |cues: &[visemes::Cue], t: u32| cues.iter().find(|c| c.start <= t && t < c.end).map(|c| c.shape);
        for t in 0..(speech.seconds() * 100.0) as u32 {
            let Some(want) = shape_at(&truth, t) else { continue };
            if !matches!(want, Shape::B | Shape::C | Shape::D) { continue; }
            total += 1;
            for (k, tr) in tracks.iter().enumerate() {
                agree[k] += usize::from(shape_at(tr, t) == Some(want));
            }
        }
        eprint!(".");
    }
    let share = agree.map(|a| a as f64 / total as f64);
    println!(
        "\nGRID s1 {} split (recorded), {} clips, {total} centiseconds of B/C/D: the face's choice agrees \
         from the sound {:.3}, from the phones performed {:.3}",
        args[1],
        ids.len(),
        share[0],
        share[1]
    );
}
