#!/usr/bin/env python3
"""A short consecutive clip of the FGNet talking-face video for tracking tests, with dlib
68-point landmarks per frame as the reference. Not part of the build; outputs committed.
  python3 tools/clip_landmarks.py [first_frame] [count]
Writes tests/data/clip/NNNN.jpg + NNNN.pts (frames first..first+count of franck.mp4)."""
import pathlib, subprocess, sys, tempfile
import numpy as np
from PIL import Image
import dlib, face_recognition_models

ROOT = pathlib.Path(__file__).resolve().parents[1]
first = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
count = int(sys.argv[2]) if len(sys.argv) > 2 else 50
out = ROOT / "tests/data/clip"
out.mkdir(parents=True, exist_ok=True)
detector = dlib.get_frontal_face_detector()
predictor = dlib.shape_predictor(face_recognition_models.pose_predictor_model_location())
with tempfile.TemporaryDirectory() as tmp:
    subprocess.run(["ffmpeg", "-v", "error", "-i", str(ROOT.parent / "shared/data/talking-face/franck.mp4"),
                    "-vf", f"select=between(n\\,{first}\\,{first + count - 1})", "-vsync", "0",
                    f"{tmp}/f%04d.png"], check=True)
    for k, f in enumerate(sorted(pathlib.Path(tmp).glob("f*.png"))):
        img = np.asarray(Image.open(f).convert("RGB"))
        dets = detector(img, 1)
        assert len(dets) == 1, f
        s = predictor(img, dets[0])
        name = f"{first + k:05d}"
        Image.fromarray(img).save(out / f"{name}.jpg", quality=95)
        body = "".join(f"{s.part(i).x + 1} {s.part(i).y + 1}\n" for i in range(68))
        (out / f"{name}.pts").write_text(f"version: 1\nn_points: 68\n{{\n{body}}}\n")
print("wrote", count, "frames to", out)
