//! The subjective-study kit (issue 16): its statistics against scipy, the answer log's
//! refusals and crash safety, and the whole study in a headless browser.
mod common;

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
        let (w, p) = (c["statistic"].as_f64().unwrap(), c["pvalue"].as_f64().unwrap());
        assert!(close(r.w, w, 1e-12), "{}: W {} vs {w}", c["name"], r.w);
        assert!(close(r.p, p, 1e-9), "{}: p {} vs {p} ({})", c["name"], r.p, r.method);
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
        let (h, p) = (c["statistic"].as_f64().unwrap(), c["pvalue"].as_f64().unwrap());
        assert!(close(r.h, h, 1e-10), "{}: H {} vs {h}", c["name"], r.h);
        assert!(close(r.p, p, 1e-8), "{}: p {} vs {p}", c["name"], r.p);
        // Mean ranks average to (N + 1) / 2, weighted by group size.
        let n: usize = r.groups.iter().map(|g| g.n).sum();
        let mean: f64 = r.groups.iter().map(|g| g.mean_rank * g.n as f64).sum::<f64>() / n as f64;
        assert!(close(mean, (n as f64 + 1.0) / 2.0, 1e-12));
    }
}

/// scipy's `binomtest(k, n)` and its exact (Clopper–Pearson) 95 % interval.
#[test]
fn binomial_matches_scipy() {
    for c in reference()["binomtest"].as_array().unwrap() {
        let (k, n) = (c["k"].as_u64().unwrap() as usize, c["n"].as_u64().unwrap() as usize);
        let r = stats::binomial(k, n).unwrap();
        for (got, key) in [(r.p, "pvalue"), (r.low, "low"), (r.high, "high")] {
            let want = c[key].as_f64().unwrap();
            assert!(close(got, want, 1e-9), "{k}/{n} {key}: {got} vs {want}");
        }
    }
    assert!(stats::binomial(3, 2).is_none() && stats::binomial(0, 0).is_none());
}
