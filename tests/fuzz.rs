//! Every reader on mutated inputs (issue 17): seeded byte- and number-level mutations of real
//! files — bit flips, "interesting" bytes and 32-bit sizes, cut, inserted and duplicated
//! ranges, truncation, numbers in text swapped for extremes — must give `Ok` or a typed error:
//! no panic, no hang (each case has a time limit), bounded memory (the process's peak RSS
//! stays under 1 GB).
//!
//! `cargo test --release --test fuzz` runs a short budget per reader (CI). The long run of
//! RELIABILITY.md: `FACESPACE_FUZZ_SECONDS=600 cargo test --release --test fuzz -- --test-threads 1`
//! (`FACESPACE_FUZZ_READER=mp4` for one reader, `FACESPACE_FUZZ_START=N` to begin at case N). A failing case is kept under
//! `target/fuzz-failures/READER-SEED/` to replay.
mod common;

use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock, mpsc};
use std::time::{Duration, Instant};

use facespace::codebook::{Codebook, SimilarityOptions};
use facespace::codec::{Clip, EncodeOptions};
use facespace::model::FaceModel;
use facespace::phonemes::PhoneMap;
use facespace::rng::Rng;
use facespace::video::Source;

/// A case slower than this is a hang.
const CASE_LIMIT: Duration = Duration::from_secs(5);
/// Peak resident memory allowed for the whole process, bytes.
const MEMORY_LIMIT: u64 = 1 << 30;

type Reader = Arc<dyn Fn(&Path) -> Result<(), String> + Send + Sync>;
/// One audio reader, as `found_cases_are_errors` runs them.
type ReadAudio = dyn Fn(&Path) -> Result<(), String>;

/// A reader and the files it is fuzzed on: the seed folder's files are copied into each case's
/// folder and one of `mutable` is mutated.
struct Target {
    name: &'static str,
    seed: PathBuf,
    mutable: Vec<&'static str>,
    read: Reader,
}

fn budget() -> (Duration, usize) {
    let seconds = std::env::var("FACESPACE_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok());
    match seconds {
        Some(s) => (Duration::from_secs_f64(s), usize::MAX),
        None => (Duration::from_secs(3), 400),
    }
}

/// The first case (`FACESPACE_FUZZ_START`, default 0): a long run can go on past the cases
/// an earlier one covered.
fn first_case() -> u64 {
    std::env::var("FACESPACE_FUZZ_START")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0)
}

const NUMBERS: [&str; 16] = [
    "0",
    "-1",
    "1e308",
    "-1e308",
    "1e-320",
    "NaN",
    "inf",
    "4294967295",
    "4294967296",
    "18446744073709551615",
    "9223372036854775807",
    "99999999999999",
    "-0",
    "65536",
    "1.5",
    "\"x\"",
];

const SIZES: [u32; 8] = [
    0,
    1,
    7,
    8,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    0xffff_fff8,
];

/// One to three mutations of `bytes`.
fn mutate(bytes: &mut Vec<u8>, rng: &mut Rng) {
    let pick = |rng: &mut Rng, n: usize| (rng.next_u64() % n.max(1) as u64) as usize;
    for _ in 0..1 + pick(rng, 3) {
        let len = bytes.len();
        match pick(rng, 8) {
            0 if len > 0 => {
                for _ in 0..1 + pick(rng, 4) {
                    let i = pick(rng, len);
                    bytes[i] ^= 1 << pick(rng, 8);
                }
            }
            1 if len > 0 => {
                let i = pick(rng, len);
                bytes[i] = [0, 0xff, 0x7f, 0x80, b'\n', b'-', b'.', 0xc3][pick(rng, 8)];
            }
            2 if len > 0 => {
                let i = pick(rng, len);
                let n = (1 + pick(rng, 16)).min(len - i);
                bytes.drain(i..i + n);
            }
            3 => {
                let i = pick(rng, len + 1);
                let n = 1 + pick(rng, 16);
                let insert: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                bytes.splice(i..i, insert);
            }
            4 if len > 0 => {
                let i = pick(rng, len);
                let n = (1 + pick(rng, 64)).min(len - i);
                let copy = bytes[i..i + n].to_vec();
                let at = pick(rng, len + 1);
                bytes.splice(at..at, copy);
            }
            5 if len > 0 => bytes.truncate(pick(rng, len)),
            6 if len >= 4 => {
                let i = pick(rng, len - 3);
                let v = SIZES[pick(rng, SIZES.len())];
                bytes[i..i + 4].copy_from_slice(&v.to_be_bytes());
            }
            _ => {
                // A run of digits (with sign, point, exponent) replaced by an extreme.
                let starts: Vec<usize> = (0..len)
                    .filter(|&i| {
                        bytes[i].is_ascii_digit() && (i == 0 || !bytes[i - 1].is_ascii_digit())
                    })
                    .collect();
                if starts.is_empty() {
                    continue;
                }
                let s = starts[pick(rng, starts.len())];
                let mut e = s;
                while e < len && (bytes[e].is_ascii_digit() || b".eE+-".contains(&bytes[e])) {
                    e += 1;
                }
                let n = NUMBERS[pick(rng, NUMBERS.len())].as_bytes().to_vec();
                bytes.splice(s..e, n);
            }
        }
    }
}

fn peak_rss() -> u64 {
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage fills the struct it is given.
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    usage.ru_maxrss as u64 * 1024
}

/// Runs `target` on mutated cases for the budget; panics naming the first case that panics,
/// hangs or pushes the peak memory over the limit (kept under target/fuzz-failures/).
fn fuzz(target: Target) {
    if let Ok(only) = std::env::var("FACESPACE_FUZZ_READER")
        && only != target.name
    {
        return;
    }
    // The unmutated seed must read: otherwise the cases test nothing.
    (target.read)(&target.seed)
        .unwrap_or_else(|e| panic!("{}: the seed does not read: {e}", target.name));
    let (time, max_cases) = budget();
    let start = Instant::now();
    let work = tempfile::tempdir().unwrap();
    let (mut cases, mut errors) = (0usize, 0usize);
    while cases < max_cases && start.elapsed() < time {
        let seed = 0x5eed_0000 + first_case() + cases as u64;
        let mut rng = Rng::new(seed);
        let dir = work.path().join(format!("case{cases}"));
        common::copy_tree(&target.seed, &dir);
        let file =
            dir.join(target.mutable[(rng.next_u64() % target.mutable.len() as u64) as usize]);
        let mut bytes = std::fs::read(&file).unwrap();
        mutate(&mut bytes, &mut rng);
        std::fs::write(&file, &bytes).unwrap();
        let (tx, rx) = mpsc::channel();
        let read = target.read.clone();
        let case_dir = dir.clone();
        std::thread::spawn(move || {
            let outcome =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read(&case_dir)));
            let _ = tx.send(outcome);
        });
        let failure = match rx.recv_timeout(CASE_LIMIT) {
            Ok(Ok(Ok(()))) => None,
            Ok(Ok(Err(_))) => {
                errors += 1;
                None
            }
            Ok(Err(_)) => Some("panicked"),
            Err(_) => Some("hung"),
        };
        let failure = failure.or((peak_rss() > MEMORY_LIMIT).then_some("went over 1 GB"));
        if let Some(what) = failure {
            let keep = common::root()
                .join("target/fuzz-failures")
                .join(format!("{}-{seed:x}", target.name));
            let _ = std::fs::remove_dir_all(&keep);
            common::copy_tree(&dir, &keep);
            panic!(
                "{}: case {cases} (seed {seed:#x}) {what}; kept in {}",
                target.name,
                keep.display()
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
        cases += 1;
    }
    eprintln!(
        "{}: {cases} cases in {:.1} s, {errors} typed errors, 0 panics, 0 hangs; peak RSS {} MB",
        target.name,
        start.elapsed().as_secs_f64(),
        peak_rss() >> 20
    );
}

/// A seed folder holding copies of `files` (paths from the repository root).
fn seed_of(files: &[&str]) -> PathBuf {
    let dir = tempfile::tempdir().unwrap().keep();
    for f in files {
        let from = common::root().join(f);
        std::fs::copy(&from, dir.join(from.file_name().unwrap())).unwrap();
    }
    dir
}

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

fn demo_model() -> &'static FaceModel {
    static MODEL: OnceLock<FaceModel> = OnceLock::new();
    MODEL.get_or_init(|| FaceModel::load(&common::root().join("models/demo/model")).unwrap())
}

/// A reader of one file, `leaf`, in the seed folder.
fn file_target(
    name: &'static str,
    seed: PathBuf,
    leaf: &'static str,
    read: fn(&Path) -> Result<(), String>,
) -> Target {
    Target {
        name,
        seed,
        mutable: vec![leaf],
        read: Arc::new(move |d| read(&d.join(leaf))),
    }
}

fn landmarks(p: &Path) -> Result<(), String> {
    facespace::shape::read_landmarks(p).map(|_| ()).map_err(err)
}

fn labels(p: &Path) -> Result<(), String> {
    facespace::phonemes::read_labels(p, None, &PhoneMap::default())
        .map(|_| ())
        .map_err(err)
}

#[test]
fn fuzz_pts() {
    let seed = seed_of(&["tests/data/clip/01000.pts"]);
    fuzz(file_target("pts", seed, "01000.pts", landmarks));
}

#[test]
fn fuzz_ljson() {
    let seed = seed_of(&["tests/data/lenna.ljson"]);
    fuzz(file_target("ljson", seed, "lenna.ljson", landmarks));
}

#[test]
fn fuzz_lab() {
    let seed = seed_of(&["tests/data/labels/hvite_hello.lab"]);
    fuzz(file_target("lab", seed, "hvite_hello.lab", labels));
}

#[test]
fn fuzz_textgrid_long() {
    let seed = seed_of(&["tests/data/labels/mfa_hello_world.TextGrid"]);
    fuzz(file_target(
        "textgrid",
        seed,
        "mfa_hello_world.TextGrid",
        labels,
    ));
}

#[test]
fn fuzz_textgrid_short() {
    let seed = seed_of(&["tests/data/labels/praat_short.TextGrid"]);
    fuzz(file_target(
        "textgrid-short",
        seed,
        "praat_short.TextGrid",
        labels,
    ));
}

#[test]
fn fuzz_tsv() {
    let seed = tempfile::tempdir().unwrap().keep();
    std::fs::write(
        seed.join("a.tsv"),
        "0.00\t0.12\tsil\n0.12\t0.31\tHH\n0.31\t0.52\tAH0\n0.52\t0.80\tL\n0.80\t1.1\tsil\n",
    )
    .unwrap();
    fuzz(file_target("tsv", seed, "a.tsv", labels));
}

#[test]
fn fuzz_npy() {
    let seed = tempfile::tempdir().unwrap().keep();
    let a = ndarray::Array2::<f32>::from_shape_fn((7, 5), |(i, j)| (i * 5 + j) as f32 * 0.5 - 3.0);
    facespace::npy::write(&seed.join("a.npy"), a.view()).unwrap();
    fuzz(Target {
        name: "npy",
        seed,
        mutable: vec!["a.npy"],
        read: Arc::new(|d| {
            facespace::npy::read_checked::<f32, ndarray::Ix2>(&d.join("a.npy"), &[None, None])
                .map(|_| ())
                .map_err(err)
        }),
    });
}

#[test]
fn fuzz_model_folder() {
    let seed = tempfile::tempdir().unwrap().keep().join("model");
    common::small_model().save(&seed).unwrap();
    fuzz(Target {
        name: "model",
        seed,
        mutable: vec![
            "model.json",
            "model.json",
            "model.json",
            "shape_variances.npy",
            "shape_mean.npy",
            "mask.npy",
            "appearance_variances.npy",
        ],
        read: Arc::new(|d| FaceModel::load(d).map(|_| ()).map_err(err)),
    });
}

/// A talker folder (issue 69): its manifest (settings, part names), its footage's and its
/// codebook's manifests mutated; every load is a talker or a typed error.
#[test]
fn fuzz_talker_folder() {
    let work = tempfile::tempdir().unwrap().keep();
    let seed = work.join("talker");
    let rec = work.join("rec");
    std::fs::create_dir(&rec).unwrap();
    for name in ["bbbf9a.mp4", "bbbf9a.txt", "bbbs7a.mp4", "bbbs7a.txt"] {
        std::fs::copy(common::root().join("tests/data/grid").join(name), rec.join(name)).unwrap();
    }
    let recordings = facespace::talker::build::Recordings {
        model: common::root().join("models/grid/model"),
        dir: rec,
        footage_clips: 1,
    };
    let parts = facespace::talker::build::parts_from_recordings(&recordings, &seed, facespace::no_progress).unwrap();
    let identity = facespace::talker::build::Identity {
        name: "fuzz".into(),
        settings: facespace::talker::Settings {
            mode: facespace::talker::Mode::Blend,
            top_n: 5,
            context: 1,
            smoothing: 3e-5,
            appearance_gain: 1.0,
            chosen_on: "given".into(),
        },
        voice: None,
        recordings: "two GRID s1 test clips".into(),
    };
    let parts = facespace::talker::build::Parts { mouths_from: None, ..parts };
    facespace::talker::build::build(&identity, &parts, &seed, facespace::no_progress).unwrap();
    std::fs::remove_dir_all(seed.join("corpus")).unwrap();
    fuzz(Target {
        name: "talker",
        seed,
        mutable: vec!["talker.json", "talker.json", "talker.json", "footage/footage.json", "codebook/codebook.json"],
        read: Arc::new(|d| facespace::talker::Talker::load(d).map(|_| ()).map_err(err)),
    });
}

#[test]
fn fuzz_codebook_folder() {
    let model = demo_model();
    let frames =
        facespace::model::load_training_set(&common::root().join("models/demo/training"), None)
            .unwrap();
    let corpus = facespace::corpus::demo::generate(model, &frames, &Default::default()).unwrap();
    let mut train = corpus.part(facespace::corpus::demo::Split::Train);
    train.truncate(3);
    let cb = Codebook::build(
        train,
        25.0,
        model.layout(),
        Some(model.hash()),
        SimilarityOptions::default(),
        &mut facespace::no_progress,
    )
    .unwrap();
    let seed = tempfile::tempdir().unwrap().keep().join("cb");
    cb.save(&seed).unwrap();
    fuzz(Target {
        name: "codebook",
        seed,
        mutable: vec![
            "codebook.json",
            "codebook.json",
            "codebook.json",
            "sentence_0000.npy",
            "similarity.npy",
        ],
        read: Arc::new(|d| Codebook::load(d).map(|_| ()).map_err(err)),
    });
}

#[test]
fn fuzz_clip_folder() {
    let model = demo_model();
    let options = EncodeOptions {
        init: Some(
            facespace::shape::read_pts(&common::root().join("tests/data/clip/01000.pts")).unwrap(),
        ),
        bits: Some(8),
        ..EncodeOptions::default()
    };
    let source = Source::open(&common::root().join("tests/data/clip")).unwrap();
    let clip = facespace::codec::encode(model, source, &options, facespace::no_progress)
        .unwrap()
        .clip;
    let seed = tempfile::tempdir().unwrap().keep().join("clip.fsp");
    clip.save(&seed, None).unwrap();
    let params = std::fs::read_dir(&seed)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .find(|n| n.starts_with("params"))
        .unwrap();
    let params: &'static str = Box::leak(params.into_boxed_str());
    fuzz(Target {
        name: "clip",
        seed,
        mutable: vec![
            "meta.json",
            "meta.json",
            "meta.json",
            params,
            "tracking.npy",
        ],
        read: Arc::new(|d| Clip::load(d, demo_model()).map(|_| ()).map_err(err)),
    });
}

/// Opens a video and decodes up to 12 frames.
fn decode_some(path: &Path) -> Result<(), String> {
    let mut source = Source::open(path).map_err(err)?;
    for _ in 0..12 {
        if source.next_frame().map_err(err)?.is_none() {
            break;
        }
    }
    Ok(())
}

#[test]
fn fuzz_mp4() {
    fuzz(Target {
        name: "mp4",
        seed: seed_of(&["tests/data/video/high_bframes_aac.mp4"]),
        mutable: vec!["high_bframes_aac.mp4"],
        read: Arc::new(|d| decode_some(&d.join("high_bframes_aac.mp4"))),
    });
}

#[test]
fn fuzz_y4m() {
    let seed = tempfile::tempdir().unwrap().keep();
    let mut sink = facespace::video::Sink::create(&seed.join("a.y4m"), 16, 12, 25.0, None).unwrap();
    for i in 0..3u8 {
        sink.write(&image::RgbImage::from_fn(16, 12, |x, y| {
            image::Rgb([x as u8 * 9, y as u8 * 11, i * 40])
        }))
        .unwrap();
    }
    sink.finish().unwrap();
    fuzz(Target {
        name: "y4m",
        seed,
        mutable: vec!["a.y4m"],
        read: Arc::new(|d| decode_some(&d.join("a.y4m"))),
    });
}

#[test]
fn fuzz_study_folder() {
    use facespace::study::{Condition, FORMAT, Manifest, Stimulus, Task, Trial, VERSION, Viewer};
    let stimuli: Vec<Stimulus> = ["original", "smoothed"]
        .iter()
        .enumerate()
        .map(|(i, c)| Stimulus {
            id: format!("a{i}"),
            sentence: "s".into(),
            condition: c.parse::<Condition>().unwrap(),
            frames: 25,
            audio: false,
        })
        .collect();
    let trials = vec![
        Trial::Judge {
            stimulus: "a0".into(),
        },
        Trial::Rate {
            first: "a0".into(),
            second: "a1".into(),
        },
        Trial::Rate {
            first: "a1".into(),
            second: "a0".into(),
        },
    ];
    let manifest = Manifest {
        format: FORMAT.into(),
        version: VERSION,
        task: Task::Both,
        conditions: stimuli.iter().map(|s| s.condition).collect(),
        pairs: vec![(Condition::Original, Condition::Smoothed)],
        sentences: vec!["s".into()],
        smoothing: 3e-6,
        seed: 1,
        fps: 25.0,
        model_hash: "h".into(),
        stimuli,
        canvas: [64, 64],
        over_recordings: false,
        viewers: vec![Viewer {
            id: "v01".into(),
            token: "0123456789abcdef".into(),
            trials,
        }],
    };
    let seed = tempfile::tempdir().unwrap().keep();
    std::fs::write(
        seed.join("study.json"),
        serde_json::to_vec_pretty(&manifest).unwrap(),
    )
    .unwrap();
    std::fs::write(
        seed.join("answers.jsonl"),
        "{\"viewer\":\"v01\",\"trial\":0,\"stimuli\":[\"a0\"],\"real\":true,\"at\":1.0}\n\
         {\"viewer\":\"v01\",\"trial\":1,\"stimuli\":[\"a0\",\"a1\"],\"scores\":[12,40.5],\"at\":2.0}\n",
    )
    .unwrap();
    fuzz(Target {
        name: "study",
        seed,
        mutable: vec!["study.json", "answers.jsonl"],
        read: Arc::new(|d| {
            let m = Manifest::load(d).map_err(err)?;
            let (answers, _) = facespace::study::answers::read(d, &m).map_err(err)?;
            let report = facespace::study::analyse::report(&m, &answers);
            report.markdown();
            Ok(())
        }),
    });
}

/// Every audio reader on `path`: the samples at the aligner's rate, the native samples, the
/// duration (header or a count without samples).
fn audio_all(path: &Path) -> Result<(), String> {
    facespace::audio::read(path, 16_000, 600.0).map_err(err)?;
    facespace::audio::read_native(path, 600.0).map_err(err)?;
    facespace::audio::duration(path, 600.0).map_err(err)?;
    Ok(())
}

#[test]
fn fuzz_wav() {
    let seed = seed_of(&["tests/data/grid/bbbf9a.wav"]);
    fuzz(file_target("wav", seed, "bbbf9a.wav", audio_all));
}

#[test]
fn fuzz_m4a() {
    let seed = seed_of(&["tests/data/grid/bbbf9a.mp4"]);
    fuzz(Target {
        name: "m4a",
        seed,
        mutable: vec!["bbbf9a.mp4"],
        read: Arc::new(|d| {
            // The same bytes as an MP4 and as an M4A (the extension picks the probe's hint).
            let m4a = d.join("bbbf9a.m4a");
            std::fs::copy(d.join("bbbf9a.mp4"), &m4a).map_err(err)?;
            let mp4 = audio_all(&d.join("bbbf9a.mp4"));
            audio_all(&m4a).and(mp4)
        }),
    });
}

/// The cases the long runs found, kept in `tests/data/fuzz/` (named `READER-what.ext`; an
/// `audio-` case goes to the audio readers, the rest to the video readers): each must now be
/// a typed error within the time limit.
#[test]
fn found_cases_are_errors() {
    let dir = common::root().join("tests/data/fuzz");
    let mut found = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let path = e.unwrap().path();
        let (tx, rx) = mpsc::channel();
        let p = path.clone();
        let audio = p
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with("audio-"));
        std::thread::spawn(move || {
            let _ = tx.send(if audio {
                // Each reader alone must refuse it.
                let readers: [&ReadAudio; 3] = [
                    &|p| {
                        facespace::audio::read(p, 16_000, 600.0)
                            .map(|_| ())
                            .map_err(err)
                    },
                    &|p| {
                        facespace::audio::read_native(p, 600.0)
                            .map(|_| ())
                            .map_err(err)
                    },
                    &|p| {
                        facespace::audio::duration(p, 600.0)
                            .map(|_| ())
                            .map_err(err)
                    },
                ];
                match readers.iter().map(|r| r(&p)).find(|r| r.is_ok()) {
                    Some(ok) => ok,
                    None => Err("refused by every audio reader".into()),
                }
            } else {
                decode_some(&p)
            });
        });
        let outcome = rx.recv_timeout(CASE_LIMIT);
        assert!(
            matches!(outcome, Ok(Err(_))),
            "{}: {outcome:?}",
            path.display()
        );
        found += 1;
    }
    assert!(found >= 1);
}
