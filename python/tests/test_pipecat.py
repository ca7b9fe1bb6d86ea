"""The pipecat processor driven as a pipeline drives it, offline (pipecat's own run_test):
a GRID clip's sound as TTS audio frames between TTSStarted/TTSStopped in; images and the
re-timed sound out. Recorded speech: GRID s1's test clip bbbf9a."""

import asyncio

import pytest

frames_mod = pytest.importorskip("pipecat.frames.frames")
test_utils = pytest.importorskip("pipecat.tests.utils")

from facespace.pipecat import FacespaceVideoProcessor


def tts(samples, rate):
    step = rate // 50
    return [
        frames_mod.TTSAudioRawFrame(audio=samples[k : k + step].tobytes(), sample_rate=rate, num_channels=1)
        for k in range(0, len(samples), step)
    ]


def test_images_and_sound_stay_together(talker, clip):
    samples, rate = clip
    face = FacespaceVideoProcessor(talker)
    sent = [frames_mod.TTSStartedFrame(), *tts(samples, rate), frames_mod.TTSStoppedFrame()]
    down, _ = asyncio.run(test_utils.run_test(face, frames_to_send=sent))
    images, heard, worst = 0, 0, 0.0
    for f in down:
        if isinstance(f, frames_mod.OutputImageRawFrame):
            images += 1
            assert f.size == talker.size and len(f.image) == talker.size[0] * talker.size[1] * 3
            worst = max(worst, abs(heard / rate - (images - 1) / talker.fps))
        elif isinstance(f, frames_mod.TTSAudioRawFrame):
            pytest.fail("the TTS audio passed through un-timed")
        elif isinstance(f, frames_mod.OutputAudioRawFrame):
            heard += f.num_frames
    assert heard == len(samples)
    expected = len(samples) / rate * talker.fps
    assert abs(images - expected) <= 1, (images, expected)
    assert worst <= 1 / talker.fps + 1e-9, worst
    assert any(isinstance(f, frames_mod.TTSStoppedFrame) for f in down)


def test_an_interruption_returns_to_the_footage(talker, clip):
    samples, rate = clip
    face = FacespaceVideoProcessor(talker)
    # A system frame overtakes queued data: the sleep lets the speech through first.
    sent = [
        frames_mod.TTSStartedFrame(),
        *tts(samples[: rate * 2], rate),
        test_utils.SleepFrame(sleep=1.0),
        frames_mod.InterruptionFrame(),
    ]
    down, _ = asyncio.run(test_utils.run_test(face, frames_to_send=sent))
    kinds = [type(f).__name__ for f in down]
    assert "InterruptionFrame" in kinds and "OutputImageRawFrame" in kinds[: kinds.index("InterruptionFrame")]
    # After the interruption the session is quiet: the next frame is the footage's own.
    after = face._session.idle_until(face._session.next_frame + 1)
    assert after and not after[0].face
