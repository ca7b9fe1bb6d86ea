//! The committed models are what today's `model build` makes of their committed training
//! sets (the commands in each folder's README): a model built before a change to the build
//! (the rim margin, say) fails here instead of drawing the change's absence into every video.

use std::path::Path;

use facespace::mesh::Region;
use facespace::model::{BuildOptions, FaceModel, load_training_set};

/// FNV-1a of the parts of a model that must match exactly: the mesh, its placement (margin
/// included) and the mask's pixels.
fn structure_hash(m: &FaceModel) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for t in &m.frame.triangles {
        t.iter().for_each(|v| eat(&v.to_le_bytes()));
    }
    eat(&m.placement.scale.to_le_bytes());
    m.placement
        .offset
        .iter()
        .for_each(|v| eat(&v.to_le_bytes()));
    eat(&m.placement.margin.to_le_bytes());
    for p in &m.frame.pixels {
        eat(&p.x.to_le_bytes());
        eat(&p.y.to_le_bytes());
    }
    h
}

/// Each array of `a` equals `b`'s to 1e-4 of its largest magnitude (the build is bit-exact on
/// any thread count here; the slack is for another CPU's rounding).
fn close(what: &str, a: &[f32], b: &[f32]) {
    assert_eq!(
        a.len(),
        b.len(),
        "{what}: {} values committed, {} built",
        a.len(),
        b.len()
    );
    let scale = a
        .iter()
        .fold(0f32, |m, x| m.max(x.abs()))
        .max(f32::MIN_POSITIVE);
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0f32, f32::max);
    assert!(
        worst <= 1e-4 * scale,
        "{what}: differs by {worst} (largest value {scale})"
    );
}

fn check(committed: &str, training: &str, region: Option<Region>, margin: f64) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let saved = FaceModel::load(&root.join(committed)).unwrap();
    let frames = load_training_set(&root.join(training), None).unwrap();
    let built = FaceModel::build(
        &frames,
        &BuildOptions {
            pixels: 20_000,
            region,
            margin,
            ..BuildOptions::default()
        },
        &mut facespace::no_progress,
    )
    .unwrap();
    let stale = format!(
        "{committed} is not what `model build` makes of {training} today: rebuild it with the command in its README"
    );
    assert_eq!(
        saved.placement.margin, built.placement.margin,
        "{stale} (margin)"
    );
    assert_eq!(
        saved.frame.n_pixels(),
        built.frame.n_pixels(),
        "{stale} (mask size)"
    );
    assert_eq!(
        saved.frame.mask_image(),
        built.frame.mask_image(),
        "{stale} (mask)"
    );
    assert_eq!(
        structure_hash(&saved),
        structure_hash(&built),
        "{stale} (mesh)"
    );
    assert_eq!(saved.region, built.region, "{stale} (region)");
    for (name, a, b) in [
        ("shape", &saved.shape.pca, &built.shape.pca),
        ("appearance", &saved.appearance.pca, &built.appearance.pca),
    ] {
        assert_eq!(
            a.n_components(),
            b.n_components(),
            "{stale} ({name} components)"
        );
        close(&format!("{stale}: {name} mean"), &a.mean, &b.mean);
        close(
            &format!("{stale}: {name} variances"),
            &a.variances,
            &b.variances,
        );
        close(
            &format!("{stale}: {name} components"),
            &a.components,
            &b.components,
        );
    }
    // A region model carries the whole-face model it was cut from, itself current.
    match (&saved.tracker, &built.tracker) {
        (Some(a), Some(b)) => {
            assert_eq!(
                structure_hash(a),
                structure_hash(b),
                "{stale} (tracker mesh)"
            );
            close(
                &format!("{stale}: tracker appearance"),
                &a.appearance.pca.components,
                &b.appearance.pca.components,
            );
        }
        (None, None) => {}
        _ => panic!("{stale} (the tracker/ inside it)"),
    }
    if saved.hash() != built.hash() {
        eprintln!("{committed}: the same model within rounding, not bit for bit (another CPU?)");
    }
}

#[test]
fn demo_model_is_current() {
    // `--margin 6`: dlib's jaw line runs up to 6 px onto FGNet's blue backdrop.
    check("models/demo/model", "models/demo/training", None, 6.0);
}

#[test]
fn grid_models_are_current() {
    check("models/grid/model", "models/grid/training", None, 4.0);
    check(
        "models/grid/lower",
        "models/grid/training",
        Some(Region::LowerFace),
        4.0,
    );
}
