"""A facespace face for pipecat: a frame processor (``pip install ./python[pipecat]``).

Put it after the TTS service. Each ``TTSAudioRawFrame`` goes into a live session whose phones
are recognised as the sound comes; the processor pushes an ``OutputImageRawFrame`` per video
frame followed by the TTS sound under it (re-timed to the frames, so transport playback keeps
them together), and the rest of the speech on ``TTSStoppedFrame``. An ``InterruptionFrame``
drops what is being said: the next image is the talker's footage. Other frames pass through.

    from pipecat.pipeline.pipeline import Pipeline
    import facespace
    from facespace.pipecat import FacespaceVideoProcessor

    face = FacespaceVideoProcessor(facespace.Talker("models/grid"))
    pipeline = Pipeline([transport.input(), stt, llm, tts, face, transport.output()])
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from pipecat.frames.frames import (
    Frame,
    InterruptionFrame,
    OutputAudioRawFrame,
    OutputImageRawFrame,
    TTSAudioRawFrame,
    TTSStoppedFrame,
)
from pipecat.processors.frame_processor import FrameDirection, FrameProcessor

from . import Frame as FaceFrame
from . import Talker

__all__ = ["FacespaceVideoProcessor"]


class FacespaceVideoProcessor(FrameProcessor):
    """Video of ``talker`` speaking the TTS audio that passes through."""

    def __init__(self, talker: Talker, **kwargs) -> None:
        super().__init__(**kwargs)
        self._talker = talker
        self._session = talker.session()
        self._pending = np.zeros(0, dtype=np.int16)
        self._rate: Optional[int] = None
        self._start: Optional[int] = None  # frame where the speech's sound starts
        self._given = 0
        self.last_frame: Optional[FaceFrame] = None
        """The last frame pushed (its index, time and whether the face was synthesised)."""

    async def process_frame(self, frame: Frame, direction: FrameDirection) -> None:
        await super().process_frame(frame, direction)
        if isinstance(frame, InterruptionFrame):
            self._session.clear()
            self._pending = np.zeros(0, dtype=np.int16)
            self._start = None
            await self.push_frame(frame, direction)
        elif isinstance(frame, TTSAudioRawFrame):
            samples = np.frombuffer(frame.audio, dtype=np.int16)
            if frame.num_channels > 1:
                samples = samples.reshape(-1, frame.num_channels).mean(axis=1).astype(np.int16)
            if self._start is None:
                self._start, self._given = self._session.next_frame, 0
            self._rate = frame.sample_rate
            self._session.push_audio(samples, frame.sample_rate)
            self._pending = np.concatenate([self._pending, samples])
            await self._push(self._session.pull(), last=False)
        elif isinstance(frame, TTSStoppedFrame):
            if self._start is not None:
                await self._push(self._session.finish(), last=True)
                self._start = None
            await self.push_frame(frame, direction)
        else:
            await self.push_frame(frame, direction)

    async def _push(self, frames, last: bool) -> None:
        for k, face in enumerate(frames):
            self.last_frame = face
            h, w, _ = face.image.shape
            await self.push_frame(OutputImageRawFrame(image=face.image.tobytes(), size=(w, h), format="RGB"))
            if self._start is None or self._rate is None:
                continue
            if last and k == len(frames) - 1:
                end = self._given + len(self._pending)
            else:
                end = int(round((face.index + 1 - self._start) / self._talker.fps * self._rate))
            n = max(0, min(end - self._given, len(self._pending)))
            if n:
                chunk, self._pending = self._pending[:n], self._pending[n:]
                self._given += n
                await self.push_frame(OutputAudioRawFrame(audio=chunk.tobytes(), sample_rate=self._rate, num_channels=1))
