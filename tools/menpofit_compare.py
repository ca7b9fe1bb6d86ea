"""Comparison with menpofit (BENCHMARKS.md, AAM search): a holistic greyscale AAM built by
menpofit from the same 40 demo training frames, fitted by its project-out inverse
compositional Lucas-Kanade fitter (2 scales) to the same 10 held-out frames from the same
kind of start (mean shape at the reference pose, moved by 3 px). Prints the mean
point-to-point error over the inter-ocular distance and the fits per second on one core.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python3 tools/menpofit_compare.py
"""
import pathlib
import time

import numpy as np
import scipy.integrate

# menpofit 0.7.1 imports scipy.integrate.simps, renamed simpson in SciPy 1.14.
scipy.integrate.simps = scipy.integrate.simpson
# ... and NumPy < 2 aliases.
np.Inf = np.inf

import menpo.io as mio  # noqa: E402
from menpo.shape import PointCloud  # noqa: E402
from menpo.transform import AlignmentSimilarity  # noqa: E402
from menpofit.aam import (  # noqa: E402
    HolisticAAM, LucasKanadeAAMFitter, ProjectOutInverseCompositional)

root = pathlib.Path(__file__).resolve().parents[1]


def load(folder):
    images = []
    for p in sorted((root / folder).glob("*.jpg")):
        im = mio.import_image(p)
        images.append(im.as_greyscale())
    return images


def iod_error(fit, truth):
    f, t = fit.points, truth.points
    left, right = t[36:42].mean(0), t[42:48].mean(0)
    return np.linalg.norm(f - t, axis=1).mean() / np.linalg.norm(left - right)


train = load("models/demo/training")
held = load("tests/data/demo-heldout")
aam = HolisticAAM(train, group="PTS", scales=(0.5, 1.0), max_shape_components=6,
                  max_appearance_components=31, verbose=False)
fitter = LucasKanadeAAMFitter(aam, lk_algorithm_cls=ProjectOutInverseCompositional,
                              n_shape=6, n_appearance=31)
errors, seconds = [], 0.0
for im in held:
    truth = im.landmarks["PTS"]
    # Mean shape aligned to the truth by a similarity, then moved by 3 px (both axes).
    start = fitter.reference_shape
    init = AlignmentSimilarity(start, truth).apply(start)
    init = PointCloud(init.points + 3.0)
    t0 = time.perf_counter()
    result = fitter.fit_from_shape(im, init, max_iters=40)
    seconds += time.perf_counter() - t0
    errors.append(iod_error(result.final_shape, truth))
print(f"menpofit POIC, 2 scales: mean error / IOD {np.mean(errors):.4f} "
      f"(per frame {np.round(errors, 3).tolist()}); {len(held) / seconds:.1f} fits/s")
