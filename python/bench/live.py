"""Benchmarks of the Python package in-process, on one core (issue 36): frames per second at
the talker's size, 512×512 and 1280×720 (pipecat's and LiveKit's usual sizes), sound-in to
frame-out latency at real time, peak resident memory, and memory over a long run at real time.

Recorded speech: the GRID s1 clips committed in tests/data/grid (bbbf9a, bbbs7a, bbwtzp),
spoken end to end, each finished as an utterance. Each configuration runs in a process of its
own, pinned to one core with one rayon thread, so its peak memory is its own.

    python python/bench/live.py              # the table: throughput, latency, peak RSS
    python python/bench/live.py memory 10    # 10 minutes at real time, RSS every 30 s
"""

from __future__ import annotations

import json
import os
import pathlib
import resource
import subprocess
import sys
import time
import wave

ROOT = pathlib.Path(__file__).resolve().parents[2]
CLIPS = ["bbbf9a", "bbbs7a", "bbwtzp"]
SIZES = {"native": None, "512x512": (512, 512), "1280x720": (1280, 720)}


def one_core():
    os.environ["RAYON_NUM_THREADS"] = "1"
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})


def clips():
    import numpy as np

    out = []
    for clip_id in CLIPS:
        with wave.open(str(ROOT / f"tests/data/grid/{clip_id}.wav")) as w:
            samples = np.frombuffer(w.readframes(w.getnframes()), dtype="<i2")
            words = []
            for line in (ROOT / f"tests/data/grid/{clip_id}.align").read_text().split("\n"):
                f = line.split()
                if len(f) == 3 and f[2] != "sil":
                    words.append((f[2], int(f[0]) / 25000))
            out.append((samples, w.getframerate(), words))
    return out


def rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def consume(frames, on_frames):
    """Draws the frames (they are drawn as iterated), handing them one by one to `on_frames`."""
    for f in frames:
        if on_frames:
            on_frames(f)


def speak(session, samples, rate, words, offset, paced_from=None, on_frames=None):
    """Pushes one clip in 20 ms chunks (its words as their sound arrives when the session
    takes words), then finishes it. With `paced_from`, each chunk waits for its moment of a
    real-time clock started then; `on_frames(frame)` gets each frame as it is drawn."""
    step = rate // 50
    words = list(words) if words is not None else None
    for k in range(0, len(samples), step):
        t = offset + (k + step) / rate
        if paced_from is not None:
            wait = paced_from + t - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        if words is not None:
            while words and offset + words[0][1] <= t:
                w, s = words.pop(0)
                session.push_words([(w, offset + s)])
        session.push_audio(samples[k : k + step], rate)
        consume(session.pull(), on_frames)
    consume(session.finish(), on_frames)


def idle_second(session, start):
    """A second of idle footage at the frame rate of a real-time clock started at `start`."""
    for _ in range(int(session.fps)):
        consume(session.idle_until(session.next_frame + 1), None)
        wait = start + session.next_frame / session.fps - time.perf_counter()
        if wait > 0:
            time.sleep(wait)


def throughput(size_name, given, repeats=4):
    """Frames per second with sound pushed as fast as it is drawn."""
    import facespace

    talker = facespace.Talker(str(ROOT / "models/grid"))
    session = talker.session(given=given, size=SIZES[size_name])
    material = clips()
    frames = 0
    seconds = 0.0

    def count(_):
        nonlocal frames
        frames += 1

    start = time.perf_counter()
    for _ in range(repeats):
        for samples, rate, words in material:
            speak(session, samples, rate, words if given == "words" else None, session.seconds, on_frames=count)
            seconds += len(samples) / rate
    wall = time.perf_counter() - start
    return {"frames": frames, "speech_s": round(seconds, 2), "fps": round(frames / wall, 1)}


def latency(size_name, given):
    """Sound-in to frame-out at real time: for each frame, the wall time it is given out
    minus the wall time its sound (to the frame's end) had been pushed."""
    import facespace

    talker = facespace.Talker(str(ROOT / "models/grid"))
    session = talker.session(given=given, size=SIZES[size_name])
    fps = talker.fps
    lags = []
    start = time.perf_counter()

    def note(f):
        lags.append(time.perf_counter() - start - (f.index + 1) / fps)

    for samples, rate, words in clips():
        speak(session, samples, rate, words if given == "words" else None, session.seconds, start, note)
        # Between utterances: idle footage at the frame rate for a second.
        idle_second(session, start)
    lags.sort()
    q = lambda p: round(1000 * lags[min(len(lags) - 1, int(p * len(lags)))])
    return {"p50_ms": q(0.5), "p95_ms": q(0.95), "max_ms": round(1000 * lags[-1])}


def run_one(kind, size_name, given):
    one_core()
    out = {"kind": kind, "size": size_name, "given": given}
    out.update(throughput(size_name, given) if kind == "throughput" else latency(size_name, given))
    out["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    print(json.dumps(out))


def memory(minutes):
    """`minutes` of speech and pauses at real time (each clip, then a second of idle
    footage), resident memory every 30 s."""
    one_core()
    import facespace

    talker = facespace.Talker(str(ROOT / "models/grid"))
    session = talker.session(size=(512, 512))
    start = time.perf_counter()
    material = clips()
    marks, next_mark = [], 0.0
    while time.perf_counter() - start < minutes * 60:
        for samples, rate, _ in material:
            speak(session, samples, rate, None, session.seconds, start)
            idle_second(session, start)
            now = time.perf_counter() - start
            if now >= next_mark:
                marks.append((round(now), round(rss_mb(), 1)))
                print(f"{marks[-1][0]:5d} s  {marks[-1][1]} MB", flush=True)
                next_mark += 30
    first = next(m for t, m in marks if t >= 30)
    print(json.dumps({"minutes": minutes, "rss_after_30s_mb": first, "rss_end_mb": marks[-1][1],
                      "rss_max_mb": max(m for _, m in marks), "frames": session.next_frame}))


def table():
    rows = []
    for kind in ["throughput", "latency"]:
        for given in ["sound", "words"]:
            for size in SIZES if kind == "throughput" else ["512x512"]:
                out = subprocess.run([sys.executable, __file__, "one", kind, size, given],
                                     check=True, capture_output=True, text=True).stdout
                rows.append(json.loads(out.strip().splitlines()[-1]))
                print(rows[-1], file=sys.stderr, flush=True)
    print("| measure | phones from | size | result | peak RSS |")
    print("|---|---|---|---|---|")
    for r in rows:
        if r["kind"] == "throughput":
            result = f"**{r['fps']} fps** ({r['frames']} frames, {r['speech_s']} s of speech)"
        else:
            result = f"p50 **{r['p50_ms']} ms**, p95 **{r['p95_ms']} ms**, worst {r['max_ms']} ms"
        print(f"| {r['kind']} | {r['given']} | {r['size']} | {result} | {r['peak_rss_mb']} MB |")


if __name__ == "__main__":
    args = sys.argv[1:]
    if args[:1] == ["one"]:
        run_one(*args[1:4])
    elif args[:1] == ["memory"]:
        memory(float(args[1]) if len(args) > 1 else 10)
    else:
        table()
