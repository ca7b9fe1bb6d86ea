"""facespace: a talking face from a statistical appearance model, in Python.

A :class:`Talker` is a talker folder (``facespace talker build``; the repository ships GRID
s1's as ``models/grid``). Its :meth:`Talker.session` is a live session: push speech as it
arrives — sound, and the words or phones with their times when a text-to-speech engine gives
them — and take video frames (``numpy.uint8`` arrays, height × width × 3, in the talker's size
or the one asked for) each with its presentation time and the face's landmarks, drawn on the
CPU over the talker's own footage; while nothing is said the footage plays as it is.
:meth:`Talker.say` writes an MP4 with sound.

Errors raise :class:`FacespaceError` with the library's message.
"""

from __future__ import annotations

import json
import os
import pathlib
from dataclasses import dataclass
from typing import Iterable, Iterator, Optional, Tuple, Union

import numpy as np

# A wheel carries the en-us acoustic model beside the package (see python/README.md); a build
# from the source tree finds the committed one itself.
_MODEL = pathlib.Path(__file__).parent / "models" / "en-us"
if _MODEL.is_dir():
    os.environ.setdefault("FACESPACE_ACOUSTIC_MODEL", str(_MODEL))

from ._facespace import BUILT_FROM as _BUILT_FROM
from ._facespace import FacespaceError, LiveSession as _LiveSession, Talker as _Talker

__all__ = ["FacespaceError", "Frame", "LiveSession", "Talker", "default_talker"]


def default_talker() -> pathlib.Path:
    """The talker folder used when none is named: ``FACESPACE_TALKER`` when set, else GRID s1's
    (``models/grid``) in the checkout the package was built from, wherever Python runs."""
    given = os.environ.get("FACESPACE_TALKER")
    if given:
        return pathlib.Path(given)
    committed = pathlib.Path(_BUILT_FROM).resolve() / "models" / "grid"
    if committed.is_dir():
        return committed
    raise FacespaceError(
        "no default talker: name a talker folder (facespace talker build), or set FACESPACE_TALKER"
    )


@dataclass
class Frame:
    """One video frame of a live session."""

    index: int
    """Frame number since the session began."""
    time: float
    """Presentation time, seconds of the session's sound (``index / fps``)."""
    image: np.ndarray
    """The picture, ``uint8``, height × width × 3 (RGB)."""
    landmarks: np.ndarray
    """The face's 68 iBUG landmarks in the picture's pixels, ``float32``, 68 × 2 (x, y): the
    face drawn, or the footage's own as tracked."""
    face: bool
    """Whether the face was synthesised (speech, or a pause in it), not the footage's own."""
    speaking: bool
    """Whether a phone (not silence) is spoken at it."""


class _Video:
    """What a talker and its sessions share: the video's rate and size."""

    _inner: Union[_Talker, _LiveSession]

    @property
    def fps(self) -> float:
        """Frames per second of the talker's video."""
        return self._inner.fps

    @property
    def size(self) -> Tuple[int, int]:
        """(width, height) of its frames."""
        return self._inner.size


class Talker(_Video):
    """A talker folder, loaded once per process."""

    def __init__(self, path: Optional[Union[str, os.PathLike]] = None) -> None:
        """The talker folder ``path``; without one, :func:`default_talker`."""
        self._inner = _Talker(str(default_talker() if path is None else path))

    @property
    def name(self) -> str:
        return self._inner.name

    def session(
        self,
        given: str = "sound",
        size: Optional[Tuple[int, int]] = None,
        fit: str = "contain",
    ) -> "LiveSession":
        """A live session. ``given`` says where its phones come from: ``"sound"``, recognised
        as the sound arrives (the default; lag about 0.2 s); ``"words"``, aligned to words
        given with their start times (:meth:`LiveSession.push_words`, a TTS's word
        timestamps); ``"phones"``, given with their times (:meth:`LiveSession.push_phones`).
        ``size`` is the pictures' (width, height), the talker's own by default; a picture of
        another aspect ratio is fitted by ``fit``: ``"contain"`` (all of it, black bars) or
        ``"cover"`` (the frame filled, the excess cut off)."""
        if size is not None:
            size = (int(size[0]), int(size[1]))
        return LiveSession(self._inner.session(str(given), size, str(fit)))

    def speak(self, text: str) -> Tuple[np.ndarray, int, list]:
        """``text`` spoken in the talker's voice (a text-to-speech engine, as :meth:`say`):
        its sound (``int16``, mono), the rate, and its phones aligned to it (ARPAbet, start,
        end, seconds). A session made with ``given="phones"`` turns them into frames::

            samples, rate, phones = talker.speak("Please call me tomorrow.")
            session = talker.session(given="phones")
            session.push_phones(phones)
            session.push_audio(samples, rate)
            frames = list(session.pull()) + list(session.finish())
        """
        pcm, rate, phones = self._inner.speak(str(text))
        return np.frombuffer(pcm, dtype="<i2"), rate, phones

    def say(
        self,
        out: str,
        text: Optional[str] = None,
        audio: Optional[str] = None,
        words: Optional[str] = None,
    ) -> dict:
        """Says ``text`` (text-to-speech in the talker's voice) or the recording ``audio``
        (aligned to ``words``; without them the lips are predicted from the sound by the
        talker's sound-to-face map, or follow phones recognised in it) into the MP4 ``out``;
        returns the report."""
        return json.loads(self._inner.say(str(out), text, None if audio is None else str(audio), words))


AudioLike = Union[bytes, bytearray, memoryview, np.ndarray]


def _samples(samples: AudioLike) -> bytes:
    """Mono samples as little-endian float32 bytes: int16 (bytes, or an int16 array) scaled
    to −1…1, float32/float64 arrays as they are."""
    if isinstance(samples, (bytes, bytearray, memoryview)):
        raw = bytes(samples)
        if len(raw) % 2:
            raise FacespaceError("int16 PCM bytes: the byte count must be even")
        return (np.frombuffer(raw, dtype="<i2").astype(np.float32) / 32768.0).astype("<f4").tobytes()
    if not isinstance(samples, np.ndarray):
        raise FacespaceError(f"audio must be bytes or a numpy array, not {type(samples).__name__}")
    if samples.ndim == 2 and 1 in samples.shape:
        samples = samples.reshape(-1)
    if samples.ndim != 1:
        raise FacespaceError(f"audio must be mono (one channel), got shape {samples.shape}")
    if samples.dtype == np.int16:
        return (samples.astype(np.float32) / 32768.0).astype("<f4").tobytes()
    if samples.dtype in (np.float32, np.float64):
        return samples.astype("<f4").tobytes()
    raise FacespaceError(f"audio samples must be int16, float32 or float64, not {samples.dtype}")


class LiveSession(_Video):
    """A live session on a talker (see the module's documentation)."""

    def __init__(self, inner: _LiveSession) -> None:
        self._inner = inner

    @property
    def next_frame(self) -> int:
        """The index the next frame will have."""
        return self._inner.next_frame

    @property
    def seconds(self) -> float:
        """Seconds of sound taken: the session time at which the next chunk starts."""
        return self._inner.seconds

    def push_audio(self, samples: AudioLike, sample_rate: int) -> None:
        """Takes the next chunk of sound: int16 PCM bytes, or a numpy int16 / float32 array,
        mono, at ``sample_rate`` (8, 16, 22.05, 24 or 48 kHz; the same every call)."""
        self._inner.push_f32(_samples(samples), int(sample_rate))

    def push_phones(self, phones: Iterable[Tuple[str, float, float]]) -> None:
        """Phones with their times, session seconds: (ARPAbet phone, start, end), in order
        (a session made with ``given="phones"``)."""
        self._inner.push_phones([(str(p), float(s), float(e)) for p, s, e in phones])

    def push_words(self, words: Iterable[Tuple[str, float]]) -> None:
        """Words with their start times, session seconds: (word, start), in order (a session
        made with ``given="words"``). Each word is aligned to its stretch of the sound (to the
        next word's start) once that sound has been pushed."""
        self._inner.push_words([(str(w), float(s)) for w, s in words])

    def _drawn(self) -> Iterator[Frame]:
        w, h = self.size
        while True:
            p = self._inner.next_picture()
            if p is None:
                return
            i, t, b, points, face, speaking = p
            yield Frame(
                i,
                t,
                np.frombuffer(b, dtype=np.uint8).reshape(h, w, 3),
                np.frombuffer(points, dtype="<f4").reshape(-1, 2),
                face,
                speaking,
            )

    def pull(self) -> Iterator[Frame]:
        """The frames settled since the last call, in order. They are drawn as they are
        iterated (one picture in memory at a time); frames left un-iterated come first from
        the next call."""
        self._inner.pull()
        return self._drawn()

    def idle_until(self, index: int) -> Iterator[Frame]:
        """:meth:`pull`, and while nothing is said the footage as it is up to frame ``index``
        (not included): a video track keeps its rate between utterances."""
        self._inner.idle_until(int(index))
        return self._drawn()

    def finish(self) -> Iterator[Frame]:
        """Ends the utterance: all its remaining frames (drawn as they are iterated)."""
        self._inner.finish()
        return self._drawn()

    def clear(self) -> None:
        """An interruption: the next frame is the footage's own face."""
        self._inner.clear()

    def close(self) -> None:
        """Ends the session; later calls raise :class:`FacespaceError`."""
        self._inner.close()

    def __enter__(self) -> "LiveSession":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _Speech:
    """A stretch of a host's speech (int16 PCM, any channel count) going into a live session,
    and its sound handed back frame by frame so each frame goes out with the sound under it:
    what the LiveKit and pipecat adapters share."""

    def __init__(self, session: LiveSession) -> None:
        self._session = session
        self.start: Optional[int] = None
        """The frame where the speech's sound starts; ``None`` between stretches."""
        self.origin = 0.0
        """Session seconds where the speech's sound starts."""
        self.rate: Optional[int] = None
        """The sound's sample rate (the last one pushed)."""
        self._pending = np.zeros(0, dtype=np.int16)
        self._given = 0

    @property
    def active(self) -> bool:
        """Whether a stretch of speech is under way."""
        return self.start is not None

    def push(self, pcm: bytes, rate: int, channels: int) -> None:
        """Takes a chunk of the speech's sound (mixed down to mono)."""
        samples = np.frombuffer(pcm, dtype=np.int16)
        if channels > 1:
            samples = samples.reshape(-1, channels).mean(axis=1).astype(np.int16)
        if self.start is None:
            self.start, self._given = self._session.next_frame, 0
            self.origin = self._session.seconds
        self.rate = rate
        self._session.push_audio(samples, rate)
        self._pending = np.concatenate([self._pending, samples])

    def under(self, frame: Frame, last: bool) -> Optional[np.ndarray]:
        """The sound under ``frame`` not yet handed back (to the frame's end; with ``last``
        all of it), or ``None``."""
        if self.start is None or self.rate is None:
            return None
        if last:
            end = self._given + len(self._pending)
        else:
            end = int(round((frame.index + 1 - self.start) / self._session.fps * self.rate))
        n = max(0, min(end - self._given, len(self._pending)))
        if n == 0:
            return None
        chunk, self._pending = self._pending[:n], self._pending[n:]
        self._given += n
        return chunk

    def end(self) -> Optional[np.ndarray]:
        """The stretch is over: the sound not yet handed back (a stretch whose last frame came
        before its sound's end, or that gave no frame at all), or ``None``. It goes out now, so
        none of it lands under the next stretch's first frame."""
        rest, self._pending = self._pending, np.zeros(0, dtype=np.int16)
        self.start = None
        return rest if len(rest) else None

    def drop(self) -> None:
        """An interruption: the sound not yet handed back is dropped."""
        self._pending = np.zeros(0, dtype=np.int16)
        self.start = None
