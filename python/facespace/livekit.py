"""A facespace face for LiveKit Agents: a ``VideoGenerator`` for
``livekit.agents.voice.avatar`` (``pip install ./python[livekit]``).

The agent's speech (``rtc.AudioFrame`` s, then ``AudioSegmentEnd``) goes into a live session
whose phones are recognised as the sound comes; iteration yields each video frame followed by
the sound that plays under it (re-timed to the frames, so the ``AVSynchronizer`` keeps them
together), ``AudioSegmentEnd`` after a segment's last frame, and the talker's own footage while
nothing is said. ``clear_buffer()`` drops what is being said: the next frame is the footage's
own face.

    from livekit.agents.voice.avatar import AvatarRunner
    import facespace
    from facespace.livekit import FacespaceVideoGenerator

    talker = facespace.Talker("models/grid")
    video = FacespaceVideoGenerator(talker, size=(1280, 720))
    runner = AvatarRunner(room, audio_recv=audio_receiver, video_gen=video, options=video.options())
    await runner.start()
"""

from __future__ import annotations

import asyncio
from typing import AsyncIterator, Callable, Optional, Tuple, Union

import numpy as np
from livekit import rtc
from livekit.agents.voice.avatar import AudioSegmentEnd, AvatarOptions, VideoGenerator

from . import Frame, Talker, _Speech

__all__ = ["FacespaceVideoGenerator"]


class FacespaceVideoGenerator(VideoGenerator):
    """Video (and re-timed sound at ``sample_rate``) of ``talker`` speaking the audio pushed
    into it, in pictures of ``size`` (width, height; the talker's own by default) fitted by
    ``fit`` (``"contain"`` or ``"cover"``). ``on_frame`` is called with each
    :class:`facespace.Frame` (its landmarks, whether the face speaks) as it is given out."""

    def __init__(
        self,
        talker: Talker,
        *,
        sample_rate: int = 24000,
        size: Optional[Tuple[int, int]] = None,
        fit: str = "contain",
        on_frame: Optional[Callable[[Frame], None]] = None,
    ) -> None:
        self._talker = talker
        self._session = talker.session(size=size, fit=fit)
        self._on_frame = on_frame
        self._sample_rate = sample_rate
        self._queue: "asyncio.Queue[Union[rtc.AudioFrame, AudioSegmentEnd]]" = asyncio.Queue()
        self._speech = _Speech(self._session)  # the segment's sound, handed back under its frames
        self._ended = False
        self._clears = 0  # interruptions so far: a batch being given out stops at one
        self.last_frame: Optional[Frame] = None
        """The last frame given out (its index, time and whether the face was synthesised)."""

    def options(self) -> AvatarOptions:
        """The ``AvatarOptions`` this generator's frames and sound have."""
        w, h = self._session.size
        return AvatarOptions(
            video_width=w,
            video_height=h,
            video_fps=self._talker.fps,
            audio_sample_rate=self._sample_rate,
            audio_channels=1,
        )

    async def push_audio(self, frame: Union[rtc.AudioFrame, AudioSegmentEnd]) -> None:
        self._queue.put_nowait(frame)

    def clear_buffer(self) -> None:
        while not self._queue.empty():
            self._queue.get_nowait()
        self._session.clear()
        self._speech.drop()
        self._ended = False
        self._clears += 1

    def __aiter__(self) -> AsyncIterator[Union[rtc.VideoFrame, rtc.AudioFrame, AudioSegmentEnd]]:
        return self._stream()

    def _take(self, item: Union[rtc.AudioFrame, AudioSegmentEnd]) -> None:
        if isinstance(item, AudioSegmentEnd):
            if self._speech.active:
                self._ended = True
            return
        rate = self._speech.rate
        if rate is not None and item.sample_rate != rate:
            raise ValueError(f"audio at {item.sample_rate} Hz after {rate} Hz")
        self._speech.push(item.data, item.sample_rate, item.num_channels)

    def _video(self, frame: Frame) -> rtc.VideoFrame:
        self.last_frame = frame
        if self._on_frame is not None:
            self._on_frame(frame)
        h, w, _ = frame.image.shape
        rgba = np.empty((h, w, 4), dtype=np.uint8)
        rgba[..., :3] = frame.image
        rgba[..., 3] = 255
        return rtc.VideoFrame(w, h, rtc.VideoBufferType.RGBA, rgba.tobytes())

    def _sound(self, chunk: Optional[np.ndarray]) -> Optional[rtc.AudioFrame]:
        """A piece of the segment's sound (``_Speech.under`` or ``end``), resampled to the
        output rate by taking the session's clock."""
        if chunk is None:
            return None
        rate, n = self._speech.rate, len(chunk)
        if rate != self._sample_rate:
            x = np.arange(int(round(n * self._sample_rate / rate))) * (rate / self._sample_rate)
            chunk = np.interp(x, np.arange(n), chunk.astype(np.float64)).round().astype(np.int16)
        return rtc.AudioFrame(chunk.tobytes(), self._sample_rate, 1, len(chunk))

    async def _stream(self) -> AsyncIterator[Union[rtc.VideoFrame, rtc.AudioFrame, AudioSegmentEnd]]:
        while True:
            # Up to a segment's end: what follows it is the next segment's, queued until then.
            while not self._ended and not self._queue.empty():
                self._take(self._queue.get_nowait())
            if not self._speech.active:
                # Nothing said: the footage as it is, one frame at a time (the synchroniser paces).
                for frame in self._session.idle_until(self._session.next_frame + 1):
                    yield self._video(frame)
                await asyncio.sleep(0)
                continue
            ending, clears = self._ended, self._clears
            # Settling runs the synthesis; each picture is then drawn as it is given out, both
            # off the event loop.
            frames = await asyncio.to_thread(self._session.finish if ending else self._session.pull)
            frame = await asyncio.to_thread(next, frames, None)
            given = 0
            while frame is not None and self._clears == clears:
                after = await asyncio.to_thread(next, frames, None)
                yield self._video(frame)
                sound = self._sound(self._speech.under(frame, ending and after is None))
                if sound is not None:
                    yield sound
                frame, given = after, given + 1
            if self._clears != clears:
                continue
            if ending:
                rest = self._sound(self._speech.end())
                if rest is not None:
                    yield rest
                self._ended = False
                yield AudioSegmentEnd()
            elif not given:
                try:
                    self._take(await asyncio.wait_for(self._queue.get(), 1 / self._talker.fps))
                except asyncio.TimeoutError:
                    pass
