//! Issue 17: `kill -9` at random moments never leaves a destination missing, half-written or
//! mixed, and the next run leaves no staging of ours behind. Two writing commands (a model
//! build and an encode), 20 kills each at times spread over their run.
mod common;

use std::path::Path;
use std::time::Instant;

/// Entries in `dir` that are our staging.
fn staging(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".facespace-tmp-") || n.starts_with(".tmp-"))
        .collect()
}

/// Runs `args` to completion once (timing it), then 20 times killed at spread-out moments;
/// after each kill, `check` must accept the destination (the complete previous version).
fn killed_runs(args: &[&str], out: &Path, check: impl Fn(&Path)) {
    let bin = env!("CARGO_BIN_EXE_facespace");
    let start = Instant::now();
    let o = std::process::Command::new(bin).args(args).output().unwrap();
    assert!(o.status.success(), "{}", common::text(&o));
    let full = start.elapsed();
    check(out);
    let mut rng = common::Rng::new(17);
    for k in 0..20 {
        let at = full.mul_f64(rng.range(0.05, 1.1));
        let mut child = std::process::Command::new(bin)
            .args(args)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(at);
        let _ = child.kill();
        let _ = child.wait();
        assert!(out.exists(), "kill {k} at {at:?}: the destination is gone");
        check(out);
    }
    // The next complete run cleans what the killed ones left.
    let o = std::process::Command::new(bin).args(args).output().unwrap();
    assert!(o.status.success(), "{}", common::text(&o));
    check(out);
    let left = staging(out.parent().unwrap());
    assert!(left.is_empty(), "staging left behind: {left:?}");
}

#[test]
fn killed_model_builds_and_encodes_leave_whole_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let faces = common::faces_dir();
    let model = dir.path().join("model");
    killed_runs(
        &[
            "model",
            "build",
            "--images",
            faces.to_str().unwrap(),
            "--pixels",
            "20000",
            "-o",
            model.to_str().unwrap(),
        ],
        &model,
        |m| {
            facespace::model::FaceModel::load(m).unwrap_or_else(|e| panic!("damaged model: {e}"));
        },
    );
    let demo =
        facespace::model::FaceModel::load(&common::root().join("models/demo/model")).unwrap();
    let clip = common::root().join("tests/data/clip");
    let out = dir.path().join("clip.fsp");
    killed_runs(
        &[
            "encode",
            clip.to_str().unwrap(),
            "--init",
            clip.join("01000.pts").to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
        &out,
        |c| {
            let loaded = facespace::codec::Clip::load(c, &demo)
                .unwrap_or_else(|e| panic!("damaged clip: {e}"));
            assert_eq!(loaded.frames.len(), 50);
        },
    );
}
