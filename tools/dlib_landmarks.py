#!/usr/bin/env python3
"""Automatic 68-point landmarks for a folder of frames (the own-talker road's slowest step).
Not part of the build. Needs PyPI `dlib-bin` (a prebuilt dlib) and `face-recognition-models`
(dlib's 68-point shape predictor):

  pip install dlib-bin face-recognition-models
  python3 tools/dlib_landmarks.py out/own/frames          # writes NAME.pts beside NAME.jpg/.png

For every image without a `.pts` beside it: dlib's HOG face detector, then its 68-point shape
predictor on the largest face, written as an iBUG `.pts` (1-based coordinates, the format's
convention: facespace reads them back 0-based). Frames with no face are listed and left unmarked. Correct the points
with `facespace annotate FOLDER` (it opens each frame with its `.pts`), then build the model.
Existing `.pts` files are never overwritten (use --force to redo them)."""
import pathlib, sys

import dlib
import face_recognition_models
import numpy as np
from PIL import Image


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    force = "--force" in sys.argv
    if len(args) != 1:
        sys.exit(__doc__)
    folder = pathlib.Path(args[0])
    detector = dlib.get_frontal_face_detector()
    predictor = dlib.shape_predictor(face_recognition_models.pose_predictor_model_location())
    images = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    marked, missed = 0, []
    for path in images:
        pts = path.with_suffix(".pts")
        if pts.exists() and not force:
            continue
        pixels = np.asarray(Image.open(path).convert("RGB"))
        faces = detector(pixels, 1)
        if not faces:
            missed.append(path.name)
            continue
        face = max(faces, key=lambda r: r.width() * r.height())
        shape = predictor(pixels, face)
        lines = [f"{shape.part(i).x + 1} {shape.part(i).y + 1}" for i in range(68)]
        tmp = pts.with_suffix(".pts.tmp")
        tmp.write_text("version: 1\nn_points: 68\n{\n" + "\n".join(lines) + "\n}\n")
        tmp.replace(pts)
        marked += 1
    print(f"marked {marked} of {len(images)} frames in {folder}")
    if missed:
        print(f"no face found in {len(missed)}: {', '.join(missed[:10])}{' …' if len(missed) > 10 else ''}")


if __name__ == "__main__":
    main()
