#!/usr/bin/env python3
"""Reference values for tests/trajectory.rs: scipy's PchipInterpolator on awkward data.

Cases: uneven knots with extrema and flats, a monotone step, two points, a flat run next to
an end (the sign(0) end condition), and a 3-dimensional face-space-like trajectory. For each,
the knots, values, query points inside the range and scipy's values and first derivatives.
Output: tests/data/pchip_scipy.json. Run: python3 tests/reference/pchip_scipy.py (scipy 1.17).
"""
import json, pathlib
import numpy as np
from scipy.interpolate import PchipInterpolator

ROOT = pathlib.Path(__file__).resolve().parents[2]
rng = np.random.default_rng(12)
cases = []


def add(name, x, y):
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if y.ndim == 1:
        y = y[:, None]
    p = PchipInterpolator(x, y)
    q = np.sort(np.concatenate([x, rng.uniform(x[0], x[-1], 60)]))
    cases.append({"name": name, "x": x.tolist(), "y": y.tolist(), "q": q.tolist(),
                  "value": p(q).tolist(), "slope": p(x, 1).tolist()})


add("uneven", [0, 0.3, 0.35, 1.0, 1.8, 2.0, 3.1, 3.2, 4.0],
    [0, 1.5, 1.5, -2.0, 0.3, 0.2, 4.0, 4.1, -1.0])
add("monotone_step", [0, 1, 2, 3, 4, 5, 6], [0, 0, 0.1, 5, 5.05, 5.1, 9])
add("two_points", [0.5, 2.0], [3.0, -1.0])
add("flat_at_end", [0, 1, 2, 3, 4], [1, 3, 3, 2, 0])
add("flat_then_rise", [0, 1, 2, 3], [2, 2, 5, 6])
t = np.arange(40) / 25.0
y = np.c_[np.sin(3 * t) + 0.1 * rng.normal(size=40), np.cumsum(rng.normal(size=40)), np.where(t > 0.8, 1.0, 0.0)]
add("face_space_3d", t, y)
json.dump(cases, open(ROOT / "tests/data/pchip_scipy.json", "w"))
print(len(cases), "cases")
