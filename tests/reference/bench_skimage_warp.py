#!/usr/bin/env python3
"""Same-machine scikit-image figure for BENCHMARKS.md: the warps of benches/warp.rs.

A 720x576 frame (lenna scaled by 1.4) with its 68 landmarks is warped (order=1) into a
reference frame of its own shape with ~40 000 pixels inside the mesh, and back.
Prints the median of repeated runs of PiecewiseAffineTransform.from_estimate + warp.
Run: python3 tests/reference/bench_skimage_warp.py
"""
import pathlib, time
import numpy as np
from PIL import Image
from skimage.transform import PiecewiseAffineTransform, warp

ROOT = pathlib.Path(__file__).resolve().parents[2]
FACES = ROOT / "models/faces/training"


def read_pts(path):
    lines = path.read_text().split("{")[1].split("}")[0].split("\n")
    return np.array([[float(v) - 1.0 for v in l.split()] for l in lines if l.strip()])


def median_ms(f, n):
    f()
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return 1000 * float(np.median(ts))


def main():
    s = 717 / 512
    big = Image.open(FACES / "lenna.png").convert("RGB").resize((717, 717), Image.BILINEAR)
    frame = np.zeros((576, 720, 3), np.uint8)
    frame[:, :717] = np.asarray(big)[70 : 70 + 576]
    pts = (read_pts(FACES / "lenna.pts") + 0.5) * s - 0.5 - np.array([0, 70])
    c = pts.mean(0)
    ref = (pts - c) / np.sqrt(((pts - c) ** 2).sum())
    from scipy.spatial import Delaunay
    tri = Delaunay(ref)
    area = sum(0.5 * abs(np.cross(ref[b] - ref[a], ref[cc] - ref[a])) for a, b, cc in tri.simplices)
    ref = ref * np.sqrt(40000 / area)
    ref = ref - ref.min(0) + 2
    h, w = int(ref[:, 1].max() + 4), int(ref[:, 0].max() + 4)
    img = frame.astype(np.float64)

    def to_ref():
        t = PiecewiseAffineTransform.from_estimate(ref, pts)
        return warp(img, t, output_shape=(h, w), order=1, preserve_range=True)

    tex = to_ref()

    def from_ref():
        t = PiecewiseAffineTransform.from_estimate(pts, ref)
        return warp(tex, t, output_shape=(576, 720), order=1, preserve_range=True)

    print(f"scikit-image to_reference 720x576 -> {w}x{h}: {median_ms(to_ref, 10):.1f} ms")
    print(f"scikit-image from_reference {w}x{h} -> 720x576: {median_ms(from_ref, 5):.1f} ms")


if __name__ == "__main__":
    main()
