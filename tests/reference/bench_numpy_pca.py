"""numpy's PCA of a 600 × 111 426 matrix (the shape of 600 frames' textures at 40 000
reference pixels × RGB), for BENCHMARKS.md's model-build comparison with facespace's PCA.

The values are random: the time of a dense PCA does not depend on them. Two ways: the
snapshot method (float64 Gram matrix + eigh + back-projection, as facespace does) and a thin
SVD (np.linalg.svd, full_matrices=False). numpy uses its bundled OpenBLAS/LAPACK.

Run: python3 tests/reference/bench_numpy_pca.py
"""
import time

import numpy as np

n, d, k = 600, 111_426, 80
rng = np.random.default_rng(15)
x = rng.standard_normal((n, d), dtype=np.float32) * 40 + 128


def snapshot():
    c = x.astype(np.float64) - x.mean(axis=0, dtype=np.float64)
    g = c @ c.T
    w, u = np.linalg.eigh(g)
    order = np.argsort(w)[::-1][:k]
    v = u[:, order].T @ c
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return w[order], v


def thin_svd():
    c = x.astype(np.float64) - x.mean(axis=0, dtype=np.float64)
    _, s, vt = np.linalg.svd(c, full_matrices=False)
    return s[:k] ** 2, vt[:k]


for name, f in [("snapshot (Gram + eigh)", snapshot), ("thin SVD", thin_svd)]:
    times = []
    for _ in range(3):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    print(f"{name}: median {sorted(times)[1]:.2f} s over 3 runs")
