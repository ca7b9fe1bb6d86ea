//! The committed models drawn over backgrounds that are not their recordings' blue: no pixel
//! of the face may be near the key colour (a model that learned the backdrop at the face's rim
//! draws blue-violet streaks down the cheeks), and a region model's cheeks are the
//! background's own.

use std::path::Path;

use facespace::facespace::Frames;
use facespace::model::{FaceModel, load_training_set};
use facespace::render::{CpuRenderer, DEFAULT_FEATHER, Renderer, feather_alpha};
use image::{Rgb, RgbImage};

/// The backdrop's colour: the per-channel median of the training images' corner pixels.
fn key_colour(images: &[&RgbImage]) -> [u8; 3] {
    let mut channels = [Vec::new(), Vec::new(), Vec::new()];
    for image in images {
        let (w, h) = image.dimensions();
        for (x, y) in [(2, 2), (w - 3, 2), (2, h - 3), (w - 3, h - 3)] {
            for (c, v) in channels.iter_mut().zip(image.get_pixel(x, y).0) {
                c.push(v);
            }
        }
    }
    channels.map(|mut c| {
        c.sort_unstable();
        c[c.len() / 2]
    })
}

fn no_key_colour_in_face(model_dir: &str, training: &str) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join(model_dir)).unwrap();
    let frames = load_training_set(&root.join(training), None).unwrap();
    let key = key_colour(&frames.iter().map(|f| &f.image).collect::<Vec<_>>());
    assert!(
        key[2] > key[0].max(key[1]),
        "{training}: the backdrop is blue ({key:?})"
    );
    let renderer = CpuRenderer::feathered(&model, DEFAULT_FEATHER);
    let dims = model.layout().dims();
    for backdrop in [Rgb([128, 128, 128]), Rgb([200, 60, 40]), Rgb([30, 160, 60])] {
        for f in &frames {
            let mut row = vec![0f32; dims];
            model
                .project_into(&f.image, &f.landmarks, &mut row)
                .unwrap();
            let params = Frames::from_rows(model.layout(), 25.0, row).unwrap();
            let (w, h) = f.image.dimensions();
            let mut canvas = RgbImage::from_pixel(w, h, backdrop);
            renderer.render_into(params.params(0), &mut canvas).unwrap();
            let face = facespace::eval::face_mask(&model, &f.landmarks.points, w, h);
            let near: Vec<(u32, u32)> = canvas
                .enumerate_pixels()
                .filter(|(x, y, p)| {
                    face[(*y * w + *x) as usize]
                        && p.0.iter().zip(key).all(|(&a, b)| a.abs_diff(b) <= 40)
                })
                .map(|(x, y, _)| (x, y))
                .collect();
            assert!(
                near.is_empty(),
                "{model_dir} over {backdrop:?}, {}: {} face pixels within 40 of the key colour {key:?}, e.g. {:?}",
                f.name,
                near.len(),
                &near[..near.len().min(5)]
            );
        }
    }
}

#[test]
fn demo_model_draws_no_backdrop() {
    no_key_colour_in_face("models/demo/model", "models/demo/training");
}

#[test]
fn grid_models_draw_no_backdrop() {
    no_key_colour_in_face("models/grid/model", "models/grid/training");
    no_key_colour_in_face("models/grid/lower", "models/grid/training");
}

/// A region model fades out away from its lips and chin: its cheeks beside the nose and its
/// nose are drawn from the background, its lips from the model.
#[test]
fn region_alpha_keeps_cheeks_from_the_background() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = FaceModel::load(&root.join("models/grid/lower")).unwrap();
    let alpha = feather_alpha(&model, DEFAULT_FEATHER);
    let frame = &model.frame;
    let at = |p: [f64; 2]| {
        let i = frame
            .pixels
            .iter()
            .position(|q| (q.x as f64 - p[0]).abs() < 0.5 && (q.y as f64 - p[1]).abs() < 0.5)
            .unwrap_or_else(|| panic!("{p:?} is not in the mask"));
        alpha[i]
    };
    let l = &frame.landmarks;
    let mid = |a: usize, b: usize, t: f64| {
        [
            (l[a][0] + t * (l[b][0] - l[a][0])).round(),
            (l[a][1] + t * (l[b][1] - l[a][1])).round(),
        ]
    };
    // Inside the lips, and between lower lip and chin: the model's.
    assert_eq!(at(mid(62, 66, 0.5)), 1.0);
    assert_eq!(at(mid(57, 8, 0.5)), 1.0);
    // The cheeks beside the nose (40 % from nostril wing to jaw) and the nose tip: background.
    assert_eq!(at(mid(31, 2, 0.4)), 0.0);
    assert_eq!(at(mid(35, 14, 0.4)), 0.0);
    assert!(at(mid(30, 33, 0.5)) < 0.01);
    // A full-face model has no articulators: only its rim fades.
    let full = FaceModel::load(&root.join("models/grid/model")).unwrap();
    let rim = feather_alpha(&full, DEFAULT_FEATHER);
    let inner = rim.iter().filter(|&&a| a == 1.0).count();
    assert!(inner > rim.len() * 3 / 4, "{inner} of {} at 1", rim.len());
}
