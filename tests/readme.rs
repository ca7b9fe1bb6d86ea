//! Issue 68: the README is short, starts with what to type, and its code blocks run as
//! written — every `cargo run --release -- …` line of its `sh` blocks (in a folder holding
//! links to the repository's `tests/` and `models/`, so `out/` is the test's own; `say` from
//! text where a text-to-speech engine is installed; `serve` until it answers its page) and its
//! Python block (the microphone's chunks and `show` given by a prelude) where the package is
//! installed. `cargo test --release` is this run itself.
use crate::common;

use std::path::Path;
use std::process::Command;

/// The contents of every fenced block of `lang` in `text`.
fn blocks(text: &str, lang: &str) -> Vec<String> {
    let fence = format!("```{lang}\n");
    let mut found = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find(&fence) {
        let body = &rest[at + fence.len()..];
        let end = body.find("```").expect("a closed block");
        found.push(body[..end].to_owned());
        rest = &body[end + 3..];
    }
    found
}

/// The value after `-o` in a command line.
fn output_of(args: &str) -> Option<&str> {
    let words: Vec<&str> = args.split_whitespace().collect();
    words.iter().position(|w| *w == "-o").and_then(|i| words.get(i + 1)).copied()
}

fn run_line(dir: &Path, args: &str) {
    let exe = env!("CARGO_BIN_EXE_facespace");
    let o = Command::new("sh")
        .args(["-c", &format!("'{exe}' {args}")])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{args}\n{}", common::text(&o));
    if let Some(out) = output_of(args) {
        assert!(dir.join(out).exists(), "{args}: no {out}");
    }
}

/// `serve` (or `study serve`) as written, on any free port: its page answers (`study serve`'s
/// at the address it prints for its first viewer).
fn serve_line(dir: &Path, args: &str) {
    let words: Vec<&str> = args.split_whitespace().collect();
    let (mut server, url) = common::listening(&words, dir, &[]);
    let (code, page) = common::http(&url, "GET", "/", "");
    let _ = server.kill();
    let _ = server.wait();
    assert_eq!(code, 200);
    assert!(page.contains("<html") || page.contains("<!doctype"), "{}", &page[..page.len().min(200)]);
}

/// The command lines of an `sh` block: comments dropped, `\` continuations joined.
fn command_lines(block: &str) -> Vec<String> {
    let mut lines = Vec::new();
    let mut pending = String::new();
    for line in block.lines() {
        let line = line.split("  #").next().unwrap_or("").trim();
        if line.starts_with('#') || (line.is_empty() && pending.is_empty()) {
            continue;
        }
        match line.strip_suffix('\\') {
            Some(head) => pending.push_str(head),
            None => {
                pending.push_str(line);
                lines.push(std::mem::take(&mut pending).split_whitespace().collect::<Vec<_>>().join(" "));
            }
        }
    }
    lines.retain(|l| !l.is_empty());
    lines
}

/// Runs every line of an `sh` block in `dir`: `cargo run --release -- …` as the binary
/// (`serve` and `study serve` until they answer; `say` from text only with a text-to-speech
/// engine), `cp` and `mkdir` through the shell; `cargo test --release` is this run and `pip
/// install` is `.ci/run`'s. Gives how many ran.
fn run_block(dir: &Path, block: &str) -> usize {
    let mut ran = 0;
    for line in command_lines(block) {
        if line == "cargo test --release" || line.starts_with("pip install ") {
            continue;
        }
        if line.starts_with("cp ") || line.starts_with("mkdir ") {
            let o = Command::new("sh").args(["-c", &line]).current_dir(dir).output().unwrap();
            assert!(o.status.success(), "{line}\n{}", common::text(&o));
            ran += 1;
            continue;
        }
        let args = line
            .strip_prefix("cargo run --release -- ")
            .unwrap_or_else(|| panic!("a line this test cannot run: {line}"));
        match args.split_whitespace().take(2).collect::<Vec<_>>()[..] {
            ["serve", ..] | ["study", "serve"] => serve_line(dir, args),
            // Viewers answer between `study serve` and `study analyse` (tests/study.rs has a
            // headless browser do it): with none, analyse says what to do first.
            ["study", "analyse"] => {
                let exe = env!("CARGO_BIN_EXE_facespace");
                let o = Command::new("sh").args(["-c", &format!("'{exe}' {args}")]).current_dir(dir).output().unwrap();
                let said = common::text(&o);
                assert!(said.contains("no answers stored yet") && said.contains("study serve"), "{args}\n{said}");
            }
            ["say", ..] if args.starts_with("say \"") && facespace::tts::available().is_none() => {
                eprintln!("skipped `{args}`: no text-to-speech engine (.ci/run installs Festival)");
            }
            _ => run_line(dir, args),
        }
        ran += 1;
    }
    ran
}

/// A folder holding links to the repository's `tests/` and `models/`.
fn workspace() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for linked in ["tests", "models"] {
        std::os::unix::fs::symlink(common::root().join(linked), dir.path().join(linked)).unwrap();
    }
    dir
}

/// docs/TALKER.md's `say` examples run as written (one, `--labels` with `--audio`, was refused
/// by the command line it documented).
#[test]
fn the_say_examples_run_as_written() {
    let page = std::fs::read_to_string(common::root().join("docs/TALKER.md")).unwrap();
    let block = blocks(&page, "sh").into_iter().next().expect("an sh block");
    assert_eq!(run_block(workspace().path(), &block), 4);
}

#[test]
fn the_readme_is_short_and_runs_as_written() {
    let readme = std::fs::read_to_string(common::root().join("README.md")).unwrap();
    let lines: Vec<&str> = readme.lines().collect();
    assert!(lines.len() <= 150, "the README has {} lines", lines.len());
    let say = lines.iter().position(|l| l.contains("-- say ")).expect("the README shows say");
    assert!(say < 40, "`say` first appears at line {}", say + 1);
    let dir = workspace();
    let ran: usize = blocks(&readme, "sh").iter().map(|b| run_block(dir.path(), b)).sum();
    assert!(ran >= 4, "{ran} README commands");
    // The Python block, where the package is installed (.ci/run installs it).
    let python = std::env::var("FACESPACE_PYTHON").unwrap_or_else(|_| "python3".into());
    let installed = Command::new(&python)
        .args(["-c", "import facespace._facespace, numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !installed {
        eprintln!("skipped the Python block: no facespace package (pip install ./python)");
        return;
    }
    let [code] = blocks(&readme, "python").try_into().expect("one Python block");
    // docs/LIVE.md's session block too (its LiveKit worker: python/tests/test_livekit.py).
    let live = std::fs::read_to_string(common::root().join("docs/LIVE.md")).unwrap();
    let session = blocks(&live, "python").into_iter().next().expect("LIVE.md's session block");
    for code in [code, session] {
        run_python(&python, dir.path(), &code);
    }
}

/// A Python block with the microphone's chunks and `show` given by a prelude: it must show
/// at least 50 frames of 512×512.
fn run_python(python: &str, dir: &Path, code: &str) {
    let prelude = "import wave, numpy as np\n\
        with wave.open('tests/data/grid/bbbf9a.wav') as w:\n    \
        pcm = np.frombuffer(w.readframes(w.getnframes()), dtype='<i2')\n\
        microphone_chunks = [pcm[k:k + 640] for k in range(0, len(pcm), 640)]\n\
        shown = []\n\
        def show(image):\n    shown.append(image.shape)\n";
    let script = format!("{prelude}{code}\nassert len(shown) >= 50 and shown[0] == (512, 512, 3), shown[:3]\n");
    let o = Command::new(python).args(["-c", &script]).current_dir(dir).output().unwrap();
    assert!(o.status.success(), "{code}\n{}", common::text(&o));
}

/// Every `sh` block of docs/ runs as written (issue 68), each page in its own folder (its
/// blocks in order, so a later one may use an earlier one's `out/`). Blocks fenced `text` are
/// records of how committed folders were made from data the repository does not hold (GRID's
/// 1 000 recordings), said so beside them.
#[test]
fn the_docs_run_as_written() {
    let mut pages: Vec<_> = std::fs::read_dir(common::root().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    pages.sort();
    let (mut ran, mut blocks_seen) = (0, 0);
    for page in pages {
        let name = page.file_name().unwrap().to_string_lossy().into_owned();
        // OWN_TALKER.md's walkthrough is tests/walkthrough.rs, TALKER.md's say examples
        // the_say_examples_run_as_written.
        if name == "OWN_TALKER.md" || name == "TALKER.md" {
            continue;
        }
        let text = std::fs::read_to_string(&page).unwrap();
        let dir = workspace();
        for block in blocks(&text, "sh") {
            blocks_seen += 1;
            let n = run_block(dir.path(), &block);
            eprintln!("{name}: {n} commands");
            ran += n;
        }
    }
    assert!(blocks_seen >= 6 && ran >= 30, "{blocks_seen} blocks, {ran} commands");
}
