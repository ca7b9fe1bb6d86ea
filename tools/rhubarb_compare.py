"""Mouth-shape tracks of Rhubarb Lip Sync beside `facespace visemes`, on the same GRID clips.

Issue 34 asks, where a Rhubarb build is at hand (built from its source beside the project,
never committed), for its timing and shapes on GRID clips beside ours. Every track is sampled
every 10 ms (Rhubarb's own resolution) and compared with a reference: the shapes `facespace
visemes --labels` gives the clip's phones in `phones/` (forced-aligned to the true words).
That reference maps phones to shapes by *our* rule, which favours our rows; so every track is
also compared with Rhubarb's own given the true words (`--dialogFile`), which favours his.

    python3 tools/rhubarb_compare.py RHUBARB FACESPACE GRID WAVDIR [N|all] [SPLIT]

RHUBARB: the `rhubarb` binary; FACESPACE: ours (`target/release/facespace`); GRID: the corpus
folder (`../shared/data/grid-s1`); WAVDIR: 16 kHz WAVs of the split's clips (`ANCHORS=DIR cargo
run --release --example grid_phones -- GRID SPLIT all` writes them to DIR/wav); N clips (all)
of SPLIT (test).
Each command runs alone on one core (`--threads 1` for Rhubarb), timed from start to exit,
the loading of its models included.
"""
import os
import subprocess
import sys
import tempfile
import time
import wave

SILENT = "X"


def track(tsv, frames):
    """A TSV track (`start<TAB>shape` lines, the last the end) → one shape per 10 ms frame."""
    cues = []
    for line in tsv.strip().splitlines():
        start, shape = line.split("\t")
        cues.append((round(float(start) * 100), shape.strip()))
    out = [SILENT] * frames
    for (start, shape), (end, _) in zip(cues, cues[1:] + [(frames, SILENT)]):
        for t in range(max(start, 0), min(end, frames)):
            out[t] = shape
    return out


def sequence(frames):
    """The shapes in order, repeats joined, rest (X) left out."""
    seq = []
    for s in frames:
        if s != SILENT and (not seq or seq[-1] != s):
            seq.append(s)
    return seq


def edits(a, b):
    row = list(range(len(b) + 1))
    for i, x in enumerate(a, 1):
        prev, row[0] = row[0], i
        for j, y in enumerate(b, 1):
            prev, row[j] = row[j], min(row[j] + 1, row[j - 1] + 1, prev + (x != y))
    return row[-1]


def run(cmd):
    clock = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return out, time.perf_counter() - clock


def main():
    rhubarb, facespace, grid, wavs = sys.argv[1:5]
    split = sys.argv[6] if len(sys.argv) > 6 else "test"
    ids = open(os.path.join(grid, split + ".txt")).read().split()
    ids = [i for i in ids if os.path.exists(os.path.join(wavs, i + ".wav"))]
    if len(sys.argv) > 5 and sys.argv[5] != "all":
        ids = ids[: int(sys.argv[5])]
    one_core = ["taskset", "-c", "0"]
    rh = one_core + [rhubarb, "-q", "--threads", "1", "-f", "tsv"]
    fs = one_core + [facespace, "visemes"]
    systems = {
        "Rhubarb 1.14, its default recogniser (words, then their phones)": lambda w, d: rh + [w],
        "Rhubarb 1.14, its phonetic recogniser": lambda w, d: rh + ["-r", "phonetic", w],
        "Rhubarb 1.14, given the true words (--dialogFile)": lambda w, d: rh + ["-d", d, w],
        "facespace visemes, no words (the general acoustic model's loop)": lambda w, d: fs + [w],
        "facespace visemes, no words, the talker's ear (--talker models/grid)":
            lambda w, d: fs + [w, "--talker", "models/grid"],
        # The corpus's own words, scored as given (a few true transcripts fail the word check).
        "facespace visemes, the true words (--transcript)":
            lambda w, d: fs + [w, "--transcript", d, "--accept-mismatch"],
    }
    given_words = "Rhubarb 1.14, given the true words (--dialogFile)"
    tracks = {name: [] for name in systems}
    spent = {name: 0.0 for name in systems}
    references, seconds = [], 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for k, clip in enumerate(ids):
            wav = os.path.join(wavs, clip + ".wav")
            with wave.open(wav) as w:
                duration = w.getnframes() / w.getframerate()
            seconds += duration
            frames = int(duration * 100)
            words = [l.split()[2] for l in open(os.path.join(grid, "align", clip + ".align"))]
            dialog = os.path.join(tmp, clip + ".txt")
            with open(dialog, "w") as f:
                f.write(" ".join(w for w in words if w not in ("sil", "sp")) + "\n")
            lab = os.path.join(grid, "phones", clip + ".lab")
            out, _ = run(fs + [wav, "--labels", lab])
            references.append(track(out, frames))
            for name, cmd in systems.items():
                out, dt = run(cmd(wav, dialog))
                spent[name] += dt
                tracks[name].append(track(out, frames))
            print(f"{k + 1}/{len(ids)} {clip}", file=sys.stderr)

    def agreement(a, b, speech_only):
        same = total = 0
        for x, y in zip(a, b):
            for s, r in zip(x, y):
                if speech_only and r == SILENT:
                    continue
                same += s == r
                total += 1
        return same / total

    def sequence_error(a, b):
        errors = sum(edits(sequence(x), sequence(y)) for x, y in zip(a, b))
        return errors / sum(len(sequence(y)) for y in b)

    print(f"GRID s1 {split} split, {len(ids)} clips, {seconds:.1f} s of sound (recorded)\n")
    print("| track | frames as the phones' shapes (all / speech) | shape sequence error against the phones' | "
          "frames as Rhubarb's given the words (all / speech) | × real time, one core (models loaded each run) |")
    print("|---|---|---|---|---|")
    rows = [("the phones' shapes (`visemes --labels phones/ID.lab`: the reference)", references, None)]
    rows += [(name, tracks[name], spent[name]) for name in systems]
    for name, t, dt in rows:
        speed = f"{seconds / dt:.1f}×" if dt else "—"
        print(f"| {name} | {agreement(t, references, False):.3f} / {agreement(t, references, True):.3f} | "
              f"{sequence_error(t, references):.1%} | "
              f"{agreement(t, tracks[given_words], False):.3f} / {agreement(t, tracks[given_words], True):.3f} | "
              f"{speed} |")


if __name__ == "__main__":
    main()
