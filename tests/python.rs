//! The Python package (issue 36, `python/`): its pytest suite, run by the interpreter that has
//! it installed (`.ci/run` installs it with `pip install ./python`; `FACESPACE_PYTHON` picks
//! another interpreter). Without the package this test says how to install it and passes:
//! `cargo test` alone needs no Python.

use crate::common;

#[test]
fn the_python_package_passes_its_tests() {
    let python = std::env::var("FACESPACE_PYTHON").unwrap_or_else(|_| "python3".into());
    let probe = std::process::Command::new(&python)
        .args(["-c", "import facespace._facespace, pytest, numpy"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        eprintln!(
            "skipped: {python} has no facespace package (pip install maturin numpy pytest && pip install ./python)"
        );
        return;
    }
    let out = std::process::Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "python/tests"])
        .current_dir(common::root())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "pytest failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{}", String::from_utf8_lossy(&out.stdout).lines().last().unwrap_or(""));
}
