#!/usr/bin/env python3
"""Reference values for tests/smooth.rs: scipy.interpolate.make_smoothing_spline, which
minimises sum w_i (y_i - f(x_i))^2 + lam * integral f''(u)^2 du, evaluated at the knots.
Cases: noisy sine on uneven knots with weights, a 25 fps face-space-like series, several lam.
Output: tests/data/smoothing_scipy.json. Run: python3 tests/reference/smoothing_scipy.py (scipy 1.17)."""
import json, pathlib
import numpy as np
from scipy.interpolate import make_smoothing_spline

ROOT = pathlib.Path(__file__).resolve().parents[2]
rng = np.random.default_rng(5)
cases = []
x = np.sort(rng.uniform(0, 3, 40))
y = np.sin(2 * x) + 0.2 * rng.normal(size=40)
w = rng.uniform(0.5, 2.0, 40)
for lam in [1e-4, 1e-2, 1.0]:
    cases.append({"name": f"uneven_weighted_{lam}", "x": x.tolist(), "y": y.tolist(), "w": w.tolist(), "lam": lam,
                  "fit": make_smoothing_spline(x, y, w=w, lam=lam)(x).tolist()})
t = np.arange(120) / 25.0
v = np.cumsum(rng.normal(size=120))
for lam in [1e-5, 1e-3, 1e-1]:
    cases.append({"name": f"frames_{lam}", "x": t.tolist(), "y": v.tolist(), "w": None, "lam": lam,
                  "fit": make_smoothing_spline(t, v, lam=lam)(t).tolist()})
json.dump(cases, open(ROOT / "tests/data/smoothing_scipy.json", "w"))
print(len(cases), "cases")
