#!/usr/bin/env python3
"""Reference values for tests/study.rs: scipy's wilcoxon, kruskal and binomtest (with the exact
Clopper-Pearson 95 % interval of `proportion_ci`), on the kinds of data a subjective study gives.

Wilcoxon cases cover every branch of scipy's method='auto': no ties and no zeros (exact null
distribution), ties or zeros with n <= 13 (exact permutation over sign flips), ties or zeros
with 13 < n <= 50 (normal approximation with the tie correction), and n > 50. Defaults
everywhere: zero_method='wilcox' (zeros dropped), correction=False, two-sided.
Output: tests/data/stats_scipy.json. Run: python3 tests/reference/stats_scipy.py (scipy 1.17).
"""
import json, pathlib
import numpy as np
from scipy import stats

ROOT = pathlib.Path(__file__).resolve().parents[2]
rng = np.random.default_rng(16)
out = {"wilcoxon": [], "kruskal": [], "binomtest": []}


def wil(name, x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    r = stats.wilcoxon(x, y)
    out["wilcoxon"].append({"name": name, "x": x.tolist(), "y": y.tolist(),
                            "statistic": float(r.statistic), "pvalue": float(r.pvalue)})


def slider(n, shift=0.0):
    """Integer 1-50 slider scores, as viewers give them (many ties)."""
    return np.clip(np.round(rng.normal(30 + shift, 8, n)), 1, 50)


wil("exact_no_ties", [1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30],
    [0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29])
wil("exact_n20", rng.normal(0, 1, 20) + 0.4, rng.normal(0, 1, 20))
wil("exact_n50", rng.normal(0, 1, 50) + 0.2, rng.normal(0, 1, 50))
wil("ties_n8", [30, 25, 40, 35, 28, 33, 29, 41], [25, 20, 35, 30, 30, 28, 24, 36])
wil("zeros_n10", [30, 25, 40, 35, 28, 33, 29, 41, 22, 19], [30, 20, 35, 35, 30, 28, 24, 36, 22, 25])
wil("zeros_and_ties_n13", slider(13, 3), slider(13))
wil("ties_n14", slider(14, 4), slider(14))
wil("ties_n30", slider(30, 2), slider(30))
wil("ties_n50", slider(50, -3), slider(50))
wil("ties_n51", slider(51, 1), slider(51))
wil("slider_n200", slider(200, 1), slider(200))
wil("no_ties_n80", rng.normal(0, 1, 80) + 0.1, rng.normal(0, 1, 80))
wil("one_pair", [3.0], [1.0])
wil("all_one_sign_n6", [10, 20, 30, 40, 50, 45], [1, 2, 3, 4, 5, 6])


def kru(name, *groups):
    groups = [np.asarray(g, float) for g in groups]
    r = stats.kruskal(*groups)
    out["kruskal"].append({"name": name, "groups": [g.tolist() for g in groups],
                           "statistic": float(r.statistic), "pvalue": float(r.pvalue)})


kru("small_no_ties", [2.9, 3.0, 2.5, 2.6, 3.2], [3.8, 2.7, 4.0, 2.4], [2.8, 3.4, 3.7, 2.2, 2.0])
kru("slider_ties", slider(24, 5), slider(24), slider(24, -4), slider(24, 1))
kru("unequal_sizes", slider(5, 10), slider(40), slider(17, -2))
kru("two_groups", slider(30, 3), slider(30))
kru("eight_conditions", *[slider(36, s) for s in [8, 0, 2, 3, -10, 4, 5, -1]])


def binom(k, n):
    r = stats.binomtest(k, n)
    ci = r.proportion_ci(confidence_level=0.95, method="exact")
    out["binomtest"].append({"k": k, "n": n, "pvalue": float(r.pvalue),
                             "low": float(ci.low), "high": float(ci.high)})


for k, n in [(7, 10), (5, 10), (0, 12), (12, 12), (1, 1), (0, 1), (31, 48), (17, 48),
             (260, 500), (130, 240), (3, 40), (999, 2000)]:
    binom(k, n)

json.dump(out, open(ROOT / "tests/data/stats_scipy.json", "w"), indent=0)
print({k: len(v) for k, v in out.items()})
