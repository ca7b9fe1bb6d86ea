//! The subjective-study kit (issue 16): its statistics against scipy, the answer log's
//! refusals and crash safety, and the whole study in a headless browser.
use crate::common;

use facespace::study::stats;
use serde_json::Value;

fn reference() -> Value {
    let path = common::root().join("tests/data/stats_scipy.json");
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

/// scipy's `wilcoxon(x, y)` (defaults) on every branch of its method choice: exact, sign-flip
/// permutation with ties or zeros, the normal approximation with the tie correction.
#[test]
fn wilcoxon_matches_scipy() {
    let cases = reference()["wilcoxon"].as_array().unwrap().clone();
    assert!(cases.len() >= 12);
    let mut methods = std::collections::BTreeSet::new();
    for c in cases {
        let r = stats::wilcoxon(&floats(&c["x"]), &floats(&c["y"])).unwrap();
        let (w, p) = (
            c["statistic"].as_f64().unwrap(),
            c["pvalue"].as_f64().unwrap(),
        );
        assert!(close(r.w, w, 1e-12), "{}: W {} vs {w}", c["name"], r.w);
        assert!(
            close(r.p, p, 1e-9),
            "{}: p {} vs {p} ({})",
            c["name"],
            r.p,
            r.method
        );
        methods.insert(r.method);
    }
    assert_eq!(methods.len(), 3, "{methods:?}");
}

/// scipy's `kruskal`, ties included.
#[test]
fn kruskal_matches_scipy() {
    for c in reference()["kruskal"].as_array().unwrap() {
        let groups: Vec<Vec<f64>> = c["groups"].as_array().unwrap().iter().map(floats).collect();
        let r = stats::kruskal(&groups).unwrap();
        let (h, p) = (
            c["statistic"].as_f64().unwrap(),
            c["pvalue"].as_f64().unwrap(),
        );
        assert!(close(r.h, h, 1e-10), "{}: H {} vs {h}", c["name"], r.h);
        assert!(close(r.p, p, 1e-8), "{}: p {} vs {p}", c["name"], r.p);
        // Mean ranks average to (N + 1) / 2, weighted by group size.
        let n: usize = r.groups.iter().map(|g| g.n).sum();
        let mean: f64 = r
            .groups
            .iter()
            .map(|g| g.mean_rank * g.n as f64)
            .sum::<f64>()
            / n as f64;
        assert!(close(mean, (n as f64 + 1.0) / 2.0, 1e-12));
    }
}

/// scipy's `binomtest(k, n)` and its exact (Clopper–Pearson) 95 % interval.
#[test]
fn binomial_matches_scipy() {
    for c in reference()["binomtest"].as_array().unwrap() {
        let (k, n) = (
            c["k"].as_u64().unwrap() as usize,
            c["n"].as_u64().unwrap() as usize,
        );
        let r = stats::binomial(k, n).unwrap();
        for (got, key) in [(r.p, "pvalue"), (r.low, "low"), (r.high, "high")] {
            let want = c[key].as_f64().unwrap();
            assert!(close(got, want, 1e-9), "{k}/{n} {key}: {got} vs {want}");
        }
    }
    assert!(stats::binomial(3, 2).is_none() && stats::binomial(0, 0).is_none());
}

// ---------------------------------------------------------------------------------------
// The study folder: design, answer log, refusals, crash safety, the browser.

use common::http;
use std::path::Path;

use facespace::codebook::Codebook;
use facespace::corpus::demo::Split;
use facespace::model::FaceModel;
use facespace::render::CpuRenderer;
use facespace::rng::Rng;
use facespace::study::create::{Heldout, pairs, trials};
use facespace::study::{
    ANSWERS, AnswerLog, Condition, CreateOptions, Manifest, Response, StudyError, Task, Trial,
};

fn conditions(s: &str) -> Vec<Condition> {
    s.split(',').map(|c| c.parse().unwrap()).collect()
}

/// A study of one held-out demo sentence (the codebook from the demo corpus's training split)
/// with `viewers` viewers, written to `dir`.
fn make_study(dir: &Path, conds: &str, viewers: usize, task: Task) -> Manifest {
    make_study_with(dir, conds, viewers, task, None, CLIP_SECONDS)
}

/// [`make_study`] with the sentence's sound and cut after `seconds` of phones.
fn make_study_with(
    dir: &Path,
    conds: &str,
    viewers: usize,
    task: Task,
    audio: Option<&Path>,
    seconds: f64,
) -> Manifest {
    let (model, cb, mut heldout) = fixture_cut(seconds);
    for h in &mut heldout {
        h.audio = audio.map(Path::to_path_buf);
    }
    create(dir, &model, &cb, &heldout, conds, viewers, task).unwrap()
}

/// Seconds of phones a study's sentence is cut after: longer than
/// [`facespace::study::answers::ANSWER_SLACK_SECONDS`], so that an answer can be too fast.
const CLIP_SECONDS: f64 = 0.8;

/// The demo model, a codebook of the demo corpus's training split, one test sentence cut
/// after its first [`CLIP_SECONDS`] of phones.
fn fixture() -> (FaceModel, Codebook, Vec<Heldout>) {
    fixture_cut(CLIP_SECONDS)
}

/// [`fixture`] with the sentence cut after `seconds` of phones.
fn fixture_cut(seconds: f64) -> (FaceModel, Codebook, Vec<Heldout>) {
    let (model, generated, cb) = common::demo_corpus_codebook();
    let mut test = generated.part(Split::Test);
    test.truncate(1);
    for sentence in &mut test {
        let keep = 1 + sentence.segments.iter().position(|s| s.end >= seconds).unwrap();
        sentence.segments.truncate(keep);
        let end = sentence.segments[keep - 1].end;
        let fps = facespace::corpus::demo::CorpusOptions::default().fps;
        let frames = ((end * fps).round() as usize).min(sentence.frames.len());
        sentence.frames = sentence.frames.slice(0..frames);
    }
    let heldout = test
        .into_iter()
        .map(|sentence| Heldout {
            sentence,
            audio: None,
            video: None,
        })
        .collect();
    (model, cb, heldout)
}

fn create(
    dir: &Path,
    model: &FaceModel,
    cb: &Codebook,
    heldout: &[Heldout],
    conds: &str,
    viewers: usize,
    task: Task,
) -> Result<Manifest, StudyError> {
    let options = CreateOptions {
        conditions: conditions(conds),
        viewers,
        task,
        smoothing: facespace::synth::DEFAULT_SMOOTHING,
        unit: Default::default(),
        seed: 16,
    };
    facespace::study::create(
        dir,
        model,
        cb,
        heldout,
        &CpuRenderer::new(model),
        &options,
        facespace::no_progress,
    )
}

#[test]
fn pairs_put_the_original_against_every_condition_and_smoothing_against_none() {
    let p = pairs(&conditions("original,blend-n3,smoothed,unsmoothed"));
    let name = |(a, b): &(Condition, Condition)| format!("{a}/{b}");
    let names: Vec<String> = p.iter().map(name).collect();
    assert_eq!(
        names,
        [
            "original/blend-n3",
            "original/smoothed",
            "original/unsmoothed",
            "smoothed/unsmoothed"
        ]
    );
    // Without the original, the first condition is the reference.
    let names: Vec<String> = pairs(&conditions("smoothed,unsmoothed,unit"))
        .iter()
        .map(name)
        .collect();
    assert_eq!(names, ["smoothed/unsmoothed", "smoothed/unit"]);
}

/// Every viewer sees every stimulus once in the Turing block (first), every sentence × pair in
/// both orders in the rating block, never a pair right after its mirror, in an order of
/// their own.
#[test]
fn each_viewer_gets_a_counterbalanced_order_of_their_own() {
    let conds = conditions("original,blend-n1,random-lips,smoothed,unsmoothed");
    let sentences: Vec<String> = (0..3).map(|i| format!("s{i}")).collect();
    let stimuli: Vec<facespace::study::Stimulus> = sentences
        .iter()
        .flat_map(|s| conds.iter().map(move |&c| (s.clone(), c)))
        .enumerate()
        .map(|(i, (sentence, condition))| facespace::study::Stimulus {
            id: format!("id{i}"),
            sentence,
            condition,
            frames: 10,
            audio: false,
        })
        .collect();
    let p = pairs(&conds);
    let mut rng = Rng::new(1);
    let a = trials(&stimuli, &sentences, &p, Task::Both, &mut rng);
    let b = trials(&stimuli, &sentences, &p, Task::Both, &mut rng);
    assert_ne!(a, b, "two viewers, two orders");
    for t in [&a, &b] {
        let judged: Vec<&str> = t[..stimuli.len()]
            .iter()
            .map(|x| match x {
                Trial::Judge { stimulus } => stimulus.as_str(),
                Trial::Rate { .. } => panic!("the Turing block comes first"),
            })
            .collect();
        let mut sorted = judged.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), stimuli.len());
        let rated = &t[stimuli.len()..];
        assert_eq!(rated.len(), sentences.len() * p.len() * 2);
        for x in rated {
            let Trial::Rate { first, second } = x else {
                panic!("judge trial in the rating block")
            };
            let mirror = Trial::Rate {
                first: second.clone(),
                second: first.clone(),
            };
            assert_eq!(rated.iter().filter(|y| **y == mirror).count(), 1);
        }
        for w in rated.windows(2) {
            let (mut x, mut y) = (w[0].stimuli(), w[1].stimuli());
            x.sort();
            y.sort();
            assert_ne!(x, y, "a pair right after its mirror");
        }
    }
}

/// Every clip of every viewer as fetched a minute ago: answers then meet the server's
/// played-through rule (tested on its own in `answers_faster_than_the_clips_are_refused`).
fn watched(log: &mut AnswerLog, manifest: &Manifest) {
    let then = std::time::Instant::now()
        .checked_sub(std::time::Duration::from_secs(60))
        .unwrap();
    for v in &manifest.viewers {
        for t in &v.trials {
            for id in t.stimuli() {
                log.fetched_at(&v.id, &v.token, id, then).unwrap();
            }
        }
    }
}

fn submit(log: &mut AnswerLog, body: serde_json::Value) -> Result<usize, (u16, String)> {
    log.submit(&body.to_string())
        .map(|a| a.trial)
        .map_err(|r| (r.status, r.message))
}

/// Forged, replayed, skipped and out-of-range submissions are refused with a reason and
/// store nothing; good ones are stored in order and survive reopening.
#[test]
fn the_answer_log_refuses_bad_submissions_and_stores_nothing_for_them() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = make_study(&study, "original,smoothed,unsmoothed", 2, Task::Both);
    let (v1, v2) = (&manifest.viewers[0], &manifest.viewers[1]);
    let (mut log, note) = AnswerLog::open(&study, manifest.clone()).unwrap();
    watched(&mut log, &manifest);
    assert!(note.is_none());
    let first_rate = v1
        .trials
        .iter()
        .position(|t| matches!(t, Trial::Rate { .. }))
        .unwrap();
    let body = |trial: usize, extra: serde_json::Value| {
        let mut b = serde_json::json!({"viewer": v1.id, "token": v1.token, "trial": trial});
        b.as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        b
    };
    // Answer the judge block, then check refusals on the first rating trial.
    for t in 0..first_rate {
        assert_eq!(
            submit(&mut log, body(t, serde_json::json!({"real": t % 2 == 0}))),
            Ok(t)
        );
    }
    let log_path = study.join(ANSWERS);
    let before = std::fs::read(&log_path).unwrap();
    let cases: Vec<(serde_json::Value, u16, &str)> = vec![
        (
            body(first_rate, serde_json::json!({"scores": [0, 20]})),
            422,
            "outside the scale",
        ),
        (
            body(first_rate, serde_json::json!({"scores": [20, 51]})),
            422,
            "outside the scale",
        ),
        (
            body(first_rate, serde_json::json!({"scores": [-3.5, 20]})),
            422,
            "outside the scale",
        ),
        (
            body(first_rate, serde_json::json!({"real": true})),
            422,
            "two scores",
        ),
        (
            body(first_rate, serde_json::json!({"scores": ["x", 20]})),
            400,
            "not an answer",
        ),
        (
            body(first_rate, serde_json::json!({"scores": [20]})),
            400,
            "not an answer",
        ),
        (
            body(first_rate, serde_json::json!({})),
            400,
            "not an answer",
        ),
        // A replay of an answered trial, and a skip ahead.
        (
            body(0, serde_json::json!({"real": true})),
            409,
            "already answered",
        ),
        (
            body(first_rate + 1, serde_json::json!({"scores": [20, 20]})),
            409,
            "not the next",
        ),
        // Forged: viewer 1's answer with viewer 2's secret, another viewer's id, no secret.
        (
            serde_json::json!({"viewer": v1.id, "token": v2.token, "trial": first_rate, "scores": [20, 20]}),
            403,
            "wrong secret",
        ),
        (
            serde_json::json!({"viewer": v2.id, "token": v1.token, "trial": 0, "real": true}),
            403,
            "wrong secret",
        ),
        (
            serde_json::json!({"viewer": "v99", "token": v1.token, "trial": 0, "real": true}),
            404,
            "not in this study",
        ),
    ];
    for (b, status, why) in cases {
        let (code, message) = submit(&mut log, b.clone()).unwrap_err();
        assert_eq!(code, status, "{b}: {message}");
        assert!(message.contains(why), "{b}: {message}");
    }
    for raw in [
        "",
        "{",
        "null",
        "[1,2]",
        "{\"viewer\": 1}",
        "{\"scores\": [1e400, 2]}",
    ] {
        assert_eq!(log.submit(raw).unwrap_err().status, 400, "{raw}");
    }
    assert_eq!(
        std::fs::read(&log_path).unwrap(),
        before,
        "a refusal stored something"
    );
    // A good answer, fractional scores at the ends of the scale.
    assert_eq!(
        submit(
            &mut log,
            body(first_rate, serde_json::json!({"scores": [1.0, 50.0]}))
        ),
        Ok(first_rate)
    );
    drop(log);
    let (log, _) = AnswerLog::open(&study, manifest.clone()).unwrap();
    assert_eq!(log.next_trial(&v1.id, &v1.token), Ok(first_rate + 1));
    assert_eq!(log.next_trial(&v2.id, &v2.token), Ok(0));
    assert_eq!(log.next_trial(&v2.id, &v1.token).unwrap_err().status, 403);
}

/// A torn last line (a crash in mid-write, never acknowledged) is left out by the analysis
/// and cut off by the server; a damaged line in the middle is an error naming its line.
#[test]
fn a_torn_last_line_is_dropped_and_a_damaged_log_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = make_study(&study, "original,unsmoothed", 1, Task::Turing);
    let v = &manifest.viewers[0];
    let (mut log, _) = AnswerLog::open(&study, manifest.clone()).unwrap();
    watched(&mut log, &manifest);
    for t in 0..2 {
        let b = serde_json::json!({"viewer": v.id, "token": v.token, "trial": t, "real": true});
        log.submit(&b.to_string()).unwrap();
    }
    drop(log);
    let path = study.join(ANSWERS);
    let whole = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, format!("{whole}{{\"viewer\":\"v01\",\"tri")).unwrap();
    let report = facespace::study::analyse(&study).unwrap();
    assert_eq!(report.answers, 2);
    assert!(
        report.notes.iter().any(|n| n.contains("torn last line")),
        "{:?}",
        report.notes
    );
    let (mut log, note) = AnswerLog::open(&study, manifest.clone()).unwrap();
    watched(&mut log, &manifest);
    assert!(note.is_some());
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        whole,
        "the torn line is cut off"
    );
    // Both trials are answered: a third answer is refused, and the log is whole lines.
    let b = serde_json::json!({"viewer": v.id, "token": v.token, "trial": 2, "real": false});
    let refusal = log.submit(&b.to_string()).unwrap_err();
    assert!(
        refusal.status == 409 && refusal.message.contains("every trial"),
        "{refusal:?}"
    );
    drop(log);
    assert_eq!(facespace::study::analyse(&study).unwrap().answers, 2);
    // A damaged middle line.
    let lines: Vec<&str> = whole.lines().collect();
    std::fs::write(&path, format!("{}\n{{oops\n{}\n", lines[0], lines[1])).unwrap();
    let err = facespace::study::analyse(&study).unwrap_err().to_string();
    assert!(err.contains("answers.jsonl: line 2"), "{err}");
}

/// A sentence with sound gets it muxed into every stimulus — a GRID recording's real sound
/// (recorded speech), decoded back from each stimulus sample for sample at lag 0; a study
/// without answers is not analysed (most likely the wrong folder).
#[test]
fn stimuli_carry_the_sentence_sound_and_an_unanswered_study_is_not_analysed() {
    let dir = tempfile::tempdir().unwrap();
    let sound = dir.path().join("demo.m4a");
    let input = common::root().join("tests/data/grid/bbbf9a.mp4");
    assert!(facespace::video::extract_audio(&input, &sound).unwrap());
    let source = facespace::audio::read(&input, 16_000, 600.0).unwrap();
    let study = dir.path().join("study");
    let manifest = make_study_with(
        &study,
        "original,unsmoothed",
        1,
        Task::Rating,
        Some(&sound),
        CLIP_SECONDS,
    );
    for s in &manifest.stimuli {
        assert!(s.audio);
        let bytes = std::fs::read(study.join("stimuli").join(s.file_name())).unwrap();
        assert!(
            bytes.windows(4).any(|w| w == b"soun"),
            "no sound track in {}",
            s.id
        );
        let heard =
            facespace::audio::read(&study.join("stimuli").join(s.file_name()), 16_000, 600.0)
                .unwrap();
        assert_eq!(heard.samples.len(), source.samples.len(), "{}", s.id);
        // Copied packet for packet with the edit list: the same samples from time 0.
        let diff = heard
            .samples
            .iter()
            .zip(&source.samples)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(diff < 1e-6, "{}: sound differs by {diff}", s.id);
    }
    let err = facespace::study::analyse(&study).unwrap_err().to_string();
    assert!(err.contains("no answers stored yet"), "{err}");
}

/// A study folder of another version, or not a study, is refused with a clear message.
#[test]
fn a_study_of_another_version_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    make_study(&study, "original,smoothed", 1, Task::Rating);
    let path = study.join("study.json");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen("\"version\": 1", "\"version\": 2", 1)).unwrap();
    let err = Manifest::load(&study).unwrap_err().to_string();
    assert!(
        err.contains("version 2") && err.contains("reads version 1"),
        "{err}"
    );
    assert!(facespace::study::StudyServer::bind(&study, "127.0.0.1:0", false).is_err());
    std::fs::write(&path, "{\"format\": \"something else\"}").unwrap();
    let err = Manifest::load(&study).unwrap_err().to_string();
    assert!(err.contains("not a facespace study"), "{err}");
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(Manifest::load(&study), Err(StudyError::Io { .. })));
}

/// Studies that cannot be made are refused before any rendering; a study with answers is
/// never replaced.
#[test]
fn bad_designs_are_refused_and_answers_are_never_overwritten() {
    assert!("blend-n0".parse::<Condition>().is_err());
    assert!(
        "lips"
            .parse::<Condition>()
            .unwrap_err()
            .contains("unknown condition")
    );
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = make_study(&study, "original,smoothed", 1, Task::Turing);
    let v = &manifest.viewers[0];
    let (mut log, _) = AnswerLog::open(&study, manifest.clone()).unwrap();
    watched(&mut log, &manifest);
    let b = serde_json::json!({"viewer": v.id, "token": v.token, "trial": 0, "real": true});
    log.submit(&b.to_string()).unwrap();
    drop(log);
    let answers = std::fs::read(study.join(ANSWERS)).unwrap();
    let (model, cb, heldout) = fixture();
    let again = create(
        &study,
        &model,
        &cb,
        &heldout,
        "original,smoothed",
        1,
        Task::Turing,
    );
    assert!(again.is_err(), "a study holding answers was replaced");
    assert_eq!(std::fs::read(study.join(ANSWERS)).unwrap(), answers);
    // Designs refused before any rendering (the folder is never created).
    let fresh = dir.path().join("fresh");
    for (conds, viewers, task, why) in [
        ("smoothed,unsmoothed", 1, Task::Turing, "needs the original"),
        ("smoothed,unsmoothed", 1, Task::Both, "needs the original"),
        ("original", 1, Task::Rating, "at least two"),
        ("original,unit,original", 1, Task::Rating, "given twice"),
        ("original,unit", 0, Task::Rating, "viewers"),
    ] {
        let err = create(&fresh, &model, &cb, &heldout, conds, viewers, task)
            .unwrap_err()
            .to_string();
        assert!(err.contains(why), "{conds}: {err}");
        assert!(!fresh.exists());
    }
    let err = create(&fresh, &model, &cb, &[], "original,unit", 1, Task::Rating).unwrap_err();
    assert!(err.to_string().contains("no held-out"), "{err}");
    // A held-out sentence that is also in the codebook.
    let held = dir.path().join("held");
    std::fs::create_dir(&held).unwrap();
    let s = &cb.sentences[0];
    facespace::npy::write(&held.join(format!("{}.npy", s.name)), s.frames.values()).unwrap();
    facespace::phonemes::write_labels(&held.join(format!("{}.lab", s.name)), &s.segments).unwrap();
    let err = facespace::study::create::load_heldout(&held, &cb, &model.hash()).unwrap_err();
    assert!(err.to_string().contains("also in the codebook"), "{err}");
}

/// The server serves only listed stimuli, answers `next` only with the viewer's secret, and
/// refuses over HTTP what the log refuses; nothing refused reaches the disk.
#[test]
fn the_server_serves_only_the_study_and_refuses_forged_requests() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = make_study(&study, "original,unsmoothed", 1, Task::Both);
    let served = serve_in_thread(&study);
    assert!(facespace::study::StudyServer::bind(&study, "0.0.0.0:0", false).is_err());
    let url = served.url.clone();
    let v = &manifest.viewers[0];
    let (code, body) = http(
        &url,
        "GET",
        &format!("/api/next?viewer={}&token={}", v.id, v.token),
        "",
    );
    assert_eq!(code, 200, "{body}");
    let next: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(
        (next["trial"].as_u64(), next["done"].as_bool()),
        (Some(0), Some(false))
    );
    let clip = next["stimuli"][0].as_str().unwrap();
    // Stimuli go only to holders of a viewer's secret.
    let bare = clip.split('?').next().unwrap();
    assert_eq!(http(&url, "GET", bare, "").0, 403, "{bare}");
    let wrong = format!("{bare}?viewer={}&token={}", v.id, "0".repeat(32));
    assert_eq!(http(&url, "GET", &wrong, "").0, 403);
    let good = serde_json::json!({"viewer": v.id, "token": v.token, "trial": 0, "real": true});
    // An answer before the clip was fetched, then before it could have played, is refused.
    let early = http(&url, "POST", "/api/answer", &good.to_string());
    assert_eq!(early.0, 425, "{}", early.1);
    let fetched = std::time::Instant::now();
    let (code, bytes) = http(&url, "GET", clip, "");
    assert!(code == 200 && bytes.len() > 1000);
    let early = http(&url, "POST", "/api/answer", &good.to_string());
    assert_eq!(early.0, 425, "{}", early.1);
    assert!(early.1.contains("play it through"), "{}", early.1);
    for path in [
        "/stimuli/../study.json",
        "/stimuli/%2e%2e/study.json",
        "/stimuli/deadbeef.mp4",
        "/study.json",
        "/answers.jsonl",
    ] {
        assert_eq!(http(&url, "GET", path, "").0, 404, "{path}");
    }
    assert_eq!(
        http(
            &url,
            "GET",
            &format!("/api/next?viewer={}&token=x", v.id),
            ""
        )
        .0,
        403
    );
    assert_eq!(http(&url, "GET", "/api/next", "").0, 404);
    let forged =
        serde_json::json!({"viewer": v.id, "token": "0".repeat(32), "trial": 0, "real": true});
    assert_eq!(
        http(&url, "POST", "/api/answer", &forged.to_string()).0,
        403
    );
    assert_eq!(
        http(&url, "POST", "/api/answer", &"x".repeat(2 << 20)).0,
        413
    );
    assert!(
        !study.join(ANSWERS).exists() || std::fs::read(study.join(ANSWERS)).unwrap().is_empty()
    );
    let lasts = manifest
        .stimulus(
            bare.trim_start_matches("/stimuli/")
                .trim_end_matches(".mp4"),
        )
        .map(|s| s.frames as f64 / manifest.fps)
        .unwrap();
    let wait = (lasts - facespace::study::answers::ANSWER_SLACK_SECONDS + 0.05).max(0.0);
    std::thread::sleep(std::time::Duration::from_secs_f64(wait).saturating_sub(fetched.elapsed()));
    assert_eq!(http(&url, "POST", "/api/answer", &good.to_string()).0, 200);
    assert_eq!(
        http(&url, "POST", "/api/answer", &good.to_string()).0,
        409,
        "a replay"
    );
    served.stop();
    assert_eq!(
        std::fs::read_to_string(study.join(ANSWERS))
            .unwrap()
            .lines()
            .count(),
        1
    );
}

// --- The whole study through the real binary and a headless Chromium. -------------------

/// `facespace study serve DIR` on a free port; returns the child and each viewer's link.
/// A study server on a free loopback port, in a thread of this test.
struct Served {
    url: String,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    handle: std::thread::JoinHandle<()>,
}

impl Served {
    /// Stops the server and waits for it (a panic in it fails the test).
    fn stop(self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.handle.join().unwrap();
    }
}

fn serve_in_thread(study: &Path) -> Served {
    let (mut server, _) = facespace::study::StudyServer::bind(study, "127.0.0.1:0", false).unwrap();
    let url = server.url();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = stop.clone();
    let handle = std::thread::spawn(move || {
        server.run(
            |_| {},
            move || flag.load(std::sync::atomic::Ordering::Relaxed),
        )
    });
    Served { url, stop, handle }
}

fn serve(study: &Path) -> (std::process::Child, Vec<String>) {
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_facespace"))
        .args([
            "study",
            "serve",
            study.to_str().unwrap(),
            "--listen",
            "127.0.0.1:0",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut out = child.stdout.take().unwrap();
    let text = common::read_until_started(&mut out);
    // Keep reading (and dropping) its log so the pipe never fills.
    std::thread::spawn(move || std::io::copy(&mut out, &mut std::io::sink()));
    let links = text
        .lines()
        .filter_map(|l| {
            l.trim()
                .split_once(": http")
                .map(|(_, u)| format!("http{u}"))
        })
        .collect();
    (child, links)
}

/// Opens `link` in Chromium and answers up to `auto` trials (`all`); returns the report line.
fn browse(browser: &str, link: &str, auto: &str) -> String {
    let mut chromium = common::cdp::Browser::launch(browser);
    let page = chromium.open(link);
    let k = if auto == "all" { "1e9" } else { auto };
    chromium
        .eval(&page, &format!("({ANSWER_TRIALS})({k})"))
        .as_str()
        .unwrap()
        .to_owned()
}

/// What the browser test does on the study page, from outside it, as a viewer would: play
/// every clip of the trial to its end (the page enables answering on `ended`), then move the
/// sliders or press a button — scores and choices a fixed function of the trial index
/// ([`auto_answer`]) — and wait for the next trial; up to `k` trials.
const ANSWER_TRIALS: &str = r##"async (k) => {
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  const settled = async () => { for (let w = 0; w < 400 && !current && !$("help").textContent.startsWith("Thank"); w++) await sleep(25); };
  await settled();
  const start = current ? current.trial : -1;
  let answered = 0;
  while (current && answered < k) {
    const i = current.trial;
    for (const box of document.querySelectorAll("#trial .clip")) {
      const v = box.querySelector("video");
      if (v.controls) throw new Error("the browser's controls would cover the face");
      const ended = new Promise((r) => v.addEventListener("ended", r, { once: true }));
      v.muted = true;
      box.querySelector("button.play").click();
      await ended;
    }
    if (current.kind === "rate") {
      current.sliders[0].value = 1 + (7 * i + 3) % 50;
      current.sliders[1].value = 1 + (11 * i + 20) % 50;
      current.sliders.forEach((s) => s.dispatchEvent(new Event("input")));
      $("submit").click();
    } else {
      current.buttons[i % 3 === 0 ? 0 : 1].click();
    }
    for (let w = 0; w < 400 && current && current.trial === i; w++) await sleep(25);
    if (current && current.trial === i) break;
    answered += 1;
    await settled();
  }
  return `AUTO DONE start=${start} answered=${answered} done=${!current}`;
}"##;

/// What [`ANSWER_TRIALS`] answers at trial `i`.
fn auto_answer(trial: &Trial, i: usize) -> Response {
    match trial {
        Trial::Rate { .. } => Response::Scores {
            scores: [
                (1 + (7 * i + 3) % 50) as f64,
                (1 + (11 * i + 20) % 50) as f64,
            ],
        },
        Trial::Judge { .. } => Response::Judgement {
            real: i.is_multiple_of(3),
        },
    }
}

/// A short study answered in a real browser by two viewers, the server killed (-9) and
/// restarted after viewer 1's fifth answer, the rest of viewer 1 beside all of viewer 2: the
/// page resumes at trial 5, every answer is stored once and in order, and `study analyse`
/// gives the statistics of those answers.
#[test]
fn headless_chromium_answers_a_study_across_a_server_crash() {
    let Some(browser) = common::chromium() else {
        eprintln!("skipped: no Chromium on PATH (.ci/run installs the distribution's package)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    // Clips of 0.4 s: the page makes a viewer play each in real time, about 40 in all.
    let manifest = make_study_with(
        &study,
        "original,smoothed,unsmoothed,random-lips",
        2,
        Task::Both,
        None,
        0.4,
    );
    let (mut server, links) = serve(&study);
    assert_eq!(links.len(), 2, "{links:?}");
    assert_eq!(
        browse(browser, &links[0], "5"),
        "AUTO DONE start=0 answered=5 done=false"
    );
    server.kill().unwrap();
    server.wait().unwrap();
    let (mut server, links) = serve(&study);
    let total = manifest.viewers[0].trials.len();
    let total2 = manifest.viewers[1].trials.len();
    // The two viewers at once, as a study's viewers are: the server interleaves their answers,
    // and the clips play in real time, so this halves the test's wait.
    let second = {
        let (browser, link) = (browser.to_owned(), links[1].clone());
        std::thread::spawn(move || browse(&browser, &link, "all"))
    };
    assert_eq!(
        browse(browser, &links[0], "all"),
        format!("AUTO DONE start=5 answered={} done=true", total - 5)
    );
    assert_eq!(
        second.join().unwrap(),
        format!("AUTO DONE start=0 answered={total2} done=true")
    );
    server.kill().unwrap();
    server.wait().unwrap();

    // Every trial answered once, in order, with what the page gave.
    let (stored, note) = facespace::study::answers::read(&study, &manifest).unwrap();
    assert!(note.is_none());
    assert_eq!(stored.len(), total + total2);
    for v in &manifest.viewers {
        let mine: Vec<_> = stored.iter().filter(|a| a.viewer == v.id).collect();
        assert_eq!(mine.len(), v.trials.len());
        for (i, (a, t)) in mine.iter().zip(&v.trials).enumerate() {
            assert_eq!(a.trial, i);
            assert_eq!(a.response, auto_answer(t, i), "{} trial {i}", v.id);
        }
    }

    // The analysis, checked against the statistics computed here from the same answers.
    let report_dir = dir.path().join("report");
    let out = common::facespace(&[
        "study",
        "analyse",
        study.to_str().unwrap(),
        "-o",
        report_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", common::text(&out));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(report_dir.join("report.json")).unwrap())
            .unwrap();
    assert!(report_dir.join("scores.png").is_file() && report_dir.join("report.md").is_file());
    assert_eq!(report["answers"], total + total2);
    assert_eq!(report["complete_viewers"], 2);
    let condition = |id: &str| manifest.stimulus(id).unwrap().condition;
    // smoothed vs unsmoothed, pooled: score of smoothed − score of unsmoothed per trial.
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let (mut correct, mut judged) = (0, 0);
    for v in &manifest.viewers {
        for (i, t) in v.trials.iter().enumerate() {
            match (t, auto_answer(t, i)) {
                (Trial::Rate { first, second }, Response::Scores { scores }) => {
                    match (condition(first), condition(second)) {
                        (Condition::Smoothed, Condition::Unsmoothed) => {
                            a.push(scores[0] / 10.0);
                            b.push(scores[1] / 10.0);
                        }
                        (Condition::Unsmoothed, Condition::Smoothed) => {
                            a.push(scores[1] / 10.0);
                            b.push(scores[0] / 10.0);
                        }
                        _ => {}
                    }
                }
                (Trial::Judge { stimulus }, Response::Judgement { real }) => {
                    judged += 1;
                    correct += usize::from(condition(stimulus).is_real() == real);
                }
                _ => unreachable!(),
            }
        }
    }
    let expected = stats::wilcoxon(&a, &b).unwrap();
    let pair = report["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["first"] == "smoothed" && p["second"] == "unsmoothed")
        .unwrap();
    assert_eq!(pair["pooled"]["n"], a.len());
    assert!(close(
        pair["pooled"]["w"].as_f64().unwrap(),
        expected.w,
        1e-12
    ));
    assert!(close(
        pair["pooled"]["p"].as_f64().unwrap(),
        expected.p,
        1e-12
    ));
    assert_eq!(pair["per_viewer"].as_array().unwrap().len(), 2);
    let turing = &report["turing"]["overall"];
    assert_eq!(
        (turing["k"].as_u64(), turing["n"].as_u64()),
        (Some(correct as u64), Some(judged as u64))
    );
    let expected = stats::binomial(correct, judged).unwrap();
    assert!(close(turing["low"].as_f64().unwrap(), expected.low, 1e-12));
    assert!(report["kruskal"]["h"].as_f64().unwrap() >= 0.0);
}

/// Issue 27, F1 and F6: the study server refuses foreign `Host`s; planted stimuli (a link to
/// `/etc/passwd`, to `/dev/zero`, a FIFO) are refused at once, never served or waited on; an
/// answer log planted as a link is refused before anything is appended through it.
#[test]
fn planted_stimuli_and_logs_are_refused_and_foreign_hosts_too() {
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = make_study(&study, "original,smoothed,unsmoothed", 1, Task::Both);
    let v = &manifest.viewers[0];
    let ids: Vec<String> = v
        .trials
        .iter()
        .flat_map(|t| t.stimuli())
        .map(str::to_owned)
        .collect();
    let stimulus = |id: &str| {
        study
            .join(facespace::study::STIMULI)
            .join(format!("{id}.mp4"))
    };
    // Three different stimuli replaced by what an attacker could plant.
    let mut planted = Vec::new();
    for id in &ids {
        if planted.contains(id) {
            continue;
        }
        planted.push(id.clone());
        if planted.len() == 3 {
            break;
        }
    }
    assert_eq!(planted.len(), 3, "{ids:?}");
    for (id, what) in planted.iter().zip(["/etc/passwd", "/dev/zero", "fifo"]) {
        let path = stimulus(id);
        std::fs::remove_file(&path).unwrap();
        if what == "fifo" {
            let c = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
            // SAFETY: mkfifo reads the NUL-terminated path it is given.
            assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        } else {
            std::os::unix::fs::symlink(what, &path).unwrap();
        }
    }
    let served = serve_in_thread(&study);
    let url = served.url.clone();
    let clock = std::time::Instant::now();
    for id in &planted {
        let path = format!("/stimuli/{id}.mp4?viewer={}&token={}", v.id, v.token);
        let (code, body) = http(&url, "GET", &path, "");
        assert!(
            code == 500 && (body.contains("symbolic link") || body.contains("not a regular")),
            "{id}: {code} {body}"
        );
        assert!(!body.contains("root:"), "{body}");
    }
    assert!(
        clock.elapsed().as_secs() < 10,
        "a planted file stalled the server"
    );
    let host = url.trim_start_matches("http://").trim_end_matches('/');
    let next = format!("/api/next?viewer={}&token={}", v.id, v.token);
    let (code, _) = common::http_raw(&url, "GET", &next, "Host: evil.example\r\n", "");
    assert_eq!(code, 421);
    let (code, _) = common::http_raw(&url, "GET", &next, &format!("Host: {host}\r\n"), "");
    assert_eq!(code, 200);
    served.stop();

    // The answer log as a link to a file outside: refused, the file untouched.
    let outside = dir.path().join("outside.txt");
    std::fs::write(&outside, "keep\n").unwrap();
    let _ = std::fs::remove_file(study.join(ANSWERS));
    std::os::unix::fs::symlink(&outside, study.join(ANSWERS)).unwrap();
    assert!(facespace::study::StudyServer::bind(&study, "127.0.0.1:0", false).is_err());
    assert_eq!(std::fs::read_to_string(&outside).unwrap(), "keep\n");
}

/// Issue 27, study validity: `study analyse` lists answers that came sooner than their clip
/// lasts, by the server's fetch timing or by the gap to the viewer's previous answer (the
/// three answers 10 ms apart a script could store before the server checked).
#[test]
fn analyse_flags_answers_faster_than_their_clips() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = make_study(&study, "original,smoothed,unsmoothed", 1, Task::Turing);
    let v = &manifest.viewers[0];
    let lasts = |t: &Trial| {
        t.stimuli()
            .iter()
            .map(|id| manifest.stimulus(id).unwrap().frames as f64 / manifest.fps)
            .fold(0.0, f64::max)
    };
    let answer = |i: usize, at: f64, after_fetch: Option<f64>| facespace::study::Answer {
        viewer: v.id.clone(),
        trial: i,
        stimuli: v.trials[i]
            .stimuli()
            .iter()
            .map(|s| s.to_string())
            .collect(),
        response: Response::Judgement { real: true },
        at,
        after_fetch,
    };
    let d = lasts(&v.trials[0]);
    // Watched: each a clip's length apart, fetched that long before.
    let slow: Vec<_> = (0..3)
        .map(|i| answer(i, 1000.0 + 2.0 * d * i as f64, Some(d + 0.1)))
        .collect();
    assert!(facespace::study::analyse::fast_answers(&manifest, &slow).is_empty());
    // Scripted: 10 ms apart (an old log without fetch times), then one with its fetch time.
    let scripted: Vec<_> = (0..3)
        .map(|i| answer(i, 1000.0 + 0.01 * i as f64, None))
        .collect();
    let fast = facespace::study::analyse::fast_answers(&manifest, &scripted);
    assert_eq!(fast.iter().map(|f| f.trial).collect::<Vec<_>>(), vec![1, 2]);
    let early = vec![answer(0, 1000.0, Some(0.05))];
    assert_eq!(
        facespace::study::analyse::fast_answers(&manifest, &early).len(),
        1
    );
    let report = facespace::study::analyse::report(&manifest, &scripted);
    assert!(
        report
            .notes
            .iter()
            .any(|n| n.contains("sooner than their clip")),
        "{:?}",
        report.notes
    );
}

/// Issue 27: the shipped pages carry no test hook (`?auto`, `?selftest`): the browser tests
/// act on them from outside (tests/common/cdp.rs).
#[test]
fn the_shipped_pages_have_no_test_hooks() {
    for page in ["src/study/page.html", "src/annotate/page.html"] {
        let text = std::fs::read_to_string(common::root().join(page)).unwrap();
        for hook in ["selftest", "has(\"auto\")", "auto("] {
            assert!(!text.contains(hook), "{page} has {hook}");
        }
    }
}

/// Issue 27, study validity: three answers in a row within milliseconds are refused — the
/// server has not handed out the clips, or not long enough ago.
#[test]
fn answers_faster_than_the_clips_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = make_study(&study, "original,unsmoothed", 1, Task::Turing);
    let served = serve_in_thread(&study);
    let url = served.url.clone();
    let v = &manifest.viewers[0];
    for i in 0..3 {
        // Fetch the clip as the page would, then answer at once.
        let (_, next) = http(
            &url,
            "GET",
            &format!("/api/next?viewer={}&token={}", v.id, v.token),
            "",
        );
        let next: serde_json::Value = serde_json::from_str(&next).unwrap();
        assert_eq!(next["trial"], 0, "nothing was stored");
        assert_eq!(
            http(&url, "GET", next["stimuli"][0].as_str().unwrap(), "").0,
            200
        );
        let a =
            serde_json::json!({"viewer": v.id, "token": v.token, "trial": 0, "real": i % 2 == 0});
        let (code, why) = http(&url, "POST", "/api/answer", &a.to_string());
        assert_eq!(code, 425, "{why}");
    }
    served.stop();
    assert!(
        !study.join(ANSWERS).exists() || std::fs::read(study.join(ANSWERS)).unwrap().is_empty()
    );
}

/// A study of a recorded talker (GRID s1, his committed model and codebook, a test-split
/// sentence held out beside its recording): every condition is drawn over the sentence's own
/// video, on the same frames, in a window centred on the face that is the manifest's stated
/// size.
#[test]
fn recorded_stimuli_are_drawn_over_their_recording_centred_on_the_face() {
    use facespace::codec::EncodeOptions;
    use facespace::synth::backdrop::{Backdrop, PoseMode};
    let root = common::root();
    let model = FaceModel::load(&root.join("models/grid/model")).unwrap();
    let cb = Codebook::load(&root.join("models/grid/codebook")).unwrap();
    let clip = root.join("tests/data/grid/bbbf9a.mp4");
    let backdrop = Backdrop::video(
        &model,
        &clip,
        PoseMode::Replay,
        1,
        &EncodeOptions::default(),
        facespace::no_progress,
    )
    .unwrap();
    let segments = facespace::phonemes::read_htk(
        &root.join("tests/data/grid/bbbf9a.lab"),
        &facespace::phonemes::PhoneMap::default(),
    )
    .unwrap();
    let heldout = vec![Heldout {
        sentence: facespace::corpus::Sentence {
            name: "bbbf9a".into(),
            source: clip.display().to_string(),
            frames: backdrop.tracked.clone(),
            segments,
        },
        audio: None,
        video: Some(clip.clone()),
    }];
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study");
    let manifest = create(
        &study,
        &model,
        &cb,
        &heldout,
        "original,smoothed",
        1,
        Task::Rating,
    )
    .unwrap();
    assert!(manifest.over_recordings);
    let [w, h] = manifest.canvas;
    // The face's extent over the sentence, and its centre.
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for p in backdrop.tracked.iter() {
        for q in model.landmarks(p).unwrap().points {
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let share = extent / f64::from(w.max(h));
    assert!(
        (share - facespace::study::create::FACE_SHARE).abs() < 0.02,
        "the face is {share:.3} of the {w}×{h} window"
    );
    let recording = facespace::video::Source::open(&clip)
        .unwrap()
        .next_frame()
        .unwrap()
        .unwrap();
    let x0 = (((lo[0] + hi[0]) / 2.0 - f64::from(w) / 2.0).round())
        .clamp(0.0, f64::from(recording.width() - w)) as u32;
    let y0 = (((lo[1] + hi[1]) / 2.0 - f64::from(h) / 2.0).round())
        .clamp(0.0, f64::from(recording.height() - h)) as u32;
    let mut corners = Vec::new();
    for s in &manifest.stimuli {
        let first = facespace::video::Source::open(&study.join("stimuli").join(s.file_name()))
            .unwrap()
            .next_frame()
            .unwrap()
            .unwrap();
        assert_eq!(first.dimensions(), (w, h), "{}", s.id);
        // The window's top corners (hair and backdrop, no face) are the recording's there.
        let mut diff = 0.0;
        let mut corner = Vec::new();
        for y in 0..8 {
            for x in (0..8).chain(w - 8..w) {
                let (a, b) = (
                    first.get_pixel(x, y).0,
                    recording.get_pixel(x0 + x, y0 + y).0,
                );
                for c in 0..3 {
                    diff += (f64::from(a[c]) - f64::from(b[c])).abs();
                    corner.push(a[c]);
                }
            }
        }
        let mean = diff / (8.0 * 16.0 * 3.0);
        assert!(
            mean < 8.0,
            "{}: the corners differ from the recording by {mean:.1}",
            s.id
        );
        corners.push(corner);
    }
    assert_eq!(corners.len(), 2);
}
