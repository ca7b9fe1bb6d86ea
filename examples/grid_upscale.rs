//! GRID s1 scaled up 2× (Lanczos) to 720×576, only to test the full-size path (issue 38): the
//! frames hold no detail beyond 360×288, but the model, the recorded mouths and the drawing
//! all run at 720×576, so what they lose there shows.
//!
//! `cargo run --release --example grid_upscale -- GRID OUT [TRAIN]` writes a GRID-like folder
//! `OUT`: `clips/` (the first TRAIN training clips, default 120, and every validation and test
//! clip, each at one quantiser, QP 14, with its sound), `phones/`, `align/` and the split
//! files as they are; `recordings/` (those training clips with their phone labels, for
//! `talker build --recordings`); `training/` (the committed model's 57 marked frames, scaled
//! with their landmarks, for `model build`).

#[path = "common/grid.rs"]
mod grid;

use std::path::Path;

use facespace::shape::{Landmarks, read_pts, write_pts};
use facespace::video::Source;
use facespace::mp4_file::{AudioTrack, Writer};
use image::RgbImage;
use image::imageops::{FilterType, resize};

/// How much larger.
const SCALE: u32 = 2;

fn larger(image: &RgbImage) -> RgbImage {
    resize(image, image.width() * SCALE, image.height() * SCALE, FilterType::Lanczos3)
}

/// A pixel centre `x` (0-based) of the source lands on `SCALE·x + (SCALE − 1)/2` in the
/// larger image, where `resize` samples it.
fn larger_marks(l: &Landmarks) -> Landmarks {
    let s = f64::from(SCALE);
    Landmarks {
        points: l.points.iter().map(|p| p.map(|v| s * v + (s - 1.0) / 2.0)).collect(),
    }
}

fn upscale_clip(from: &Path, to: &Path) {
    let mut source = Source::open(from).unwrap();
    let info = source.info();
    let mut writer =
        Writer::create_with_qp(to, info.width * SCALE, info.height * SCALE, info.fps, 14).unwrap();
    while let Some(frame) = source.next_frame().unwrap() {
        writer.write(&larger(&frame)).unwrap();
    }
    let sound = AudioTrack::read(from).unwrap();
    writer.finish(to, sound.as_ref()).unwrap();
}

fn main() {
    let (grid, _, _) = grid::args();
    let out = std::path::PathBuf::from(std::env::args().nth(2).expect("the output folder"));
    let train: usize = std::env::args().nth(3).map_or(120, |n| n.parse().unwrap());
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for dir in ["clips", "recordings", "training"] {
        std::fs::create_dir_all(out.join(dir)).unwrap();
    }
    for name in ["train.txt", "validation.txt", "test.txt", "damaged.txt", "README.md"] {
        std::fs::copy(grid.join(name), out.join(name)).unwrap();
    }
    for dir in ["phones", "align"] {
        let link = out.join(dir);
        if !link.exists() {
            std::os::unix::fs::symlink(std::fs::canonicalize(grid.join(dir)).unwrap(), link)
                .unwrap();
        }
    }
    // The marked frames, with their landmarks.
    let marked = root.join("models/grid/training");
    for path in facespace::video::image_files(&marked).unwrap() {
        let image = facespace::video::read_image(&path).unwrap();
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        facespace::video::write_png(&out.join(format!("training/{name}.png")), &larger(&image))
            .unwrap();
        let marks = read_pts(&path.with_extension("pts")).unwrap();
        write_pts(&out.join(format!("training/{name}.pts")), &larger_marks(&marks)).unwrap();
    }
    let recordings = grid::split(&grid, "train", train);
    let mut ids = recordings.clone();
    ids.extend(grid::split(&grid, "validation", usize::MAX));
    ids.extend(grid::split(&grid, "test", usize::MAX));
    let clock = std::time::Instant::now();
    for id in &ids {
        let clip = out.join(format!("clips/{id}.mp4"));
        if !clip.exists() {
            upscale_clip(&grid.join(format!("clips/{id}.mp4")), &clip);
        }
        eprint!(".");
    }
    eprintln!();
    for id in &recordings {
        let clip = out.join(format!("recordings/{id}.mp4"));
        if !clip.exists() {
            std::fs::hard_link(out.join(format!("clips/{id}.mp4")), clip).unwrap();
        }
        std::fs::copy(grid.join(format!("phones/{id}.lab")), out.join(format!("recordings/{id}.lab")))
            .unwrap();
    }
    println!(
        "{} clips scaled {SCALE}× into {} in {:.0} s; {} recordings, {} marked frames",
        ids.len(),
        out.display(),
        clock.elapsed().as_secs_f64(),
        recordings.len(),
        facespace::video::image_files(&marked).unwrap().len()
    );
}
