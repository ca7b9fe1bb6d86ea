//! Issue 26: the "Your own talker" walkthrough (docs/OWN_TALKER.md), followed line by line as written —
//! from a video of the talker to a synthesised sentence with its sound — on GRID speaker 1's
//! committed clips. Each `cargo run --release --` runs this build's binary; the other lines
//! (`cp`, `mkdir`) run in `sh`, in a folder holding links to the repository's `tests/` and
//! `models/`, so `out/` is the test's own.
use crate::common;

use std::path::Path;
use std::process::Command;

/// The commands of docs/OWN_TALKER.md's first `sh` block under `## Your own talker`,
/// continuation lines joined, comments dropped.
fn walkthrough() -> Vec<String> {
    let readme = std::fs::read_to_string(common::root().join("docs/OWN_TALKER.md")).unwrap();
    let section = &readme[readme
        .find("## Your own talker")
        .expect("docs/OWN_TALKER.md has the section")..];
    let block = &section[section.find("```sh\n").expect("an sh block") + 6..];
    let block = &block[..block.find("```").unwrap()];
    let mut commands = Vec::new();
    let mut current = String::new();
    for line in block.lines() {
        let line = line.trim();
        if current.is_empty() && (line.is_empty() || line.starts_with('#')) {
            continue;
        }
        match line.strip_suffix('\\') {
            Some(part) => current.push_str(part),
            None => {
                current.push_str(line);
                commands.push(std::mem::take(&mut current));
            }
        }
    }
    commands
}

/// Runs one walkthrough line in `dir`; returns its output, failing the test on a non-zero exit.
fn run(dir: &Path, line: &str) -> String {
    let exe = env!("CARGO_BIN_EXE_facespace");
    let command = match line.strip_prefix("cargo run --release -- ") {
        Some(args) => format!("'{exe}' {args}"),
        None => line.to_owned(),
    };
    let o = Command::new("sh")
        .args(["-c", &command])
        .current_dir(dir)
        .output()
        .unwrap();
    let text = common::text(&o);
    assert!(o.status.success(), "{line}\n{text}");
    text
}

/// The annotate line: the server starts on the frames and lists all 40 (a person would now
/// click; the next README line puts the committed marks in place instead). Only the port
/// differs from the README: any free one, so parallel tests never collide.
fn annotate(dir: &Path, line: &str) {
    let args: Vec<&str> = line.strip_prefix("cargo run --release -- ").unwrap().split_whitespace().collect();
    let (mut server, url) = common::listening(&args, dir, &[]);
    let (code, body) = common::http(&url, "GET", "/api/frames", "");
    let _ = server.kill();
    let _ = server.wait();
    assert_eq!(code, 200, "{body}");
    let listing: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(listing["frames"].as_array().unwrap().len(), 40, "{body}");
    assert_eq!(listing["marked"].as_array().unwrap().len(), 0, "{body}");
}

#[test]
fn the_own_talker_walkthrough_runs_as_written() {
    let commands = walkthrough();
    assert!(commands.len() >= 10, "{commands:#?}");
    let dir = tempfile::tempdir().unwrap();
    for linked in ["tests", "models"] {
        std::os::unix::fs::symlink(common::root().join(linked), dir.path().join(linked)).unwrap();
    }
    let mut outputs = Vec::new();
    for line in &commands {
        if line.starts_with("cargo run --release -- annotate ") {
            annotate(dir.path(), line);
            outputs.push(String::new());
        } else {
            outputs.push(run(dir.path(), line));
        }
    }
    let all = outputs.join("\n");
    eprintln!("{all}");
    let own = dir.path().join("out/own");

    // The model is of this talker: none of his three clips loses the face.
    let corpus = &outputs[commands
        .iter()
        .position(|c| c.contains("corpus from-videos"))
        .unwrap()];
    assert!(corpus.contains("2 sentences"), "{corpus}");
    assert_eq!(corpus.matches(", 0 lost").count(), 2, "{corpus}");
    let track = &outputs[commands
        .iter()
        .position(|c| c.contains("-- track "))
        .unwrap()];
    assert!(track.contains(", 0 lost"), "{track}");

    // The synthesised sentence: a video of the recording's 75 frames with its sound, the
    // borrowed phones named, the target's timings beside it.
    let synth = &outputs[commands
        .iter()
        .position(|c| c.contains("-- synth "))
        .unwrap()];
    assert!(synth.contains("75 frames at 25 fps"), "{synth}");
    assert!(
        synth.contains("is absent from the codebook: used"),
        "{synth}"
    );
    let video = own.join("synth/video.mp4");
    let frames = facespace::video::Source::open(&video).unwrap().count();
    assert_eq!(frames, 75);
    assert!(own.join("synth/utterance.lab").is_file());
    let sound = facespace::audio::read(&video, 16_000, 60.0).unwrap();
    let recording = facespace::audio::read(
        &common::root().join("tests/data/grid/bbwtzp.wav"),
        16_000,
        60.0,
    )
    .unwrap();
    assert!(
        (sound.seconds() - recording.seconds()).abs() < 0.1,
        "{} s of sound for a {} s recording",
        sound.seconds(),
        recording.seconds()
    );
    // The recording's own sound, sample for sample (its AAC packets are copied).
    let n = sound.samples.len().min(recording.samples.len());
    let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| f64::from(x * y)).sum::<f64>();
    let (s, r) = (&sound.samples[..n], &recording.samples[..n]);
    let correlation = dot(s, r) / (dot(s, s) * dot(r, r)).sqrt();
    assert!(correlation > 0.99, "correlation {correlation}");

    // The same parts as one talker folder, and `say` over its footage: one MP4 of the
    // sentence's 75 frames in the recordings' framing, with its sound.
    let say = &outputs[commands
        .iter()
        .position(|c| c.contains("-- say "))
        .unwrap()];
    assert!(say.contains("75 frames at 25 fps, 360×288, with sound"), "{say}");
    let said = facespace::video::Source::open(&own.join("say.mp4")).unwrap();
    assert_eq!((said.info().width, said.info().height), (360, 288));
    assert_eq!(said.count(), 75);
    assert!(own.join("talker/talker.json").is_file());

    // And the codec round trip.
    assert!(own.join("decoded.mp4").is_file());
}
