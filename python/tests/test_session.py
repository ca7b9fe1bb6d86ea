"""The Python package against the library (issue 36): frames follow the sound, an
interruption returns to the footage at once, bad input raises with the library's message.
Recorded speech: GRID s1's test clip bbbf9a (committed in tests/data/grid)."""


import numpy as np
import pytest

import facespace


def test_frames_follow_the_sound(talker, clip):
    samples, rate = clip
    session = talker.session()
    frames = []
    step = rate // 25  # 40 ms chunks
    for k in range(0, len(samples), step):
        session.push_audio(samples[k : k + step], rate)
        frames += session.pull()
    frames += session.finish()
    expected = len(samples) / rate * talker.fps
    assert abs(len(frames) - expected) <= 1, (len(frames), expected)
    assert [f.index for f in frames] == list(range(len(frames)))
    w, h = talker.size
    for f in frames:
        assert f.image.shape == (h, w, 3) and f.image.dtype == np.uint8
        assert abs(f.time - f.index / talker.fps) < 1e-9
    speaking = sum(f.speaking for f in frames)
    assert speaking >= 25, speaking
    # Sync: speech sits where the clip's words are (GRID opens and closes on silence).
    assert not any(f.speaking for f in frames[-10:])


def test_bytes_and_float_arrays_give_the_same_frames(talker, clip):
    samples, rate = clip
    a, b = talker.session(), talker.session()
    a.push_audio(samples.tobytes(), rate)
    b.push_audio(samples.astype(np.float32) / 32768.0, rate)
    fa, fb = a.pull() + a.finish(), b.pull() + b.finish()
    assert len(fa) == len(fb)
    assert all(np.array_equal(x.image, y.image) for x, y in zip(fa, fb))


def test_an_interruption_returns_to_the_footage_at_once(talker, clip):
    samples, rate = clip
    session = talker.session()
    quiet = session.idle_until(10)
    assert len(quiet) == 10 and not any(f.face for f in quiet)
    session.push_audio(samples[: rate * 2], rate)
    spoken = session.pull()
    assert any(f.face for f in spoken)
    session.clear()
    after = session.idle_until(session.next_frame + 3)
    assert after and not any(f.face for f in after), [f.face for f in after]


def test_bad_input_raises_with_the_library_message(talker, root):
    session = talker.session()
    with pytest.raises(facespace.FacespaceError, match="int16, float32"):
        session.push_audio(np.zeros(640, dtype=np.int32), 16000)
    with pytest.raises(facespace.FacespaceError, match="Hz"):
        session.push_audio(np.zeros(640, dtype=np.int16), 12345)
    with pytest.raises(facespace.FacespaceError, match="mono"):
        session.push_audio(np.zeros((640, 2), dtype=np.int16), 16000)
    with pytest.raises(facespace.FacespaceError, match="even"):
        session.push_audio(b"\x00\x01\x02", 16000)
    with pytest.raises(facespace.FacespaceError, match="unknown phone"):
        session.push_phones([("zz", 0.0, 0.1)])
    session.push_audio(np.zeros(640, dtype=np.int16), 16000)
    with pytest.raises(facespace.FacespaceError, match="Hz"):
        session.push_audio(np.zeros(1920, dtype=np.int16), 48000)
    session.close()
    with pytest.raises(facespace.FacespaceError, match="closed"):
        session.pull()
    with pytest.raises(facespace.FacespaceError):
        facespace.Talker(str(root / "models/demo"))
    with pytest.raises(facespace.FacespaceError):
        facespace.Talker("/no/such/talker")
