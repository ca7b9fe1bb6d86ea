#!/usr/bin/env python3
"""Reference output for tests/warp.rs: scikit-image's piecewise affine warp of a real face.

The source image is models/faces/training/lenna.png at its 68 landmarks; the target shape is
takeo's landmarks placed in a 150x170 frame. scikit-image triangulates the target points
(scipy Delaunay) and maps each output pixel into the source with that triangle's affine
transform, sampling bilinearly (order=1). We store:
  tests/data/warp_skimage.png   the warped image (rounded to uint8)
  tests/data/warp_skimage.json  target points, source points, the triangles used, the mask
                                of output pixels inside the mesh (run-length rows), and the
                                scipy Delaunay triangulation of the target points.
Run: python3 tests/reference/warp_skimage.py   (scikit-image 0.26, scipy 1.17 were used)
"""
import json, pathlib
import numpy as np
from PIL import Image
from scipy.spatial import Delaunay
from skimage.transform import PiecewiseAffineTransform, warp

ROOT = pathlib.Path(__file__).resolve().parents[2]
FACES = ROOT / "models/faces/training"


def read_pts(path):
    lines = path.read_text().split("{")[1].split("}")[0].split("\n")
    return np.array([[float(v) - 1.0 for v in l.split()] for l in lines if l.strip()])


def main():
    image = np.asarray(Image.open(FACES / "lenna.png").convert("RGB")).astype(np.float64)
    src = read_pts(FACES / "lenna.pts")
    tgt = read_pts(FACES / "takeo.pts")
    # Place the target shape in a W x H frame with a margin of 4 px.
    W, H = 150, 170
    lo, hi = tgt.min(0), tgt.max(0)
    s = min((W - 9) / (hi[0] - lo[0]), (H - 9) / (hi[1] - lo[1]))
    tgt = (tgt - lo) * s + 4.0
    tform = PiecewiseAffineTransform.from_estimate(tgt, src)  # maps output (target) -> input
    out = warp(image, tform, output_shape=(H, W), order=1, preserve_range=True, mode="constant", cval=0)
    yy, xx = np.mgrid[0:H, 0:W]
    inside = tform._tesselation.find_simplex(np.c_[xx.ravel(), yy.ravel()]) >= 0
    Image.fromarray(np.clip(np.round(out), 0, 255).astype(np.uint8)).save(ROOT / "tests/data/warp_skimage.png")
    delaunay = Delaunay(tgt).simplices
    json.dump(
        {
            "width": W,
            "height": H,
            "target": tgt.tolist(),
            "source": src.tolist(),
            "triangles": tform._tesselation.simplices.tolist(),
            "mask_rows": ["".join("1" if v else "0" for v in row) for row in inside.reshape(H, W)],
            "scipy_delaunay": delaunay.tolist(),
        },
        open(ROOT / "tests/data/warp_skimage.json", "w"),
    )


if __name__ == "__main__":
    main()
