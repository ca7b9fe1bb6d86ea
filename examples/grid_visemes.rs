//! Do the viseme track's diphthongs open and close as the recorded face does? (issue 34)
//! Each clip of a GRID s1 split tracked with the talker's model; in every video frame inside
//! an /ay/ or /ey/ of the clip's phones (`phones/`, forced-aligned to the true words) the
//! face's own opening (inner-mouth height, `visemes::openings`) is compared with the shape
//! the track shows then — one shape for the whole vowel (`Shape::of_phone`) against the
//! onset and its glide (`visemes::cues`, `Shape::of_diphthong`). Both opening glides close
//! toward B; the talker's typical B, C and D openings (`visemes::face_levels`) turn a shape
//! into an opening and an opening into its nearest shape.
//!
//! `cargo run --release --example grid_visemes -- ../shared/data/grid-s1 all SPLIT`

#[path = "common/grid.rs"]
mod grid;
#[path = "common/track.rs"]
mod track;

use facespace::phonemes::{Phone, PhoneMap, read_htk};
use facespace::visemes::{self, Extended, Shape};

fn main() {
    let (root, limit, split) = grid::args();
    let talker = facespace::talker::Talker::load(std::path::Path::new("models/grid")).unwrap();
    let levels = visemes::face_levels(&talker.model, &talker.codebook).unwrap();
    let level = |s: Shape| match s {
        Shape::B => Some(levels[0]),
        Shape::C => Some(levels[1]),
        Shape::D => Some(levels[2]),
        _ => None,
    };
    let nearest = |h: f64| {
        [Shape::B, Shape::C, Shape::D]
            .into_iter()
            .min_by(|&a, &b| (level(a).unwrap() - h).abs().total_cmp(&(level(b).unwrap() - h).abs()))
            .unwrap()
    };
    let glides = [Phone::parse("ay").unwrap(), Phone::parse("ey").unwrap()];
    // [one shape, onset and glide]: frames agreeing with the face's nearest shape, and the sum
    // of |shape's opening − face's opening|; per half of the vowel.
    let (mut agree, mut error) = ([[0usize; 2]; 2], [[0f64; 2]; 2]);
    // Per vowel (/ay/, /ey/) and half: the face's summed opening and its frames.
    let (mut mean, mut count) = ([[0f64; 2]; 2], [[0usize; 2]; 2]);
    let ids = grid::split(&root, &split, limit);
    for id in &ids {
        let clip = root.join(format!("clips/{id}.mp4"));
        let (_, tracked, _) = track::tracked(&talker.model, &clip);
        let opening = visemes::openings(&talker.model, &tracked);
        let segments = read_htk(&root.join(format!("phones/{id}.lab")), &PhoneMap::default()).unwrap();
        let seconds = opening.len() as f64 / tracked.fps();
        let cues = visemes::cues(&segments, seconds, Extended::default()).unwrap();
        for (k, &h) in opening.iter().enumerate() {
            let t = k as f64 / tracked.fps();
            let Some(seg) = segments.iter().find(|s| s.start <= t && t < s.end && glides.contains(&s.phone)) else {
                continue;
            };
            let half = usize::from(t >= 0.5 * (seg.start + seg.end));
            let cs = (t * 100.0).round() as u32;
            let shown = cues.iter().find(|c| c.start <= cs && cs < c.end).map(|c| c.shape);
            let one = Shape::of_phone(seg.phone);
            let p = usize::from(seg.phone == glides[1]);
            mean[p][half] += h;
            count[p][half] += 1;
            for (j, shape) in [one, shown].into_iter().enumerate() {
                let shape = shape.unwrap();
                agree[j][half] += usize::from(shape == nearest(h));
                error[j][half] += (level(shape).unwrap_or(levels[1]) - h).abs();
            }
        }
    }
    let span = levels[2] - levels[0];
    let frames = [0, 1].map(|half| count[0][half] + count[1][half]);
    println!("GRID s1 {split} split (recorded), {} clips: video frames inside /ay/ and /ey/", ids.len());
    println!("| track | frames as the face's nearest shape, first half / second half | |opening − face's| / (D − B), first / second half |");
    println!("|---|---|---|");
    for (j, name) in ["one shape per vowel (of_phone)", "onset, then its glide (of_diphthong)"].iter().enumerate() {
        println!(
            "| {name} | {:.3} / {:.3} | {:.3} / {:.3} |",
            agree[j][0] as f64 / frames[0] as f64,
            agree[j][1] as f64 / frames[1] as f64,
            error[j][0] / frames[0] as f64 / span,
            error[j][1] / frames[1] as f64 / span,
        );
    }
    for p in 0..2 {
        println!("{:?}: the face's mean opening, first half {:.4}, second half {:.4} ({} / {} frames)", glides[p], mean[p][0] / count[p][0] as f64, mean[p][1] / count[p][1] as f64, count[p][0], count[p][1]);
    }
    println!("({} / {} frames; levels B {:.3}, C {:.3}, D {:.3})", frames[0], frames[1], levels[0], levels[1], levels[2]);
}
