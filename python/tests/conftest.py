"""What the Python tests share: the repository, its GRID s1 talker, the recorded test clips
(GRID s1, committed in tests/data/grid) and the lip-closure check of the Rust tests
(tests/common/mod.rs, `closes_within`)."""

import pathlib
import wave

import numpy as np
import pytest

import facespace

ROOT = pathlib.Path(__file__).resolve().parents[2]
BILABIALS = {"P", "B", "M"}
# As tests/live.rs: lips resting closed before a sentence's first /b/ hold a plateau.
PLATEAU = 0.05


@pytest.fixture(scope="session")
def root():
    return ROOT


@pytest.fixture(scope="session")
def talker(root):
    return facespace.Talker(str(root / "models/grid"))


def grid_clip(clip_id):
    """A committed GRID s1 clip: mono int16 samples, the rate, its phones (.lab: phone,
    start, end in seconds) and its words with their start times (.align)."""
    data = ROOT / "tests/data/grid"
    with wave.open(str(data / f"{clip_id}.wav")) as w:
        assert w.getnchannels() == 1 and w.getsampwidth() == 2
        samples, rate = np.frombuffer(w.readframes(w.getnframes()), dtype="<i2"), w.getframerate()
    phones = []
    for line in (data / f"{clip_id}.lab").read_text().split("\n"):
        f = line.split()
        if len(f) == 3:
            phones.append((f[2].upper(), int(f[0]) / 1e7, int(f[1]) / 1e7))
    words = []
    for line in (data / f"{clip_id}.align").read_text().split("\n"):
        f = line.split()
        if len(f) == 3 and f[2] != "sil":
            words.append((f[2], int(f[0]) / 25000))
    return samples, rate, phones, words


@pytest.fixture(scope="session")
def clip():
    """bbbf9a's sound: mono int16 samples and the rate."""
    samples, rate, _, _ = grid_clip("bbbf9a")
    return samples, rate


def inner_height(landmarks):
    """Inner-mouth height of the iBUG points (facespace::eval::mouth::inner_mouth_height)."""
    return float(np.mean([landmarks[b][1] - landmarks[t][1] for t, b in [(61, 67), (62, 66), (63, 65)]]))


def closes_within(height, start, end, fps, plateau=PLATEAU):
    """None when the lips close for a phone at start…end s (the nearest local minimum of the
    opening to the phone's middle is within the phone ± one frame and at most half the widest
    opening within 150 ms); else why not."""
    middle = (start + end) / 2 * fps
    lo = max(int(np.floor((start - 0.15) * fps)), 0)
    hi = min(int(np.ceil((end + 0.15) * fps)), len(height) - 1)
    widest = max(height[lo : hi + 1])
    flat = plateau * widest
    minima = [
        k
        for k in range(1, len(height) - 1)
        if height[k] <= height[k - 1] + flat and height[k] <= height[k + 1] + flat
    ]
    if not minima:
        return "the lips never close"
    k = min(minima, key=lambda k: abs(k - middle))
    t = k / fps
    if t < start - 1 / fps - 1e-9 or t > end + 1 / fps + 1e-9:
        return f"the nearest closure is at frame {k} ({t:.2f} s)"
    if height[k] > 0.5 * widest:
        return f"frame {k} opens {height[k]:.2f} px of {widest:.2f}: not a closure"
    return None


def closures(frames, phones, fps, shift=0.0):
    """(bilabials whose lips close within a frame, bilabials, the failures) for frames given
    out in order from index 0 (facespace.Frame s)."""
    assert [f.index for f in frames] == list(range(len(frames)))
    height = [inner_height(f.landmarks) for f in frames]
    fails = []
    count = 0
    for phone, start, end in phones:
        if phone in BILABIALS:
            count += 1
            why = closes_within(height, start + shift, end + shift, fps)
            if why:
                fails.append(f"/{phone}/ {start:.2f}–{end:.2f} s: {why}")
    return count - len(fails), count, fails
