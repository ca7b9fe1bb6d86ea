"""What the Python tests share: the repository, its GRID s1 talker, and the recorded test
clip bbbf9a (GRID s1, committed in tests/data/grid)."""

import pathlib
import wave

import numpy as np
import pytest

import facespace


@pytest.fixture(scope="session")
def root():
    return pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def talker(root):
    return facespace.Talker(str(root / "models/grid"))


@pytest.fixture(scope="session")
def clip(root):
    """bbbf9a's sound: mono int16 samples and the rate."""
    with wave.open(str(root / "tests/data/grid/bbbf9a.wav")) as w:
        assert w.getnchannels() == 1 and w.getsampwidth() == 2
        return np.frombuffer(w.readframes(w.getnframes()), dtype="<i2"), w.getframerate()
