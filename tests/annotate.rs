//! The landmark page (issue 15): the server's API and refusals, and the page itself driven by
//! a headless Chromium (skipped, saying so, where none is installed; `.ci/run` installs it).
mod common;

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use facespace::annotate::{AnnotateError, Annotator};
use facespace::http::HttpError;
use facespace::model::FaceModel;

/// A folder with two test-clip frames, the first with its `.pts`.
fn frames(dir: &Path) {
    let clip = common::root().join("tests/data/clip");
    for f in ["01000.jpg", "01000.pts", "01001.jpg"] {
        std::fs::copy(clip.join(f), dir.join(f)).unwrap();
    }
}

fn demo_model() -> FaceModel {
    FaceModel::load(&common::root().join("models/demo/model")).unwrap()
}

/// Starts a server on a free loopback port; returns its address and the stop flag.
fn start(dir: &Path) -> (String, Arc<AtomicBool>) {
    let annotator = Annotator::bind(dir, demo_model(), false, "127.0.0.1:0", false).unwrap();
    let url = annotator.url();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    std::thread::spawn(move || annotator.run(|_| {}, move || flag.load(Ordering::Relaxed)));
    (url, stop)
}

#[test]
fn server_serves_saves_and_refuses() {
    let dir = tempfile::tempdir().unwrap();
    frames(dir.path());
    let (url, stop) = start(dir.path());
    let (code, body) = common::http(&url, "GET", "/api/frames", "");
    assert_eq!(code, 200);
    assert!(
        body.contains("01000.jpg") && body.contains("01001.jpg"),
        "{body}"
    );
    // Path traversal and files that are not listed frames are refused.
    for p in [
        "/frames/..%2F..%2Fetc%2Fpasswd",
        "/frames/01000.pts",
        "/api/points/..%2Fx.jpg",
    ] {
        assert_eq!(common::http(&url, "GET", p, "").0, 404, "{p}");
    }
    assert_eq!(common::http(&url, "GET", "/frames/01000.jpg", "").0, 200);
    // The marked frame starts from its .pts; the other has none (the page asks for eye clicks).
    let (_, marked) = common::http(&url, "GET", "/api/points/01000.jpg", "");
    assert!(marked.contains("\"source\":\"pts\""), "{marked}");
    let (_, unmarked) = common::http(&url, "GET", "/api/points/01001.jpg", "");
    assert!(unmarked.contains("\"points\":null"), "{unmarked}");
    // Bad landmarks are refused and nothing is written.
    for bad in ["{\"points\": [[1, 2]]}", "not json", "{\"points\": \"x\"}"] {
        assert_eq!(
            common::http(&url, "POST", "/api/points/01001.jpg", bad).0,
            400,
            "{bad}"
        );
    }
    assert!(!dir.path().join("01001.pts").exists());
    let points: Vec<[f64; 2]> = (0..68)
        .map(|k| [100.0 + k as f64, 120.0 + 0.5 * k as f64])
        .collect();
    let body = serde_json::json!({ "points": points }).to_string();
    assert_eq!(
        common::http(&url, "POST", "/api/points/01001.jpg", &body).0,
        200
    );
    let saved = facespace::shape::read_pts(&dir.path().join("01001.pts")).unwrap();
    assert_eq!(saved.points, points);
    stop.store(true, Ordering::Relaxed);
    // Other machines are not served unless asked.
    let err = Annotator::bind(dir.path(), demo_model(), false, "0.0.0.0:0", false)
        .err()
        .unwrap();
    assert!(
        matches!(err, AnnotateError::Http(HttpError::NotLoopback(_))),
        "{err}"
    );
    assert!(Annotator::bind(dir.path(), demo_model(), false, "0.0.0.0:0", true).is_ok());
}

/// What the browser test does on the page, from outside it: for the first two frames, place
/// the mean from two eye clicks where there are no points yet, drag landmark 30 by (+5, +3)
/// image pixels with pointer events, and report each frame's point before and after.
const DRAG_TWO_FRAMES: &str = r#"(async () => {
  const at = (px, py) => ({clientX: canvas.getBoundingClientRect().left + px, clientY: canvas.getBoundingClientRect().top + py, bubbles: true, pointerId: 1});
  const log = [];
  for (let k = 0; k < Math.min(2, frames.length); k++) {
    await load(k);
    if (!points) {
      for (const c of [[image.width * 0.4, image.height * 0.4], [image.width * 0.6, image.height * 0.4]]) {
        const [x, y] = toCanvas(c);
        canvas.dispatchEvent(new PointerEvent("pointerdown", at(x, y)));
      }
    }
    const before = points[30].slice();
    const [x, y] = toCanvas(centre(points[30]));
    canvas.dispatchEvent(new PointerEvent("pointerdown", at(x, y)));
    canvas.dispatchEvent(new PointerEvent("pointermove", at(x + 5 * view.s, y + 3 * view.s)));
    canvas.dispatchEvent(new PointerEvent("pointerup", at(x + 5 * view.s, y + 3 * view.s)));
    await saving;
    log.push(`${frames[k]} ${before[0].toFixed(3)} ${before[1].toFixed(3)} ${points[30][0].toFixed(3)} ${points[30][1].toFixed(3)}`);
  }
  return log.join("\n");
})()"#;

/// The page in a real browser: for each of two frames (one with landmarks, one placed from two
/// eye clicks on the mean shape), drag landmark 30 by (+5, +3) pixels, then check the `.pts`
/// on disk holds the moved point.
#[test]
fn headless_chromium_drags_a_point_and_it_is_saved() {
    let Some(chromium) = common::chromium() else {
        eprintln!("skipped: no Chromium on PATH (.ci/run installs the distribution's package)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    frames(dir.path());
    let original = facespace::shape::read_pts(&dir.path().join("01000.pts")).unwrap();
    let (url, stop) = start(dir.path());
    let mut browser = common::cdp::Browser::launch(chromium);
    let page = browser.open(&url);
    browser.wait_for(&page, "frames.length > 0 && image && image.complete");
    // Pointer events dispatched on the page's canvas, as a person's drag would make them.
    let log = browser.eval(&page, DRAG_TWO_FRAMES);
    stop.store(true, Ordering::Relaxed);
    let log = log.as_str().unwrap().to_owned();
    let lines: Vec<&str> = log.lines().collect();
    assert_eq!(lines.len(), 2, "{log}");
    for line in lines {
        let f: Vec<&str> = line.split_whitespace().collect();
        let v: Vec<f64> = f[1..].iter().map(|x| x.parse().unwrap()).collect();
        assert!(
            (v[2] - v[0] - 5.0).abs() < 1e-3 && (v[3] - v[1] - 3.0).abs() < 1e-3,
            "{line}"
        );
        let pts = dir.path().join(Path::new(f[0]).with_extension("pts"));
        let saved = facespace::shape::read_pts(&pts).unwrap();
        assert_eq!(saved.len(), 68);
        assert!(
            (saved.points[30][0] - v[2]).abs() < 2e-3 && (saved.points[30][1] - v[3]).abs() < 2e-3,
            "{line}"
        );
        if f[0] == "01000.jpg" {
            // Started from its own .pts; only point 30 moved.
            assert!((v[0] - original.points[30][0]).abs() < 1e-3, "{line}");
            assert!((saved.points[0][0] - original.points[0][0]).abs() < 1e-5);
        }
    }
}
