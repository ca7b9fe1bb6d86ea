//! Warps: identity, agreement with scikit-image on a real face, Delaunay against scipy.
use crate::common;

use std::collections::BTreeSet;

use common::Params;
use facespace::mesh::{self, MeshError, ReferenceFrame, Triangle};
use facespace::render::{CpuRenderer, Renderer};
use facespace::shape::read_pts;
use facespace::warp::{self, WarpError};
use image::RgbImage;
use serde::Deserialize;

#[derive(Deserialize)]
struct Reference {
    width: usize,
    height: usize,
    target: Vec<[f64; 2]>,
    source: Vec<[f64; 2]>,
    triangles: Vec<Triangle>,
    mask_rows: Vec<String>,
    scipy_delaunay: Vec<Triangle>,
}

fn reference() -> Reference {
    let text =
        std::fs::read_to_string(common::root().join("tests/data/warp_skimage.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn lenna() -> RgbImage {
    image::open(common::faces_dir().join("lenna.png"))
        .unwrap()
        .to_rgb8()
}

/// Warping with identical source and target landmarks returns the input pixels.
#[test]
fn identity_warp_returns_the_input() {
    let image = lenna();
    let pts = read_pts(&common::faces_dir().join("lenna.pts"))
        .unwrap()
        .points;
    let triangles = mesh::delaunay(&pts).unwrap();
    let frame = ReferenceFrame::from_landmarks(
        pts.clone(),
        triangles,
        image.width() as usize,
        image.height() as usize,
    )
    .unwrap();
    assert!(
        frame.n_pixels() > 10_000,
        "mesh covers the face: {} pixels",
        frame.n_pixels()
    );
    let texture = warp::to_reference(&frame, &image, &pts).unwrap();
    let mut worst = 0f32;
    for (p, t) in frame.pixels.iter().zip(texture.chunks_exact(3)) {
        let px = image.get_pixel(p.x, p.y).0;
        for c in 0..3 {
            worst = worst.max((t[c] - px[c] as f32).abs());
        }
    }
    assert!(worst < 1e-2, "image → reference identity error {worst}");
    // And back: drawing the texture at the same landmarks reproduces the image inside the mesh.
    let mut canvas = RgbImage::new(image.width(), image.height());
    warp::from_reference_into(&frame, &texture, &pts, &mut canvas).unwrap();
    for p in &frame.pixels {
        assert_eq!(
            canvas.get_pixel(p.x, p.y),
            image.get_pixel(p.x, p.y),
            "at {},{}",
            p.x,
            p.y
        );
    }
}

/// Our image → reference warp against scikit-image's PiecewiseAffineTransform + warp
/// (order 1) on a real face, same triangles: within 1 grey level on ≥ 99% of mask pixels.
#[test]
fn warp_agrees_with_scikit_image() {
    let r = reference();
    let expected = image::open(common::root().join("tests/data/warp_skimage.png"))
        .unwrap()
        .to_rgb8();
    let frame =
        ReferenceFrame::from_landmarks(r.target.clone(), r.triangles.clone(), r.width, r.height)
            .unwrap();
    let texture = warp::to_reference(&frame, &lenna(), &r.source).unwrap();
    let (mut within, mut worst) = (0usize, 0i32);
    for (p, t) in frame.pixels.iter().zip(texture.chunks_exact(3)) {
        let e = expected.get_pixel(p.x, p.y).0;
        let d = (0..3)
            .map(|c| (warp::to_u8(t[c]) as i32 - e[c] as i32).abs())
            .max()
            .unwrap();
        worst = worst.max(d);
        within += (d <= 1) as usize;
    }
    let frac = within as f64 / frame.n_pixels() as f64;
    eprintln!(
        "scikit-image parity: {:.4}% of {} mask pixels within 1 grey level, worst {worst}",
        100.0 * frac,
        frame.n_pixels()
    );
    assert!(
        frac >= 0.99,
        "only {:.3}% within 1 grey level",
        100.0 * frac
    );
    // The masks agree too (pixels exactly on the hull may go either way).
    let theirs: usize = r
        .mask_rows
        .iter()
        .map(|row| row.bytes().filter(|&b| b == b'1').count())
        .sum();
    let ours = frame.n_pixels();
    assert!(
        (ours as f64 - theirs as f64).abs() <= 0.01 * theirs as f64,
        "mask sizes {ours} vs {theirs}"
    );
}

/// Our Delaunay triangulation of a face shape is scipy's (as sets of vertex triples).
#[test]
fn delaunay_matches_scipy() {
    let r = reference();
    let canon = |ts: &[Triangle]| -> BTreeSet<[u32; 3]> {
        ts.iter()
            .map(|t| {
                let mut t = *t;
                t.sort();
                t
            })
            .collect()
    };
    let ours = mesh::delaunay(&r.target).unwrap();
    assert_eq!(canon(&ours), canon(&r.scipy_delaunay));
}

#[test]
fn degenerate_meshes_are_errors() {
    let line: Vec<[f64; 2]> = (0..10).map(|i| [i as f64, 2.0 * i as f64]).collect();
    assert!(matches!(
        mesh::delaunay(&line),
        Err(MeshError::Degenerate(_))
    ));
    let dup = vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 0.0]];
    let err = mesh::delaunay(&dup).unwrap_err();
    assert!(
        err.to_string().contains("landmarks 1 and 3 coincide"),
        "{err}"
    );
    let pts = vec![[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [5.0, 0.0]];
    let flat = [[0, 1, 3]];
    assert!(matches!(
        mesh::validate(&pts, &[[0, 1, 2], flat[0]]),
        Err(MeshError::ZeroArea { index: 1, .. })
    ));
    assert!(matches!(
        mesh::validate(&pts, &[[0, 1, 9]]),
        Err(MeshError::IndexOutOfRange { vertex: 9, .. })
    ));
    assert!(matches!(
        ReferenceFrame::fit_mean(&pts, vec![[0, 1, 2]], 10, 0.0),
        Err(MeshError::TooFewPixels(10))
    ));
}

#[test]
fn warp_input_errors() {
    let r = reference();
    let frame =
        ReferenceFrame::from_landmarks(r.target.clone(), r.triangles.clone(), r.width, r.height)
            .unwrap();
    let image = lenna();
    assert!(matches!(
        warp::to_reference(&frame, &image, &r.source[..60]),
        Err(WarpError::LandmarkCount {
            expected: 68,
            found: 60
        })
    ));
    let mut nan = r.source.clone();
    nan[3][0] = f64::NAN;
    assert!(matches!(
        warp::to_reference(&frame, &image, &nan),
        Err(WarpError::NotFinite { index: 3 })
    ));
    assert!(matches!(
        warp::to_reference(&frame, &RgbImage::new(0, 0), &r.source),
        Err(WarpError::EmptyImage { .. })
    ));
    let mut canvas = RgbImage::new(10, 10);
    assert!(matches!(
        warp::from_reference_into(&frame, &[0.0; 5], &r.target, &mut canvas),
        Err(WarpError::TextureLength { .. })
    ));
}

/// Rendering paints nothing beyond one pixel of some triangle's bounding box, even where
/// the mesh has slivers (the demo model's eyebrow arches: a shifted half-plane of a sliver
/// once reached across the whole frame).
#[test]
fn render_dilation_stays_next_to_the_mesh() {
    let model =
        facespace::model::FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let face =
        facespace::model::load_training_set(&common::root().join("tests/data/demo-heldout"), None)
            .unwrap();
    for e in face.iter().take(3) {
        let row = model.project(&e.image, &e.landmarks).unwrap();
        let params = model.layout().split(&row).unwrap();
        let sentinel = image::Rgb([1, 2, 3]);
        let mut canvas = RgbImage::from_pixel(e.image.width(), e.image.height(), sentinel);
        CpuRenderer::new(&model)
            .render_into(params, &mut canvas)
            .unwrap();
        let r = model.reconstruct(params).unwrap();
        let boxes: Vec<[f64; 4]> = model
            .frame
            .triangles
            .iter()
            .map(|t| {
                let p = t.map(|v| r.landmarks.points[v as usize]);
                let (xs, ys) = (p.map(|q| q[0]), p.map(|q| q[1]));
                let lo = |a: [f64; 3]| a[0].min(a[1]).min(a[2]) - 1.0;
                let hi = |a: [f64; 3]| a[0].max(a[1]).max(a[2]) + 1.0;
                [lo(xs), hi(xs), lo(ys), hi(ys)]
            })
            .collect();
        let stray = canvas
            .enumerate_pixels()
            .filter(|(_, _, p)| **p != sentinel)
            .filter(|(x, y, _)| {
                !boxes.iter().any(|b| {
                    (*x as f64) >= b[0]
                        && (*x as f64) <= b[1]
                        && (*y as f64) >= b[2]
                        && (*y as f64) <= b[3]
                })
            })
            .count();
        assert_eq!(
            stray, 0,
            "{}: {stray} pixels painted away from the mesh",
            e.name
        );
    }
}

/// Feathered compositing: with no feather it draws exactly what the plain renderer draws;
/// with one, pixels deep inside the face are unchanged, pixels off the face keep the
/// background, and the edge lies between the two.
#[test]
fn feathered_compositing_blends_only_the_edge() {
    let model = common::small_model();
    let face = &common::faces()[0];
    let (pose, shape) = model.shape.project(&face.landmarks).unwrap();
    let params = Params {
        pose,
        shape,
        appearance: vec![0.0; model.appearance.n_params()],
    };
    let (w, h) = face.image.dimensions();
    let background = RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([(x % 256) as u8, (y % 256) as u8, 200])
    });
    let draw = |r: &dyn Renderer| {
        let mut canvas = background.clone();
        r.render_into(params.view(), &mut canvas).unwrap();
        canvas
    };
    let hard = draw(&CpuRenderer::new(&model));
    let none = draw(&CpuRenderer::feathered(&model, 0.0));
    assert!(hard == none, "feather 0 must equal the plain renderer");
    let soft = CpuRenderer::feathered(&model, 6.0);
    let alpha = soft.alpha().unwrap();
    assert!(alpha.iter().all(|a| (0.0..=1.0).contains(a)));
    assert!(alpha.iter().filter(|&&a| a == 1.0).count() > alpha.len() / 2);
    assert!(alpha.iter().any(|&a| a < 0.2));
    let blended = draw(&soft);
    let (mut same_inside, mut kept_outside, mut between) = (0, 0, 0);
    for ((h, b), bg) in hard.pixels().zip(blended.pixels()).zip(background.pixels()) {
        if h == bg {
            // Not drawn by the face: the blend leaves it too.
            assert_eq!(b, bg);
            kept_outside += 1;
        } else if h == b {
            same_inside += 1;
        } else {
            between += 1;
        }
    }
    assert!(same_inside > 0 && kept_outside > 0 && between > 0);
    assert!(
        between < same_inside,
        "only the edge is blended: {between} vs {same_inside}"
    );
}
