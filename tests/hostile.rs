//! Issue 17's reproducers, one by one, against the release binary: each gives a clear error
//! (exit 1, naming the problem) or completes — never a panic (101), a signal, a hang or a
//! memory bomb. Every run has an address-space limit (3 GiB) and a time limit (60 s).
//! (Reproducers tested elsewhere: user files kept — `cli.rs`; kills — `kill.rs`; MP4 box
//! sizes — `video.rs`; codebook layout overflow and `/dev/zero` — `codebook.rs`; negative
//! variances and placement — `model.rs`; every reader mutated — `fuzz.rs`.)
use crate::common;

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TIME_LIMIT: Duration = Duration::from_secs(60);
const MEMORY_LIMIT: u64 = 3 << 30;

/// Runs the binary with the limits; returns the exit code (None: killed by a signal or the
/// time limit) and stdout + stderr.
fn run(args: &[&str]) -> (Option<i32>, String) {
    run_with(args, &[], MEMORY_LIMIT)
}

/// [`run`] with variables `env` set and `memory` bytes of address space.
fn run_with(args: &[&str], env: &[(&str, &str)], memory: u64) -> (Option<i32>, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_facespace"));
    cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
    cmd.envs(env.iter().copied());
    // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            let limit = libc::rlimit {
                rlim_cur: memory,
                rlim_max: memory,
            };
            libc::setrlimit(libc::RLIMIT_AS, &limit);
            Ok(())
        });
    }
    let mut child = cmd.spawn().unwrap();
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let out = child.wait_with_output().unwrap();
            let text = format!(
                "{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            return (status.code(), text);
        }
        if start.elapsed() > TIME_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            return (None, format!("over {TIME_LIMIT:?}: {args:?}"));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The run fails cleanly (exit 1) and its message contains every one of `words`.
#[track_caller]
fn refused(args: &[&str], words: &[&str]) {
    let (code, text) = run(args);
    assert_eq!(code, Some(1), "{args:?} → {code:?}\n{text}");
    for w in words {
        assert!(text.contains(w), "{args:?}: no {w:?} in\n{text}");
    }
    assert!(text.len() < 4000, "{args:?}: a {} byte message", text.len());
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The shared inputs: a clip folder of the demo talker and a codebook of the demo corpus.
struct Fixture {
    dir: tempfile::TempDir,
    clip: PathBuf,
    cb: PathBuf,
    lab: PathBuf,
}

fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let frames = common::root().join("tests/data/clip");
    let clip = dir.path().join("clip.fsp");
    let corpus = dir.path().join("corpus");
    let cb = dir.path().join("cb");
    let model = common::root().join("models/demo/model");
    for args in [
        vec![
            "encode",
            s(&frames),
            "--init",
            &format!("{}/01000.pts", s(&frames)),
            "-o",
            s(&clip),
        ],
        vec!["corpus", "demo", "-o", s(&corpus)],
        vec![
            "codebook",
            "build",
            "--model",
            s(&model),
            "--corpus",
            &format!("{}/train", s(&corpus)),
            "-o",
            s(&cb),
        ],
    ] {
        let (code, text) = run(&args);
        assert_eq!(code, Some(0), "{text}");
    }
    let lab = corpus.join("heldout/demo55.lab");
    Fixture { dir, clip, cb, lab }
}

impl Fixture {
    /// `synth` on the fixture's codebook, drawn on the CPU into `out`, then `extra`.
    fn synth_args(&self, out: &Path, extra: &[&str]) -> Vec<String> {
        let mut args = vec![
            "synth",
            "--codebook",
            s(&self.cb),
            "--renderer",
            "cpu",
            "-o",
            s(out),
        ];
        args.extend_from_slice(extra);
        args.iter().map(|x| x.to_string()).collect()
    }
}

/// A copy of folder `from` at `to` with `edit` applied to its JSON file `name`.
fn edited(from: &Path, to: &Path, name: &str, edit: impl FnOnce(&mut serde_json::Value)) {
    copy_files(from, to);
    let path = to.join(name);
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
}

/// Reproducers 5–10 on clip folders and decoding.
#[test]
fn clip_folders_and_decoding() {
    let f = fixture();
    let d = f.dir.path();
    let out = d.join("out.mp4");
    // 5: an audio name outside the folder is never followed.
    std::fs::create_dir(d.join("outside")).unwrap();
    std::fs::copy(
        common::root().join("tests/data/video/high_bframes_aac.mp4"),
        d.join("outside/secret_voice.m4a"),
    )
    .unwrap();
    for (i, audio) in ["../outside/secret_voice.m4a", "/etc/passwd", "/dev/zero"]
        .iter()
        .enumerate()
    {
        let c = d.join(format!("audio{i}.fsp"));
        edited(&f.clip, &c, "meta.json", |m| m["audio"] = (*audio).into());
        refused(
            &["decode", s(&c), "-o", s(&out)],
            &["not a plain file inside the folder"],
        );
        assert!(!out.exists());
    }
    // Issue 27, F4: an audio name that is a FIFO inside the folder is refused at once (ffmpeg
    // or our decoder would block on it forever).
    {
        use std::os::unix::ffi::OsStrExt;
        let c = d.join("fifo.fsp");
        edited(&f.clip, &c, "meta.json", |m| m["audio"] = "fifo.m4a".into());
        let fifo = std::ffi::CString::new(c.join("fifo.m4a").as_os_str().as_bytes()).unwrap();
        // SAFETY: mkfifo reads the NUL-terminated path it is given.
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
        let clock = std::time::Instant::now();
        refused(
            &["decode", s(&c), "-o", s(&out)],
            &["fifo.m4a", "not a regular file"],
        );
        assert!(clock.elapsed().as_secs() < 30);
        assert!(!out.exists());
    }
    // Issue 27, F5: a canvas whose sides pass but whose area would need gigabytes.
    {
        let c = d.join("huge.fsp");
        edited(&f.clip, &c, "meta.json", |m| {
            m["width"] = 16384.into();
            m["height"] = 16384.into();
        });
        refused(
            &["decode", s(&c), "-o", s(&out)],
            &["268435456 pixels", "meta.json"],
        );
    }
    // 6, 7, 9: absurd sizes and rates are blamed on meta.json, before any allocation.
    let cases: Vec<(&str, serde_json::Value, &str)> = vec![
        ("fps", 1e-300.into(), "frame rate"),
        ("fps", 0.into(), "frame rate"),
        ("width", 4294967295u64.into(), "width"),
        ("height", 65536.into(), "height"),
        ("version", "1".into(), "version"),
    ];
    for (i, (key, value, word)) in cases.into_iter().enumerate() {
        let c = d.join(format!("meta{i}.fsp"));
        edited(&f.clip, &c, "meta.json", |m| m[key] = value.clone());
        let (code, text) = run(&["decode", s(&c), "-o", s(&out)]);
        assert_eq!(code, Some(1), "{key}={value}: {text}");
        assert!(
            text.contains("meta.json") && text.contains(word),
            "{key}={value}: {text}"
        );
        assert!(!text.contains("version 0"), "{text}");
    }
    // 10: quantisation min > max.
    let q = d.join("q.fsp");
    let frames = common::root().join("tests/data/clip");
    let (code, text) = run(&[
        "encode",
        s(&frames),
        "--init",
        &format!("{}/01000.pts", s(&frames)),
        "--bits",
        "8",
        "-o",
        s(&q),
    ]);
    assert_eq!(code, Some(0), "{text}");
    let bad = d.join("qbad.fsp");
    edited(&q, &bad, "meta.json", |m| {
        let min = m["quantisation"]["min"].clone();
        m["quantisation"]["min"] = m["quantisation"]["max"].clone();
        m["quantisation"]["max"] = min;
    });
    refused(&["decode", s(&bad), "-o", s(&out)], &["meta.json"]);
    // 10: a clip without its model hash is not decoded with another model.
    let other = d.join("other");
    let (code, text) = run(&[
        "model",
        "build",
        "--images",
        s(&common::faces_dir()),
        "--pixels",
        "6000",
        "-o",
        s(&other),
    ]);
    assert_eq!(code, Some(0), "{text}");
    // 2: synthesis into a model folder, tracking into its own input folder: refused, intact.
    let before = std::fs::read(other.join("model.json")).unwrap();
    refused(
        &[
            "synth",
            "--codebook",
            s(&f.cb),
            "--labels",
            s(&f.lab),
            "-o",
            s(&other),
        ],
        &["refusing"],
    );
    assert_eq!(std::fs::read(other.join("model.json")).unwrap(), before);
    let input = d.join("input");
    std::fs::create_dir(&input).unwrap();
    for e in std::fs::read_dir(&frames).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), input.join(e.file_name())).unwrap();
    }
    let truth = std::fs::read(input.join("01000.pts")).unwrap();
    refused(
        &[
            "track",
            s(&input),
            "--init",
            s(&input.join("01000.pts")),
            "-o",
            s(&input),
        ],
        &["refusing"],
    );
    assert_eq!(std::fs::read(input.join("01000.pts")).unwrap(), truth);
    let nohash = d.join("nohash.fsp");
    edited(&f.clip, &nohash, "meta.json", |m| {
        m["model_hash"] = serde_json::Value::Null
    });
    let (code, text) = run(&["decode", s(&nohash), "--model", s(&other), "-o", s(&out)]);
    assert_eq!(code, Some(1), "{text}");
    // 10: feather values.
    for feather in ["--feather=NaN", "--feather=inf", "--feather=-5"] {
        refused(
            &["decode", s(&f.clip), feather, "-o", s(&out)],
            &["feather"],
        );
    }
}

/// Reproducers 6–9 on synthesis options and label files.
#[test]
fn synthesis_options_and_labels() {
    let f = fixture();
    let d = f.dir.path();
    let out = d.join("syn");
    let synth = |extra: &[&str]| f.synth_args(&out, extra);
    let refused_synth = |extra: &[&str], words: &[&str]| {
        let args = synth(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&args, words);
        assert!(!out.exists(), "{extra:?} wrote output");
    };
    for fps in ["0.0001", "1e9", "1e4", "NaN"] {
        refused_synth(&["--labels", s(&f.lab), "--fps", fps], &["frame rate"]);
    }
    refused_synth(
        &["--labels", s(&f.lab), "--context", "1000000000"],
        &["context"],
    );
    // Label files: a 2^63 end time, an end of 1e300, overlaps, a 3 MB line.
    let write = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let huge = write("huge.lab", "0 9223372036854775807 sil\n");
    refused_synth(&["--labels", s(&huge)], &["huge.lab"]);
    let far = write("far.tsv", "0\t0.5\tsil\n0.5\t1e300\tah\n");
    let (code, text) = run(&synth(&["--labels", s(&far)])
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>());
    assert_eq!(code, Some(1), "{text}");
    assert!(!text.contains("0×0"), "{text}");
    let overlap = write(
        "overlap.lab",
        "0 5000000 sil\n3000000 9000000 ah\n9000000 12000000 sil\n",
    );
    refused_synth(&["--labels", s(&overlap)], &["overlap.lab"]);
    let long = write("long.lab", &format!("0 5000000 {}\n", "x".repeat(3 << 20)));
    refused_synth(&["--labels", s(&long)], &["long.lab"]);
    let tg = write(
        "bomb.TextGrid",
        "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\nxmin = 0\nxmax = 1\ntiers? <exists>\nsize = 1\nitem []:\n    item [1]:\n        class = \"IntervalTier\"\n        name = \"phones\"\n        xmin = 0\n        xmax = 1\n        intervals: size = 10000000\n        intervals [1]:\n            xmin = 0\n            xmax = 1\n            text = \"sil\"\n",
    );
    refused_synth(&["--labels", s(&tg)], &["bomb.TextGrid"]);
    // 7: a 6 000-word text is synthesised within the limits (at 0.2 fps, to keep the test
    // short: 379 frames; rendering streams, so memory does not grow with the frames).
    let text = vec!["hello world"; 3000].join(" ");
    let args = synth(&["--text", &text, "--fps", "0.2"]);
    let (code, msg) = run(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(code, Some(0), "{}", &msg[..msg.len().min(2000)]);
}

/// Reproducers 5–10 on codebooks, models, videos and options.
#[test]
fn codebooks_models_videos_and_options() {
    let f = fixture();
    let d = f.dir.path();
    // 5: sentence files outside the folder, or not regular files.
    let fifo = d.join("cbfifo");
    edited(&f.cb, &fifo, "codebook.json", |_| {});
    std::fs::remove_file(fifo.join("sentence_0000.npy")).unwrap();
    let name = std::ffi::CString::new(s(&fifo.join("sentence_0000.npy"))).unwrap();
    // SAFETY: a plain mkfifo call on a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o644) }, 0);
    refused(&["codebook", "info", s(&fifo)], &["sentence_0000.npy"]);
    for (i, file) in ["/abs/secret.npy", "../../x.npy"].iter().enumerate() {
        let c = d.join(format!("cbpath{i}"));
        edited(&f.cb, &c, "codebook.json", |v| {
            v["sentences"][0][0] = (*file).into()
        });
        refused(&["codebook", "info", s(&c)], &[file]);
    }
    // 6, 7: sample counts.
    for samples in [
        serde_json::json!(18446744073709551615u64),
        serde_json::json!(10000000),
        serde_json::json!(1e12),
    ] {
        let c = d.join("cbsamples");
        let _ = std::fs::remove_dir_all(&c);
        edited(&f.cb, &c, "codebook.json", |v| {
            v["options"]["samples"] = samples.clone()
        });
        refused(&["codebook", "info", s(&c)], &["samples"]);
    }
    // 9: a codebook whose layout differs from the model's with the same total is named as such.
    let c = d.join("cblayout");
    edited(&f.cb, &c, "codebook.json", |v| {
        let shape = v["layout"]["shape"].as_u64().unwrap();
        let app = v["layout"]["appearance"].as_u64().unwrap();
        v["layout"]["shape"] = (shape + 1).into();
        v["layout"]["appearance"] = (app - 1).into();
        v["model_hash"] = serde_json::Value::Null;
    });
    let (code, text) = run(&[
        "synth",
        "--codebook",
        s(&c),
        "--labels",
        s(&f.lab),
        "-o",
        s(&d.join("x")),
    ]);
    assert_eq!(code, Some(1), "{text}");
    assert!(text.contains("layout") || text.contains("shape"), "{text}");
    // 6, 7: model sizes.
    for pixels in ["18446744073709551615", "100000000", "10000000000"] {
        refused(
            &[
                "model",
                "build",
                "--images",
                s(&common::faces_dir()),
                "--pixels",
                pixels,
                "-o",
                s(&d.join("m")),
            ],
            &["pixels"],
        );
    }
    let model = common::root().join("models/demo/model");
    for (i, (key, value)) in [
        ("scale", serde_json::json!(491238.0)),
        ("offset", serde_json::json!([1e6, 1e6])),
    ]
    .into_iter()
    .enumerate()
    {
        let m = d.join(format!("model{i}"));
        edited(&model, &m, "model.json", |v| {
            v["reference"]["placement"][key] = value.clone()
        });
        refused(&["model", "info", s(&m)], &["model.json"]);
    }
    // 6: a Y4M header with a non-ASCII tag; 8: a FIFO as input.
    let y4m = d.join("tag.y4m");
    std::fs::write(&y4m, b"YUV4MPEG2 W360 H288 F25:1 \xc3\xa9 C444\n").unwrap();
    refused(&["track", s(&y4m), "-o", s(&d.join("t.npy"))], &["tag.y4m"]);
    let pipe = d.join("pipe.mp4");
    let name = std::ffi::CString::new(s(&pipe)).unwrap();
    // SAFETY: as above.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o644) }, 0);
    refused(
        &["track", s(&pipe), "-o", s(&d.join("t.npy"))],
        &["pipe.mp4"],
    );
    // 6, 7, 10: MP4 tables — stts without entries, stsz declaring 2^32 − 1 samples, mdhd
    // timescale 0 (fps 0).
    let mp4 = std::fs::read(common::root().join("tests/data/video/high_bframes_aac.mp4")).unwrap();
    let at = |tag: &[u8]| mp4.windows(4).position(|w| w == tag).unwrap();
    for (name, offset, value) in [
        ("stts", at(b"stts") + 8, 0u32),
        ("stsz", at(b"stsz") + 12, u32::MAX),
        ("mdhd", at(b"mdhd") + 16, 0),
    ] {
        let mut bytes = mp4.clone();
        bytes[offset..offset + 4].copy_from_slice(&value.to_be_bytes());
        let p = d.join(format!("{name}.mp4"));
        std::fs::write(&p, bytes).unwrap();
        refused(
            &["encode", s(&p), "-o", s(&d.join("e.fsp"))],
            &[&format!("{name}.mp4")],
        );
    }
    // 10: landmarks far away, tracking thresholds, bits.
    let frames = common::root().join("tests/data/clip");
    let real = facespace::shape::read_pts(&frames.join("01000.pts")).unwrap();
    for (i, shift) in [1e300, -5000.0].iter().enumerate() {
        let pts = d.join(format!("far{i}.pts"));
        let moved = facespace::shape::Landmarks {
            points: real
                .points
                .iter()
                .map(|p| [p[0] + shift, p[1] + shift])
                .collect(),
        };
        facespace::shape::write_pts(&pts, &moved).unwrap();
        refused(
            &[
                "track",
                s(&frames),
                "--init",
                s(&pts),
                "-o",
                s(&d.join("t.npy")),
            ],
            &[if i == 0 {
                "far0.pts"
            } else {
                "outside the first frame"
            }],
        );
    }
    refused(
        &[
            "track",
            s(&frames),
            "--reinit-error",
            "NaN",
            "-o",
            s(&d.join("t.npy")),
        ],
        &["re-initialisation error"],
    );
    let start = Instant::now();
    refused(
        &[
            "encode",
            s(&frames),
            "--bits",
            "12",
            "-o",
            s(&d.join("b.fsp")),
        ],
        &["bits"],
    );
    assert!(
        start.elapsed() < Duration::from_secs(5),
        "--bits 12 refused only after {:?}",
        start.elapsed()
    );
}

// ---- Issue 39: data safety, round three -------------------------------------------------

/// Makes a FIFO at `path`.
fn mkfifo(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: mkfifo reads the NUL-terminated path it is given.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
}

/// Copies the files (not folders) of `from` into a new folder `to`.
fn copy_files(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

fn is_fifo(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_fifo())
}

const GRID_WORDS: &str = "bin blue by f nine again";

fn grid(name: &str) -> PathBuf {
    common::root().join("tests/data/grid").join(name)
}

/// Finding 1 (data loss): an output over one of its own inputs — the recording, the
/// transcript, the background video — is refused and the input is untouched; so is every
/// single-file `-o` that is a FIFO or a link to a device (each command given inputs that
/// would otherwise run to the write).
#[test]
fn outputs_never_replace_their_inputs_or_devices() {
    let f = fixture();
    let d = f.dir.path();
    let wav = d.join("mine.wav");
    std::fs::copy(grid("bbbf9a.wav"), &wav).unwrap();
    let transcript = d.join("words.txt");
    std::fs::write(&transcript, GRID_WORDS).unwrap();
    let bg = d.join("bg.mp4");
    std::fs::copy(common::root().join("models/demo/background.mp4"), &bg).unwrap();
    let kept = |p: &Path, from: &Path| {
        assert_eq!(
            std::fs::read(p).unwrap(),
            std::fs::read(from).unwrap(),
            "{p:?} changed"
        );
    };
    refused(
        &["align", s(&wav), "--text", GRID_WORDS, "-o", s(&wav)],
        &["also an input"],
    );
    kept(&wav, &grid("bbbf9a.wav"));
    refused(
        &[
            "align",
            s(&wav),
            "--transcript",
            s(&transcript),
            "-o",
            s(&transcript),
        ],
        &["also an input"],
    );
    assert_eq!(std::fs::read_to_string(&transcript).unwrap(), GRID_WORDS);
    // The same file through a link is the same input.
    let link = d.join("link.wav");
    std::os::unix::fs::symlink(&wav, &link).unwrap();
    refused(
        &["align", s(&wav), "--text", GRID_WORDS, "-o", s(&link)],
        &["also an input"],
    );
    kept(&wav, &grid("bbbf9a.wav"));
    refused(
        &["decode", s(&f.clip), "--background", s(&bg), "-o", s(&bg)],
        &["also an input"],
    );
    kept(&bg, &common::root().join("models/demo/background.mp4"));
    // FIFOs and a link to /dev/null as the destination of every single-file writer.
    let frames = common::root().join("tests/data/clip");
    let init = frames.join("01000.pts");
    let corpus = d.join("corpus");
    let model = common::root().join("models/demo/model");
    let image = common::root().join("tests/data/demo-heldout/f00804.jpg");
    let dev_null = d.join("null.lab");
    std::os::unix::fs::symlink("/dev/null", &dev_null).unwrap();
    refused(
        &["align", s(&wav), "--text", GRID_WORDS, "-o", s(&dev_null)],
        &["not a regular file"],
    );
    assert!(std::fs::symlink_metadata(&dev_null).unwrap().is_symlink());
    let cases: Vec<(&str, Vec<String>)> = vec![
        (
            "a.lab",
            vec![
                "align".into(),
                s(&wav).into(),
                "--text".into(),
                GRID_WORDS.into(),
            ],
        ),
        ("b.mp4", vec!["decode".into(), s(&f.clip).into()]),
        (
            "c.npy",
            vec![
                "track".into(),
                s(&frames).into(),
                "--init".into(),
                s(&init).into(),
            ],
        ),
        (
            "d.json",
            vec![
                "eval".into(),
                "--codebook".into(),
                s(&f.cb).into(),
                "--heldout".into(),
                format!("{}/heldout", s(&corpus)),
            ],
        ),
        (
            "e.json",
            vec![
                "train-weights".into(),
                "--codebook".into(),
                s(&f.cb).into(),
                "--validation".into(),
                format!("{}/heldout", s(&corpus)),
                "--population".into(),
                "4".into(),
                "--generations".into(),
                "1".into(),
            ],
        ),
        (
            "f.png",
            vec!["codebook".into(), "similarity".into(), s(&f.cb).into()],
        ),
        (
            "g.png",
            vec![
                "model".into(),
                "reconstruct".into(),
                s(&model).into(),
                "--image".into(),
                s(&image).into(),
            ],
        ),
        (
            "h.json",
            vec!["codec-report".into(), s(&frames).into(), s(&f.clip).into()],
        ),
    ];
    for (name, mut args) in cases {
        let fifo = d.join(name);
        mkfifo(&fifo);
        args.extend(["-o".into(), s(&fifo).into()]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&args, &["not a regular file"]);
        assert!(is_fifo(&fifo), "{args:?} replaced the FIFO");
    }
}

/// The three audio headers of finding 3 (kept in `tests/data/fuzz/`, where the fuzz suite
/// replays them), copied into `dir`: a WAV at 0 Hz, an MP4 whose `mdhd` timescales are 0, an
/// MP4 whose `hdlr` boxes have size 0.
fn broken_audio(dir: &Path) -> Vec<PathBuf> {
    [
        "audio-wav-rate-0.wav",
        "audio-mp4-mdhd-timescale-0.mp4",
        "audio-mp4-hdlr-size-0.mp4",
    ]
    .iter()
    .map(|name| {
        let p = dir.join(name);
        std::fs::copy(common::root().join("tests/data/fuzz").join(name), &p).unwrap();
        p
    })
    .collect()
}

/// Finding 3: audio headers that made symphonia panic (exit 101) are refused with a message
/// by every command that reads sound: align, synth --audio, decode (a clip's audio.m4a),
/// corpus from-videos (NAME.wav beside frames) and demo --clip.
#[test]
fn audio_headers_that_crashed_the_decoder_are_refused() {
    let f = fixture();
    let d = f.dir.path();
    let grid_model = common::root().join("models/grid/model");
    let grid_cb = common::root().join("models/grid/codebook");
    for bad in broken_audio(d) {
        let out = d.join("out");
        refused(
            &[
                "align",
                s(&bad),
                "--text",
                GRID_WORDS,
                "-o",
                s(&d.join("a.lab")),
            ],
            &[s(&bad)],
        );
        refused(
            &[
                "synth",
                "--model",
                s(&grid_model),
                "--codebook",
                s(&grid_cb),
                "--audio",
                s(&bad),
                "--text",
                GRID_WORDS,
                "--renderer",
                "cpu",
                "-o",
                s(&out),
            ],
            &[s(&bad)],
        );
        // demo --clip: the clip's own sound.
        if bad.extension().is_some_and(|e| e == "mp4") {
            std::fs::write(bad.with_extension("txt"), GRID_WORDS).unwrap();
            refused(&["demo", "--clip", s(&bad), "-o", s(&out)], &[s(&bad)]);
        }
        // corpus from-videos: a frame folder with NAME.wav and NAME.txt beside it.
        let rec = d.join("rec");
        let _ = std::fs::remove_dir_all(&rec);
        std::fs::create_dir_all(rec.join("x")).unwrap();
        for f in ["01000.jpg", "01001.jpg", "01002.jpg"] {
            std::fs::copy(
                common::root().join("tests/data/clip").join(f),
                rec.join("x").join(f),
            )
            .unwrap();
        }
        std::fs::write(rec.join("x.txt"), GRID_WORDS).unwrap();
        let ext = bad.extension().unwrap().to_str().unwrap();
        let ext = if ext == "wav" { "wav" } else { "m4a" };
        std::fs::copy(&bad, rec.join(format!("x.{ext}"))).unwrap();
        let (code, text) = run(&[
            "corpus",
            "from-videos",
            s(&rec),
            "-o",
            s(&d.join("corpus2")),
        ]);
        assert_eq!(code, Some(1), "{text}");
        // decode: the clip's own sound.
        let c = d.join("sound.fsp");
        let _ = std::fs::remove_dir_all(&c);
        edited(&f.clip, &c, "meta.json", |m| {
            m["audio"] = "audio.m4a".into()
        });
        std::fs::copy(&bad, c.join("audio.m4a")).unwrap();
        let decoded = d.join("decoded.mp4");
        let (code, text) = run(&["decode", s(&c), "-o", s(&decoded)]);
        assert_eq!(code, Some(1), "{text}");
        assert!(text.contains("audio.m4a"), "{text}");
        assert!(!decoded.exists());
    }
}

/// Finding 4: inputs that still bypassed the one opener — a FIFO blocked forever, `/dev/zero`
/// was read to 4 GB or taken for an absent `corpus.json`. Each is refused at once.
#[test]
fn fifos_and_devices_as_inputs_are_refused() {
    let f = fixture();
    let d = f.dir.path();
    let fifo = d.join("fifo");
    mkfifo(&fifo);
    let zero = Path::new("/dev/zero");
    let wav = grid("bbbf9a.wav");
    let training = common::root().join("models/demo/training");
    for input in [fifo.as_path(), zero] {
        refused(
            &[
                "align",
                s(&wav),
                "--transcript",
                s(input),
                "-o",
                s(&d.join("a.lab")),
            ],
            &["transcript", "not a regular file"],
        );
        for flag in ["--region", "--triangles"] {
            refused(
                &[
                    "model",
                    "build",
                    "--images",
                    s(&training),
                    flag,
                    s(input),
                    "-o",
                    s(&d.join("m")),
                ],
                &["not a regular file"],
            );
        }
        refused(
            &[
                "model",
                "reconstruct",
                s(&common::root().join("models/demo/model")),
                "--image",
                s(input),
                "-o",
                s(&d.join("r.png")),
            ],
            &["not a regular file"],
        );
    }
    // demo --clip: the words beside the clip.
    let clip = d.join("x.mp4");
    std::fs::copy(grid("bbbf9a.mp4"), &clip).unwrap();
    mkfifo(&d.join("x.txt"));
    refused(
        &["demo", "--clip", s(&clip), "-o", s(&d.join("demo"))],
        &["x.txt"],
    );
    // codebook build: corpus.json as a link to /dev/zero, and as a FIFO.
    for planted in [None, Some(())] {
        let corpus = d.join(format!("corpus-{}", planted.is_some()));
        copy_files(&d.join("corpus/train"), &corpus);
        let _ = std::fs::remove_file(corpus.join("corpus.json"));
        match planted {
            None => std::os::unix::fs::symlink(zero, corpus.join("corpus.json")).unwrap(),
            Some(()) => mkfifo(&corpus.join("corpus.json")),
        }
        refused(
            &[
                "codebook",
                "build",
                "--model",
                s(&common::root().join("models/demo/model")),
                "--corpus",
                s(&corpus),
                "-o",
                s(&d.join("cb2")),
            ],
            &["corpus.json", "not a regular file"],
        );
    }
}

/// Finding 7: a `corpus.json` that lies about its frame rate is an error naming the file and
/// the field, never taken for an absent one.
#[test]
fn corpus_json_lies_are_errors() {
    let f = fixture();
    let d = f.dir.path();
    let model = common::root().join("models/demo/model");
    let lies = [
        "{\"fps\": 0}",
        "{\"fps\": -1}",
        "{\"fps\": -1e308}",
        "{\"fps\": \"NaN\"}",
        "{\"fps\": \"25\"}",
        "{\"fps\": null}",
        "{\"fps\": []}",
        "{}",
        "not JSON",
    ];
    let build = |corpus: &Path| {
        let o = d.join("cb2");
        let args = [
            "codebook",
            "build",
            "--model",
            s(&model),
            "--corpus",
            s(corpus),
            "-o",
            s(&o),
        ];
        let (code, text) = run(&args);
        assert_eq!(code, Some(1), "{text}");
        assert!(text.contains("corpus.json") && text.len() < 4000, "{text}");
        text
    };
    for (i, lie) in lies.iter().enumerate() {
        let corpus = d.join(format!("corpus{i}"));
        copy_files(&d.join("corpus/train"), &corpus);
        std::fs::write(corpus.join("corpus.json"), lie).unwrap();
        let text = build(&corpus);
        assert!(text.contains("fps") || lie == &"not JSON", "{lie}: {text}");
    }
    // A folder under that name.
    let corpus = d.join("corpus-dir");
    copy_files(&d.join("corpus/train"), &corpus);
    let _ = std::fs::remove_file(corpus.join("corpus.json"));
    std::fs::create_dir(corpus.join("corpus.json")).unwrap();
    build(&corpus);
}

/// Finding 5: well-formed but absurd inputs cost bounded time and memory — 10⁶ label
/// segments in every format, a TextGrid holding more intervals than it declares, an hour of
/// sound under 3 s of labels, a 10 000-word `--say` (refused before any engine runs).
#[test]
fn absurd_inputs_are_refused_quickly() {
    let f = fixture();
    let d = f.dir.path();
    let out = d.join("syn");
    // Each within `run`'s time and memory limits, refused with a message naming the cause.
    let synth = |extra: &[&str], words: &[&str]| {
        let args = f.synth_args(&out, extra);
        refused(&args.iter().map(String::as_str).collect::<Vec<_>>(), words);
        assert!(!out.exists());
    };
    let n = 1_000_000;
    let mut lab = String::new();
    let mut tsv = String::new();
    // The short TextGrid form (the long one of 10⁶ intervals is over the 64 MiB read whole).
    let mut tg = format!(
        "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\n0\n3\n<exists>\n1\n\"IntervalTier\"\n\"phones\"\n0\n3\n{n}\n"
    );
    let mut long_tg = "File type = \"ooTextFile\"\nObject class = \"TextGrid\"\nxmin = 0\nxmax = 3\ntiers? <exists>\nsize = 1\nitem []:\n    item [1]:\n        class = \"IntervalTier\"\n        name = \"phones\"\n        xmin = 0\n        xmax = 3\n        intervals: size = 10\n".to_owned();
    for i in 0..n {
        let (a, b) = (i as f64 * 3e-6, (i + 1) as f64 * 3e-6);
        lab.push_str(&format!("{} {} ah\n", i * 30, (i + 1) * 30));
        tsv.push_str(&format!("{a}\t{b}\tah\n"));
        tg.push_str(&format!("{a}\n{b}\n\"ah\"\n"));
        if i < 100_000 {
            let (a, b) = (i as f64 * 3e-5, (i + 1) as f64 * 3e-5);
            long_tg.push_str(&format!("        intervals [{}]:\n            xmin = {a}\n            xmax = {b}\n            text = \"ah\"\n", i + 1));
        }
    }
    for (name, text) in [
        ("many.lab", &lab),
        ("many.tsv", &tsv),
        ("many.TextGrid", &tg),
    ] {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        synth(&["--labels", s(&p)], &[name, "segments"]);
    }
    // A TextGrid declaring 10 intervals and holding 10⁵.
    let p = d.join("lying.TextGrid");
    std::fs::write(&p, &long_tg).unwrap();
    synth(&["--labels", s(&p)], &["lying.TextGrid", "declares"]);
    // Sound far longer than the labels: 20 minutes (8 kHz, 8 bit) under demo55's few seconds.
    let long = d.join("long.wav");
    let samples = 8000 * 1200;
    let mut wav = Vec::with_capacity(44 + samples);
    wav.extend_from_slice(b"RIFF");
    wav.extend_from_slice(&(36 + samples as u32).to_le_bytes());
    wav.extend_from_slice(b"WAVEfmt ");
    wav.extend_from_slice(&16u32.to_le_bytes()); // the fmt chunk's size
    wav.extend_from_slice(&1u16.to_le_bytes()); // PCM
    wav.extend_from_slice(&1u16.to_le_bytes()); // mono
    wav.extend_from_slice(&8000u32.to_le_bytes());
    wav.extend_from_slice(&8000u32.to_le_bytes());
    wav.extend_from_slice(&1u16.to_le_bytes());
    wav.extend_from_slice(&8u16.to_le_bytes());
    wav.extend_from_slice(b"data");
    wav.extend_from_slice(&(samples as u32).to_le_bytes());
    wav.extend((0..samples).map(|i| 128u8.wrapping_add(((i / 10) % 20) as u8)));
    std::fs::write(&long, &wav).unwrap();
    synth(
        &["--labels", s(&f.lab), "--audio", s(&long)],
        &["long.wav", "the sound lasts"],
    );
    // 10 000 words to speak: refused from the text, whether or not an engine is installed.
    let words = vec!["hello"; 10_000].join(" ");
    synth(&["--say", &words], &["10000 words", "at most 1200"]);
}

/// Finding 8: an unknown 1 MB "word" and a codebook whose `photometric` record is 100 KB are
/// quoted in a few hundred bytes, not echoed whole.
#[test]
fn errors_do_not_echo_megabytes() {
    let f = fixture();
    let d = f.dir.path();
    let words = d.join("words.txt");
    std::fs::write(&words, format!("bin {} again", "q".repeat(1 << 20))).unwrap();
    refused(
        &[
            "align",
            s(&grid("bbbf9a.wav")),
            "--transcript",
            s(&words),
            "-o",
            s(&d.join("a.lab")),
        ],
        &["not in the pronouncing dictionary", "bytes)"],
    );
    let cb = d.join("cb-photometric");
    edited(&f.cb, &cb, "codebook.json", |v| {
        v["photometric"] = serde_json::Value::String("x".repeat(100_000));
    });
    refused(&["codebook", "info", s(&cb)], &["codebook.json", "bytes)"]);
}

// Issue 69, round four: the commands and surfaces added since round three.

/// A copy of the committed GRID talker in `dir/name` (a talker reads only what is inside
/// itself, never through a link).
fn grid_talker_copy(dir: &Path, name: &str) -> PathBuf {
    let talker = dir.join(name);
    let grid = common::root().join("models/grid");
    for part in ["model", "codebook", "footage", "mouths", "sound-to-face"] {
        common::copy_tree(&grid.join(part), &talker.join(part));
    }
    std::fs::copy(grid.join("talker.json"), talker.join("talker.json")).unwrap();
    talker
}

/// R5-1, R5-2, R5-3: `visemes -o` over its own recording or transcript, `say -o` into the
/// talker it reads, and the library's `Talker::say` (what the Python package calls) over its
/// recording or into its talker are refused before any work, the files as they were.
#[test]
fn outputs_never_land_on_what_the_new_commands_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let wav = d.join("mine.wav");
    std::fs::copy(grid("bbbf9a.wav"), &wav).unwrap();
    let transcript = d.join("mine.txt");
    std::fs::write(&transcript, GRID_WORDS).unwrap();
    let same = |p: &Path, bytes: &[u8]| assert!(std::fs::read(p).unwrap() == bytes, "{p:?} changed");
    let recording = std::fs::read(&wav).unwrap();
    refused(
        &["visemes", s(&wav), "--text", GRID_WORDS, "-o", s(&wav)],
        &["also an input"],
    );
    same(&wav, &recording);
    refused(
        &["visemes", s(&wav), "--transcript", s(&transcript), "-f", "json", "-o", s(&transcript)],
        &["also an input"],
    );
    same(&transcript, GRID_WORDS.as_bytes());
    let talker = grid_talker_copy(d, "talker");
    let labels = common::root().join("tests/data/grid/bbbs7a.lab");
    let mouths = talker.join("mouths/mouths.mp4");
    let kept_mouths = std::fs::read(&mouths).unwrap();
    refused(
        &["say", "--talker", s(&talker), "--labels", s(&labels), "-o", s(&mouths)],
        &["inside the input folder"],
    );
    same(&mouths, &kept_mouths);
    let t = facespace::talker::Talker::load(&talker).unwrap();
    let sound = facespace::talker::SayRequest::new(facespace::talker::Speech::Sound(wav.clone()));
    let e = t.say(&sound, &wav, |_| {}).expect_err("refused").to_string();
    assert!(e.contains("also an input"), "{e}");
    same(&wav, &recording);
    let e = t.say(&sound, &mouths, |_| {}).expect_err("refused").to_string();
    assert!(e.contains("inside the input folder"), "{e}");
    same(&mouths, &kept_mouths);
    facespace::talker::Talker::load(&talker).unwrap().mouths().unwrap().expect("its mouths whole");
}

/// R5-6: an output that names no video format is refused before any work, with or without a
/// system ffmpeg; and an ffmpeg that dies while frames are still coming (here one that exits
/// at once) is an error naming it — never a death by SIGPIPE (exit 141, no message) — with no
/// staging left beside the output.
#[test]
fn video_outputs_that_ffmpeg_cannot_take_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let labels = common::root().join("tests/data/grid/bbbs7a.lab");
    let start = Instant::now();
    for name in ["out.txt", "dec.md"] {
        refused(
            &["say", "--labels", s(&labels), "-o", s(&d.join(name))],
            &["not a video format", "give .mp4"],
        );
    }
    assert!(start.elapsed() < Duration::from_secs(10), "refused before any work");
    let fake = d.join("bin");
    std::fs::create_dir(&fake).unwrap();
    let ffmpeg = fake.join("ffmpeg");
    std::fs::write(&ffmpeg, "#!/bin/sh\nexit 1\n").unwrap();
    std::fs::set_permissions(&ffmpeg, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let path = format!("{}:{}", fake.display(), std::env::var("PATH").unwrap_or_default());
    let out = d.join("out").join("say.mkv");
    let (code, text) = run_with(
        &["say", "--labels", s(&labels), "--renderer", "cpu", "-o", s(&out)],
        &[("PATH", &path)],
        MEMORY_LIMIT,
    );
    assert_eq!(code, Some(1), "{text}");
    assert!(text.contains("ffmpeg failed"), "{text}");
    let left: Vec<_> = std::fs::read_dir(d.join("out")).unwrap().flatten().map(|e| e.file_name()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// R5-7, R5-16, R5-17: text that no engine should be given is refused from the text, before
/// any engine runs (a stand-in `text2wave` that marks being called shows it): digits and
/// words the dictionary lacks, one 5 000-letter word, 2 000 long words, 1 996 words (more
/// speech than is aligned at once) — each quickly, naming the cause and never a staging path.
#[test]
fn text_to_speech_is_refused_before_the_engine() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fake = d.join("bin");
    std::fs::create_dir(&fake).unwrap();
    let mark = d.join("engine-ran");
    let engine = fake.join("text2wave");
    std::fs::write(&engine, format!("#!/bin/sh\ntouch '{}'\nexit 1\n", mark.display())).unwrap();
    std::fs::set_permissions(&engine, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let path = format!("{}:{}", fake.display(), std::env::var("PATH").unwrap_or_default());
    let long_words = vec!["internationalization"; 2000].join(" ");
    let many = vec!["hello"; 1996].join(" ");
    let cases: [(&str, String, &[&str]); 5] = [
        ("digits in a word", "Our B2B sales.".into(), &["digits that are not a number", "b2b", "in words"]),
        ("an unknown word", "Hello zorblax.".into(), &["not in the pronouncing dictionary: zorblax"]),
        ("one long word", "a".repeat(5000), &["a word of 5000 letters"]),
        ("long words", long_words, &["2000 words"]),
        ("many words", many, &["1996 words", "at most 1200"]),
    ];
    for (what, text, words) in cases {
        let out = d.join("say.mp4");
        let start = Instant::now();
        let (code, said) = run_with(&["say", &text, "-o", s(&out)], &[("PATH", &path)], MEMORY_LIMIT);
        assert_eq!(code, Some(1), "{what}: {said}");
        for w in words {
            assert!(said.contains(w), "{what}: no {w:?} in {said}");
        }
        assert!(!said.contains("facespace-tmp") && said.len() < 4000, "{what}: {said}");
        assert!(start.elapsed() < Duration::from_secs(10), "{what}: {:?}", start.elapsed());
        assert!(!mark.exists(), "{what}: the engine ran");
        assert!(!out.exists());
    }
}

/// R5-12: a 20 MB transcript of 3 s of speech is refused from its word count, in a few
/// hundred megabytes (it took 1.16 GB before the refusal): under a 1 GiB address space.
#[test]
fn a_huge_transcript_is_judged_before_its_graph() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let words = d.join("words.txt");
    let text = "bin blue by f nine again ".repeat(800_000);
    std::fs::write(&words, &text).unwrap();
    let wav = grid("bbbf9a.wav");
    let out = d.join("out.mp4");
    for args in [
        vec!["say", "--audio", s(&wav), "--transcript", s(&words), "-o", s(&out)],
        vec!["align", s(&wav), "--transcript", s(&words), "-o", s(&d.join("out.lab"))],
    ] {
        let start = Instant::now();
        let (code, said) = run_with(&args, &[], 1 << 30);
        assert_eq!(code, Some(1), "{args:?}: {said}");
        assert!(said.contains("too long for the audio"), "{said}");
        assert!(start.elapsed() < Duration::from_secs(10));
    }
}

/// R5-13: a talker folder reads only regular files inside itself: `talker.json` linked to
/// `/etc/passwd`, a part linked to another folder, a file of a part linked elsewhere — each
/// refused, naming it.
#[test]
fn a_talker_reads_nothing_through_links() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let labels = common::root().join("tests/data/grid/bbbs7a.lab");
    let grid = common::root().join("models/grid");
    let say = |talker: &Path, named: &str| {
        let out = d.join("out.mp4");
        refused(
            &["say", "--talker", s(talker), "--labels", s(&labels), "-o", s(&out)],
            &[named, "not a plain file inside the folder"],
        );
        assert!(!out.exists());
    };
    let t = grid_talker_copy(d, "a");
    std::fs::remove_file(t.join("talker.json")).unwrap();
    std::os::unix::fs::symlink("/etc/passwd", t.join("talker.json")).unwrap();
    say(&t, "talker.json");
    let t = grid_talker_copy(d, "b");
    std::fs::remove_dir_all(t.join("model")).unwrap();
    std::os::unix::fs::symlink(grid.join("model"), t.join("model")).unwrap();
    say(&t, "\"model\"");
    let t = grid_talker_copy(d, "c");
    std::fs::remove_file(t.join("codebook/codebook.json")).unwrap();
    std::os::unix::fs::symlink(grid.join("codebook/codebook.json"), t.join("codebook/codebook.json")).unwrap();
    say(&t, "codebook/codebook.json");
    // The copy itself, without links, speaks.
    let t = grid_talker_copy(d, "d");
    let out = d.join("fine.mp4");
    let (code, said) = run(&["say", "--talker", s(&t), "--labels", s(&labels), "--renderer", "cpu", "-o", s(&out)]);
    assert_eq!(code, Some(0), "{said}");
}

/// R5-4, R5-5, R5-14: `talker build` builds only into a new or empty folder or one it made;
/// never into (or inside) its recordings; settings no synthesis can use are refused before
/// any work; and a rebuild keeps a part only when made from the same inputs — recordings
/// replaced under the same names make a new corpus and codebook.
#[test]
fn talker_build_keeps_to_its_own_folder_and_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model = common::root().join("models/grid/model");
    let rec = d.join("rec");
    std::fs::create_dir(&rec).unwrap();
    let data = common::root().join("tests/data/grid");
    let put = |name: &str, from: &str| {
        for ext in ["mp4", "txt"] {
            std::fs::copy(data.join(format!("{from}.{ext}")), rec.join(format!("{name}.{ext}"))).unwrap();
        }
    };
    for name in ["bbbf9a", "bbbs7a", "bbwtzp"] {
        put(name, name);
    }
    let build = |out: &Path, extra: &[&str]| {
        let mut args = vec!["talker", "build", "--model", s(&model), "--recordings", s(&rec), "--name", "t"];
        args.extend_from_slice(extra);
        args.extend(["-o", s(out)]);
        args.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let refuse = |out: &Path, extra: &[&str], words: &[&str]| {
        let args = build(out, extra);
        let start = Instant::now();
        refused(&args.iter().map(String::as_str).collect::<Vec<_>>(), words);
        assert!(start.elapsed() < Duration::from_secs(10), "{args:?}");
    };
    // Settings refused before any work.
    let t = d.join("t");
    for (flag, value) in [("--smoothing", "NaN"), ("--smoothing", "1e308"), ("--top-n", "0"), ("--context", "99")] {
        refuse(&t, &[&format!("{flag}={value}")], &[flag, "out of range"]);
        assert!(!t.exists());
    }
    // A user's folder, the recordings folder, a folder inside it.
    let mine = d.join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("talker.json"), "{\"mine\": true}").unwrap();
    refuse(&mine, &[], &["did not make", "talker.json"]);
    assert_eq!(std::fs::read_to_string(mine.join("talker.json")).unwrap(), "{\"mine\": true}");
    refuse(&rec, &[], &["also an input"]);
    refuse(&rec.join("talker"), &[], &["inside the input folder"]);
    assert_eq!(std::fs::read_dir(&rec).unwrap().count(), 6, "the recordings as they were");
    // Built, then built again from other recordings under the same names: the corpus and
    // the codebook follow the recordings' contents, not their names.
    let built = |what: &str| {
        let args = build(&t, &[]);
        let (code, said) = run(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert_eq!(code, Some(0), "{what}: {said}");
        let talker = facespace::talker::Talker::load(&t).unwrap();
        let phones = |name: &str| {
            let s = talker.codebook.sentences.iter().find(|s| s.name == name).unwrap();
            s.segments.iter().map(|g| g.phone).collect::<Vec<_>>()
        };
        (phones("bbbf9a"), phones("bbbs7a"))
    };
    let first = built("first");
    assert_ne!(first.0, first.1);
    assert_eq!(built("again, every part kept"), first);
    put("bbbf9a", "bbbs7a");
    put("bbbs7a", "bbbf9a");
    assert_eq!(built("other recordings"), (first.1.clone(), first.0.clone()), "a part made from the old recordings was kept");
}
