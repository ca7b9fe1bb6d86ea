#!/usr/bin/env python3
"""Make the demo training set: frames of the FGNet talking-face video (franck.mp4) with
68-point iBUG landmarks from dlib's shape predictor, chosen to span the mouth shapes.

Not part of the build; run once, check the overlays by eye, commit the outputs.
  ffmpeg -i ../shared/data/talking-face/franck.mp4 -vf "select=not(mod(n\\,4))" -vsync 0 /tmp/franck/f%05d.png
  python3 tools/demo_training_set.py /tmp/franck --overlay /tmp/overlay-demo
Needs: pip install dlib-bin face-recognition-models pillow numpy.

1. Every extracted frame (every 4th video frame): dlib HOG face detector, then the 68-point
   predictor (the model shipped in face-recognition-models).
2. Mouth descriptors per frame, normalised by the inter-ocular distance: inner-lip opening,
   outer-lip opening, mouth width, jaw drop (nose tip to chin).
3. 40 training frames by farthest-point sampling in the standardised descriptor space,
   starting from the frame nearest the median (a neutral mouth); 10 held-out frames drawn
   with a fixed seed from the rest, at least 12 video frames from any training frame.
Outputs: models/demo/training/fNNNNN.jpg + .pts (NNNNN = video frame index, 0-based),
tests/data/demo-heldout/ (same), and tools/demo_training_set.json (the selection record).
"""
import argparse, json, pathlib, sys
import numpy as np
from PIL import Image, ImageDraw
import dlib, face_recognition_models

ROOT = pathlib.Path(__file__).resolve().parents[1]


def write_pts(path, pts):
    body = "".join(f"{x + 1:.3f} {y + 1:.3f}\n" for x, y in pts)
    path.write_text(f"version: 1\nn_points: {len(pts)}\n{{\n{body}}}\n")


def descriptors(p):
    iod = np.linalg.norm(p[36:42].mean(0) - p[42:48].mean(0))
    inner = np.mean([np.linalg.norm(p[a] - p[b]) for a, b in [(61, 67), (62, 66), (63, 65)]])
    outer = np.linalg.norm(p[51] - p[57])
    width = np.linalg.norm(p[48] - p[54])
    jaw = np.linalg.norm(p[33] - p[8])
    return np.array([inner, outer, width, jaw]) / iod


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("frames")
    ap.add_argument("--overlay")
    ap.add_argument("--train", type=int, default=40)
    ap.add_argument("--heldout", type=int, default=10)
    args = ap.parse_args()
    detector = dlib.get_frontal_face_detector()
    predictor = dlib.shape_predictor(face_recognition_models.pose_predictor_model_location())
    files = sorted(pathlib.Path(args.frames).glob("f*.png"))
    found = {}
    for k, f in enumerate(files):
        img = np.asarray(Image.open(f).convert("RGB"))
        dets = detector(img, 1)
        if len(dets) != 1:
            continue
        s = predictor(img, dets[0])
        video_frame = 4 * (int(f.stem[1:]) - 1)
        found[video_frame] = (f, np.array([[s.part(i).x, s.part(i).y] for i in range(68)], float))
    print(f"{len(found)} of {len(files)} frames with exactly one face", file=sys.stderr)
    keys = sorted(found)
    d = np.array([descriptors(found[k][1]) for k in keys])
    z = (d - d.mean(0)) / d.std(0)
    chosen = [int(np.argmin(np.linalg.norm(z - np.median(z, 0), axis=1)))]
    dist = np.linalg.norm(z - z[chosen[0]], axis=1)
    while len(chosen) < args.train:
        i = int(np.argmax(dist))
        chosen.append(i)
        dist = np.minimum(dist, np.linalg.norm(z - z[i], axis=1))
    train = sorted(keys[i] for i in chosen)
    rng = np.random.default_rng(2026)
    pool = [k for k in keys if min(abs(k - t) for t in train) >= 12]
    heldout = sorted(int(k) for k in rng.choice(pool, args.heldout, replace=False))
    for name, subset in [("models/demo/training", train), ("tests/data/demo-heldout", heldout)]:
        out = ROOT / name
        out.mkdir(parents=True, exist_ok=True)
        for k in subset:
            f, pts = found[k]
            Image.open(f).convert("RGB").save(out / f"f{k:05d}.jpg", quality=95)
            # dlib's integer pixel coordinates are pixel centres, 0-based.
            write_pts(out / f"f{k:05d}.pts", pts)
    if args.overlay:
        tiles = []
        for k in train + heldout:
            f, pts = found[k]
            im = Image.open(f).convert("RGB")
            dr = ImageDraw.Draw(im)
            for x, y in pts:
                dr.ellipse([x - 1.5, y - 1.5, x + 1.5, y + 1.5], outline=(0, 255, 0))
            x0, y0 = pts.min(0) - 15
            x1, y1 = pts.max(0) + 15
            tiles.append(im.crop((int(x0), int(y0), int(x1), int(y1))).resize((120, 150)))
        sheet = Image.new("RGB", (120 * 10, 150 * ((len(tiles) + 9) // 10)))
        for i, t in enumerate(tiles):
            sheet.paste(t, (120 * (i % 10), 150 * (i // 10)))
        pathlib.Path(args.overlay).mkdir(parents=True, exist_ok=True)
        sheet.save(pathlib.Path(args.overlay) / "sheet.png")
    record = {"source": "franck.mp4 (FGNet talking face)", "every_nth_frame": 4, "detected": len(found),
              "train": train, "heldout": heldout,
              "descriptor_range": {"min": d.min(0).tolist(), "max": d.max(0).tolist()}}
    (ROOT / "tools/demo_training_set.json").write_text(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
