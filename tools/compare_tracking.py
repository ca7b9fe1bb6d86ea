"""Tracked landmarks of the whole FGNet video against dlib's at the 50 demo frames
(BENCHMARKS.md, tracking). Frame `fNNNNN` of models/demo/training and tests/data/demo-heldout
is row NNNNN of the array `facespace track franck.mp4 -o track.npy` writes.

    python3 tools/compare_tracking.py track.npy
"""
import pathlib
import sys

import numpy as np

root = pathlib.Path(__file__).resolve().parents[1]


def read_pts(path):
    body = path.read_text().split("{")[1].split("}")[0].split()
    return np.array(body, float).reshape(-1, 2) - 1.0  # .pts is 1-based on disk


tracked = np.load(sys.argv[1])
files = sorted(list((root / "models/demo/training").glob("*.pts"))
               + list((root / "tests/data/demo-heldout").glob("*.pts")))
errors = []
for f in files:
    truth, fit = read_pts(f), tracked[int(f.stem[1:])]
    iod = np.linalg.norm(truth[36:42].mean(0) - truth[42:48].mean(0))
    errors.append(np.linalg.norm(fit - truth, axis=1).mean() / iod)
e = np.array(errors)
worst = files[int(e.argmax())].stem
print(f"{len(e)} frames: error / inter-ocular distance mean {e.mean():.4f}, median "
      f"{np.median(e):.4f}, {(e < 0.055).sum()} under 5.5%, worst {e.max():.3f} ({worst})")
