#!/usr/bin/env python3
"""GRID speaker 1's model training frames (recorded video), with dlib 68-point landmarks.
Not part of the build; outputs committed. Needs ffmpeg, PyPI dlib + face-recognition-models.

  python3 tools/grid_landmarks.py [N_CLIPS]

Takes N_CLIPS (default 30) training-split clips spread evenly over the sorted training list
(damaged ones skipped) and from each two frames chosen by the clip's phone labels: the middle
of its longest open vowel (mouth open) and the middle of its longest /b p m/ (closed). Writes
models/grid/training/ID_FFF.jpg + .pts (FFF = frame index in the clip)."""
import pathlib, subprocess, sys, tempfile
import numpy as np
from PIL import Image
import dlib, face_recognition_models

ROOT = pathlib.Path(__file__).resolve().parents[1]
GRID = ROOT.parent / "shared/data/grid-s1"
n_clips = int(sys.argv[1]) if len(sys.argv) > 1 else 30
out = ROOT / "models/grid/training"
out.mkdir(parents=True, exist_ok=True)
damaged = set((GRID / "damaged.txt").read_text().split())
train = [i for i in sorted((GRID / "train.txt").read_text().split()) if i not in damaged]
clips = [train[round(k * (len(train) - 1) / (n_clips - 1))] for k in range(n_clips)]
OPEN = {"AA", "AE", "AH", "AO", "AW", "AY", "EH", "EY"}
CLOSED = {"B", "P", "M"}
detector = dlib.get_frontal_face_detector()
predictor = dlib.shape_predictor(face_recognition_models.pose_predictor_model_location())

def pick(lab, kinds):
    best = None
    for line in lab.read_text().splitlines():
        s, e, p = line.split()
        s, e = int(s) / 1e7, int(e) / 1e7
        if p in kinds and (best is None or e - s > best[1] - best[0]):
            best = (s, e)
    return None if best is None else round((best[0] + best[1]) / 2 * 25)

written = 0
with tempfile.TemporaryDirectory() as tmp:
    for cid in clips:
        lab = GRID / "phones" / f"{cid}.lab"
        for frame in {pick(lab, OPEN), pick(lab, CLOSED)} - {None}:
            png = pathlib.Path(tmp) / f"{cid}_{frame}.png"
            subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(GRID / "clips" / f"{cid}.mp4"),
                            "-vf", f"select=eq(n\\,{frame})", "-vsync", "0", "-frames:v", "1", str(png)],
                           check=True)
            img = np.asarray(Image.open(png).convert("RGB"))
            dets = detector(img, 1)
            if len(dets) != 1:
                print("skipped", cid, frame, "faces:", len(dets))
                continue
            s = predictor(img, dets[0])
            name = f"{cid}_{frame:03d}"
            Image.fromarray(img).save(out / f"{name}.jpg", quality=95)
            body = "".join(f"{s.part(i).x + 1} {s.part(i).y + 1}\n" for i in range(68))
            (out / f"{name}.pts").write_text(f"version: 1\nn_points: 68\n{{\n{body}}}\n")
            written += 1
print("wrote", written, "frames to", out)
