"""Cheek shimmer of a synthesis folder against the video it was drawn over (issue 68: the
FGNet demo's cheeks shimmered 2.5x the real video's). Per frame, two boxes on the cheeks from
the synthesis's own landmarks (between the jaw line, iBUG 2-4 / 12-14, and the nose wing,
31 / 35; from the nose's middle, 29, down to its base, 33); the shimmer is the mean absolute
change of grey (BT.601) inside them from one frame to the next, in grey levels a frame.

    python3 tools/cheek_shimmer.py SYNTH_DIR BACKGROUND.mp4     (needs numpy, Pillow, ffmpeg)
"""
import glob
import subprocess
import sys

import numpy as np
from PIL import Image


def frames_of(video, w, h, n):
    raw = subprocess.run(["ffmpeg", "-v", "error", "-i", video, "-f", "rawvideo", "-pix_fmt", "rgb24", "-"],
                         check=True, capture_output=True).stdout
    return np.frombuffer(raw, np.uint8).reshape(-1, h, w, 3)[:n]


def grey(rgb):
    return rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114


def boxes(p):
    out = []
    for jaw, nose in ((3, 31), (13, 35)):
        x0, x1 = sorted((p[jaw][0] + 0.25 * (p[nose][0] - p[jaw][0]), p[jaw][0] + 0.75 * (p[nose][0] - p[jaw][0])))
        out.append((int(x0), int(p[29][1]), int(x1) + 1, int(p[33][1]) + 1))
    return out


def shimmer(images, marks):
    steps = []
    for t in range(1, len(images)):
        a, b = grey(images[t - 1].astype(float)), grey(images[t].astype(float))
        for x0, y0, x1, y1 in boxes(marks[t]):
            steps.append(np.abs(b[y0:y1, x0:x1] - a[y0:y1, x0:x1]).mean())
    return float(np.mean(steps))


def main(folder, background):
    files = sorted(glob.glob(f"{folder}/frames/*.png"))
    synth = np.stack([np.asarray(Image.open(f).convert("RGB")) for f in files])
    marks = np.load(f"{folder}/landmarks.npy")
    h, w = synth.shape[1:3]
    real = frames_of(background, w, h, len(synth))
    print(f"cheek shimmer (grey levels a frame): synthesis {shimmer(synth, marks):.2f}, "
          f"the video under it {shimmer(real, marks):.2f} ({len(synth)} frames)")


if __name__ == "__main__":
    main(*sys.argv[1:3])
