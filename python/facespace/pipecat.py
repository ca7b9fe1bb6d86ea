"""A facespace face for pipecat: a frame processor (``pip install ./python[pipecat]``).

Put it after the TTS service. Each ``TTSAudioRawFrame`` goes into a live session; the processor
pushes an ``OutputImageRawFrame`` per video frame followed by the TTS sound under it (re-timed
to the frames, so transport playback keeps them together), and the rest of the speech on
``TTSStoppedFrame``. An ``InterruptionFrame`` drops what is being said: the next image is the
talker's footage. Other frames pass through.

The phones come from the sound, recognised as it arrives — unless the TTS service gives word
timestamps (Cartesia, ElevenLabs, Rime, …: ``TTSTextFrame`` s whose ``pts`` is the word's
start) and ``word_timestamps=True``: then each word is aligned to its own stretch of the
sound, so the lips close on the sound's own /p b m/. The words' times are taken as pipecat's
TTS services set them: from the clock at the speech's first audio frame. The trade: from the
sound a frame leaves within 200 ms of its sound (BENCHMARKS "Python package": 153–161 ms at
95 % on one core); with word timestamps it waits for the next word's start (about a word,
the last word for the sentence's end), which costs nothing when the TTS delivers its sound
ahead of playback, as streaming services do.

Recognition, synthesis and each picture's drawing run on worker threads (``asyncio.to_thread``),
as the LiveKit adapter's do: the event loop only hands frames on.

    from pipecat.pipeline.pipeline import Pipeline
    import facespace
    from facespace.pipecat import FacespaceVideoProcessor

    face = FacespaceVideoProcessor(facespace.Talker("models/grid"), size=(512, 512))
    pipeline = Pipeline([transport.input(), stt, llm, tts, face, transport.output()])
"""

from __future__ import annotations

import asyncio
from typing import Callable, Iterator, Optional, Tuple

import numpy as np

from pipecat.frames.frames import (
    Frame,
    InterruptionFrame,
    OutputAudioRawFrame,
    OutputImageRawFrame,
    TTSAudioRawFrame,
    TTSStoppedFrame,
    TTSTextFrame,
)
from pipecat.processors.frame_processor import FrameDirection, FrameProcessor

from . import FacespaceError
from . import Frame as FaceFrame
from . import Talker, _Speech

__all__ = ["FacespaceVideoProcessor"]


class FacespaceVideoProcessor(FrameProcessor):
    """Video of ``talker`` speaking the TTS audio that passes through, in pictures of ``size``
    (width, height; the talker's own by default) fitted by ``fit`` (``"contain"`` or
    ``"cover"``). ``on_frame`` is called with each :class:`facespace.Frame` (its landmarks,
    whether the face speaks) before its image is pushed."""

    def __init__(
        self,
        talker: Talker,
        *,
        size: Optional[Tuple[int, int]] = None,
        fit: str = "contain",
        word_timestamps: bool = False,
        on_frame: Optional[Callable[[FaceFrame], None]] = None,
        **kwargs,
    ) -> None:
        super().__init__(**kwargs)
        self._talker = talker
        self._session = talker.session("words" if word_timestamps else "sound", size=size, fit=fit)
        self._words = word_timestamps
        self._on_frame = on_frame
        self._speech = _Speech(self._session)  # the TTS sound, handed back under its frames
        self._baseline: Optional[int] = None  # clock (ns) of the speech's first audio frame
        self._last_word_pts = 0
        # The session's work (recognition, synthesis, drawing) runs on a worker thread, never
        # on the event loop; one piece at a time, an interruption included.
        self._busy = asyncio.Lock()
        self.last_frame: Optional[FaceFrame] = None
        """The last frame pushed (its index, time and whether the face was synthesised)."""

    async def process_frame(self, frame: Frame, direction: FrameDirection) -> None:
        await super().process_frame(frame, direction)
        if isinstance(frame, InterruptionFrame):
            async with self._busy:
                self._session.clear()
                self._speech.drop()
                self._baseline = None
            await self.push_frame(frame, direction)
        elif isinstance(frame, TTSAudioRawFrame):
            async with self._busy:
                if not self._speech.active:
                    # As pipecat's word timestamp tracker sets its baseline.
                    self._baseline = max(self._last_word_pts, self.get_clock().get_time())
                await asyncio.to_thread(self._speech.push, frame.audio, frame.sample_rate, frame.num_channels)
                await self._push(self._session.pull, last=False)
        elif isinstance(frame, TTSTextFrame):
            if self._words and frame.pts and self._baseline is not None:
                async with self._busy:
                    self._last_word_pts = max(self._last_word_pts, frame.pts)
                    start = self._speech.origin + (frame.pts - self._baseline) / 1e9
                    try:
                        await asyncio.to_thread(self._session.push_words, [(frame.text, start)])
                    except FacespaceError:
                        pass  # a word out of order: its sound's phones are recognised instead
                    await self._push(self._session.pull, last=False)
            await self.push_frame(frame, direction)
        elif isinstance(frame, TTSStoppedFrame):
            async with self._busy:
                if self._speech.active:
                    await self._push(self._session.finish, last=True)
                    await self._push_sound(self._speech.end())
                    self._baseline = None
            await self.push_frame(frame, direction)
        else:
            await self.push_frame(frame, direction)

    async def _push(self, settle: Callable[[], Iterator[FaceFrame]], last: bool) -> None:
        """Settles the session (``pull`` or ``finish``) and pushes each frame, drawn as it is
        taken, with the sound under it — the settling and every drawing on a worker thread;
        with ``last``, all the speech's remaining sound goes after its last frame."""
        frames = await asyncio.to_thread(settle)
        face = await asyncio.to_thread(next, frames, None)
        while face is not None:
            after = await asyncio.to_thread(next, frames, None)
            await self._give(face, last and after is None)
            face = after

    async def _give(self, face: FaceFrame, last: bool) -> None:
        self.last_frame = face
        if self._on_frame is not None:
            self._on_frame(face)
        h, w, _ = face.image.shape
        await self.push_frame(OutputImageRawFrame(image=face.image.tobytes(), size=(w, h), format="RGB"))
        await self._push_sound(self._speech.under(face, last))

    async def _push_sound(self, chunk: Optional[np.ndarray]) -> None:
        """A piece of the speech's sound (``_Speech.under`` or ``end``), if any."""
        if chunk is not None:
            await self.push_frame(OutputAudioRawFrame(audio=chunk.tobytes(), sample_rate=self._speech.rate, num_channels=1))
