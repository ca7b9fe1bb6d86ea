//! Forced-alignment benchmark on GRID speaker 1 (recorded speech): every clip of
//! `../shared/data/grid-s1/clips` aligned to its transcript (the words of `align/ID.align`),
//! phone boundaries compared with `phones/ID.lab` (pocketsphinx 5.1.1) and word boundaries
//! with `align/ID.align` (the corpus's own HMM alignment). Also the speed on one core, and
//! PyPI pocketsphinx on the same decoded audio when `python3 -c "import pocketsphinx"` works.
//!
//! `cargo run --release --example align_grid [-- GRID_DIR [LIMIT]]`

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use facespace::align::{self, Aligner};
use facespace::audio;
use facespace::phonemes::{self, PhoneMap};

#[path = "common/grid.rs"]
mod grid;

/// Index pairs of a longest common subsequence of two phone sequences (by phone).
fn lcs(a: &[phonemes::Segment], b: &[phonemes::Segment]) -> Vec<(usize, usize)> {
    let (n, m) = (a.len(), b.len());
    let mut t = vec![vec![0usize; m + 1]; n + 1];
    for i in (0..n).rev() {
        for j in (0..m).rev() {
            t[i][j] = if a[i].phone == b[j].phone {
                t[i + 1][j + 1] + 1
            } else {
                t[i + 1][j].max(t[i][j + 1])
            };
        }
    }
    let (mut i, mut j, mut out) = (0, 0, Vec::new());
    while i < n && j < m {
        if a[i].phone == b[j].phone {
            out.push((i, j));
            i += 1;
            j += 1;
        } else if t[i + 1][j] >= t[i][j + 1] {
            i += 1;
        } else {
            j += 1;
        }
    }
    out
}

fn quantiles(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    };
    (median, v[(n as f64 * 0.9) as usize])
}

fn within(v: &[f64], ms: f64) -> f64 {
    100.0 * v.iter().filter(|&&d| d <= ms / 1000.0 + 1e-9).count() as f64 / v.len() as f64
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let grid = PathBuf::from(args.get(1).cloned().unwrap_or_else(|| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/grid-s1").to_owned()
    }));
    let limit: usize = args
        .get(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(usize::MAX);
    let mut ids: Vec<String> = std::fs::read_dir(grid.join("clips"))
        .unwrap()
        .filter_map(|e| {
            let p = e.ok()?.path();
            if p.extension()? != "mp4" {
                return None;
            }
            Some(p.file_stem()?.to_str()?.to_owned())
        })
        .collect();
    ids.sort();
    ids.truncate(limit);

    let t0 = Instant::now();
    let aligner = Aligner::load_default(&[]).unwrap();
    let load_ms = t0.elapsed().as_secs_f64() * 1e3;

    let wav_dir = tempfile::tempdir().unwrap();
    let mut decoded = Vec::new();
    for id in &ids {
        let a = audio::read(
            &grid.join("clips").join(format!("{id}.mp4")),
            16_000,
            align::MAX_SECONDS,
        )
        .unwrap();
        audio::write_wav(&wav_dir.path().join(format!("{id}.wav")), &a).unwrap();
        decoded.push(a);
    }

    let mut phone_d = Vec::new();
    let mut word_start_d = Vec::new();
    let mut word_end_d = Vec::new();
    let mut word_d = Vec::new();
    let mut mismatched = 0;
    let mut unpaired = 0;
    let mut total_ref = 0;
    let mut failed = Vec::new();
    let mut align_seconds = 0.0;
    let mut audio_seconds = 0.0;
    let mut texts = Vec::new();
    for (id, a) in ids.iter().zip(&decoded) {
        let words = grid::read_align(&grid.join("align").join(format!("{id}.align")));
        let text: Vec<&str> = words.iter().map(|w| w.2.as_str()).collect();
        let text = text.join(" ");
        texts.push(format!("{id}\t{text}"));
        let t = Instant::now();
        let result = aligner.align(&a.samples, a.rate, &text);
        align_seconds += t.elapsed().as_secs_f64();
        audio_seconds += a.seconds();
        let result = match result {
            Ok(r) => r,
            Err(e) => {
                failed.push(format!("{id}: {e}"));
                continue;
            }
        };
        // Words against the corpus alignment.
        for (w, (s, e, _)) in result.words.iter().zip(&words) {
            word_start_d.push((w.start - s).abs());
            word_end_d.push((w.end - e).abs());
            word_d.push((w.start - s).abs());
            word_d.push((w.end - e).abs());
        }
        // Phones against pocketsphinx: the speech phones' starts and ends, when the phone
        // sequences agree (they differ only where another pronunciation won).
        let reference = phonemes::read_htk(
            &grid.join("phones").join(format!("{id}.lab")),
            &PhoneMap::default(),
        )
        .unwrap();
        let ours = result.segments();
        let speech = |s: &[phonemes::Segment]| -> Vec<phonemes::Segment> {
            s.iter()
                .filter(|p| p.phone != phonemes::Phone::SIL)
                .copied()
                .collect()
        };
        let (r, o) = (speech(&reference), speech(&ours));
        if r.len() != o.len() || r.iter().zip(&o).any(|(a, b)| a.phone != b.phone) {
            mismatched += 1;
        }
        // Phones paired by a longest common subsequence (identical sequences pair one to one;
        // another pronunciation leaves its differing phones unpaired). Each boundary once:
        // every paired phone's start, and its end where silence follows it in the reference.
        let pairs = lcs(&r, &o);
        for &(i, j) in &pairs {
            phone_d.push((r[i].start - o[j].start).abs());
            if r.get(i + 1).is_none_or(|next| next.start > r[i].end + 1e-6) {
                phone_d.push((r[i].end - o[j].end).abs());
            }
        }
        unpaired += r.len() - pairs.len();
        total_ref += r.len();
    }
    let aligned = ids.len() - failed.len();
    let (pm, p90) = quantiles(&mut phone_d);
    let (wm, w90) = quantiles(&mut word_d);
    let (wsm, _) = quantiles(&mut word_start_d);
    let (wem, _) = quantiles(&mut word_end_d);
    println!(
        "GRID s1 (recorded speech), {} clips, {:.0} s of audio; {} aligned, {} failed",
        ids.len(),
        audio_seconds,
        aligned,
        failed.len()
    );
    for f in &failed {
        println!("  failed: {f}");
    }
    println!(
        "phones vs phones/ (pocketsphinx): {} boundaries ({} clips chose another pronunciation somewhere; {} of {} reference phones unpaired): median |Δ| {:.1} ms, 90th pct {:.1} ms, {:.1} % ≤ 10 ms, {:.1} % ≤ 20 ms, {:.1} % ≤ 40 ms",
        phone_d.len(),
        mismatched,
        unpaired,
        total_ref,
        pm * 1e3,
        p90 * 1e3,
        within(&phone_d, 10.0),
        within(&phone_d, 20.0),
        within(&phone_d, 40.0)
    );
    println!(
        "words vs align/ (corpus): {} boundaries: median |Δ| {:.1} ms (starts {:.1}, ends {:.1}), 90th pct {:.1} ms, {:.1} % ≤ 40 ms, {:.1} % ≤ 80 ms",
        word_d.len(),
        wm * 1e3,
        wsm * 1e3,
        wem * 1e3,
        w90 * 1e3,
        within(&word_d, 40.0),
        within(&word_d, 80.0)
    );
    println!(
        "speed (one thread): model load {load_ms:.0} ms; {:.2} ms per clip, {:.0}× real time",
        align_seconds * 1e3 / ids.len() as f64,
        audio_seconds / align_seconds
    );
    // pocketsphinx on the same WAVs, in this run.
    let list = wav_dir.path().join("list.tsv");
    std::fs::write(&list, texts.join("\n")).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/pocketsphinx_align.py");
    match Command::new("python3")
        .arg(&script)
        .arg(wav_dir.path())
        .arg(&list)
        .output()
    {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            print!("{text}");
            if let Some(ms) = text
                .lines()
                .find_map(|l| l.strip_prefix("pocketsphinx ms per clip: "))
                .and_then(|v| v.trim().parse::<f64>().ok())
            {
                println!(
                    "ratio: facespace is {:.1}× as fast as pocketsphinx per clip",
                    ms / (align_seconds * 1e3 / ids.len() as f64)
                );
            }
        }
        Ok(out) => println!(
            "pocketsphinx not measured: {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ),
        Err(e) => println!("pocketsphinx not measured: {e}"),
    }
}
