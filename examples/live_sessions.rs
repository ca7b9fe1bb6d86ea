//! Many live sessions on one talker (issue 35): N sessions, each fed a committed GRID s1 clip's
//! sound in 20 ms chunks at 48 kHz, round-robin as a server would, on one thread; reports the
//! peak resident memory before and after, per session, and the real-time factor of them all
//! together (≥ 1: the thread keeps up with N speakers; rendering not included).
//!
//! Then 1 000 idle sessions (each has taken one chunk, as a page that opened and went quiet)
//! and the memory they hold.
//!
//! `cargo run --release --example live_sessions -- [N…]` (default 1 10 100)

use std::path::Path;

use facespace::live::Session;
use facespace::talker::Talker;

/// Resident set size now, kB (Linux).
fn rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn main() {
    let counts: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|n| n.parse().ok())
        .collect();
    let counts = if counts.is_empty() {
        vec![1, 10, 100]
    } else {
        counts
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let before = rss_kb();
    let talker = Talker::load(&root.join("models/grid")).unwrap();
    // The recogniser's model and dictionary load with the first session; count them here.
    let mut warm = Session::new(&talker);
    warm.push_audio(&[0.0; 960], 48_000).unwrap();
    drop(warm);
    let loaded = rss_kb();
    let sound = facespace::audio::read(&root.join("tests/data/grid/bbbs7a.wav"), 48_000, 600.0).unwrap();
    println!(
        "talker and recogniser loaded: {:.0} MB resident (process before: {:.0} MB)\n",
        loaded as f64 / 1024.0,
        before as f64 / 1024.0
    );
    println!("| sessions | resident after, MB | per session, MB | frames out | × real time, all together, one thread |");
    println!("|---|---|---|---|---|");
    for n in counts {
        let at_start = rss_kb();
        let mut sessions: Vec<Session<'_>> = (0..n).map(|_| Session::new(&talker)).collect();
        let mut frames = 0;
        let clock = std::time::Instant::now();
        for chunk in sound.samples.chunks(960) {
            for s in sessions.iter_mut() {
                s.push_audio(chunk, 48_000).unwrap();
                frames += s.pull().unwrap().len();
            }
        }
        for s in sessions.iter_mut() {
            frames += s.finish().unwrap().len();
        }
        let took = clock.elapsed().as_secs_f64();
        let resident = rss_kb();
        println!(
            "| {n} | {:.0} | {:.2} | {frames} | {:.1}× |",
            resident as f64 / 1024.0,
            resident.saturating_sub(at_start) as f64 / 1024.0 / n as f64,
            n as f64 * sound.seconds() / took
        );
    }
    let at_start = rss_kb();
    let mut idle: Vec<Session<'_>> = (0..1000).map(|_| Session::new(&talker)).collect();
    for s in idle.iter_mut() {
        s.push_audio(&sound.samples[..960], 48_000).unwrap();
        s.pull().unwrap();
    }
    let resident = rss_kb();
    println!(
        "\n1 000 idle sessions: {:.0} MB resident, {:.0} kB each",
        resident as f64 / 1024.0,
        resident.saturating_sub(at_start) as f64 / 1000.0
    );
    drop(idle);
}
