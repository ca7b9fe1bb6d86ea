#!/usr/bin/env python3
"""Reference forced alignment with PyPI pocketsphinx 5.x, for benchmarks only (never a run-time
dependency of facespace): the settings that made ../shared/data/grid-s1/phones/ (bundled
en-us model and dictionary, beams 1e-80 / 1e-60 / 1e-80, silprob 0.1, a word pass then a
phone pass).

    python3 tools/pocketsphinx_align.py WAV_DIR LIST.tsv [OUT_DIR]

LIST.tsv: `id<TAB>words` lines; WAV_DIR/id.wav: 16 kHz mono 16-bit. Prints the time per clip
(both passes, front end included, one thread); with OUT_DIR writes id.lab (HTK, 100 ns).
"""
import sys, time, wave
from pocketsphinx import Decoder

def main():
    wav_dir, listing = sys.argv[1], sys.argv[2]
    out_dir = sys.argv[3] if len(sys.argv) > 3 else None
    t0 = time.perf_counter()
    dec = Decoder(beam=1e-80, wbeam=1e-60, pbeam=1e-80, silprob=0.1, bestpath=False, loglevel="FATAL")
    load = time.perf_counter() - t0
    items = [l.split("\t", 1) for l in open(listing).read().splitlines() if l.strip()]
    pcm = {}
    for cid, _ in items:
        with wave.open(f"{wav_dir}/{cid}.wav", "rb") as w:
            pcm[cid] = w.readframes(w.getnframes())
    spent = 0.0
    for cid, words in items:
        t = time.perf_counter()
        dec.set_align_text(words)
        dec.start_utt(); dec.process_raw(pcm[cid], full_utt=True); dec.end_utt()
        dec.set_alignment()
        dec.start_utt(); dec.process_raw(pcm[cid], full_utt=True); dec.end_utt()
        al = dec.get_alignment()
        phones = [(p.start, p.duration, p.name) for p in al.phones()]
        spent += time.perf_counter() - t
        if out_dir:
            with open(f"{out_dir}/{cid}.lab", "w") as f:
                for s, d, n in phones:
                    f.write(f"{s * 100000} {(s + d) * 100000} {n}\n")
    print(f"pocketsphinx model load ms: {load * 1e3:.0f}")
    print(f"pocketsphinx ms per clip: {spent * 1e3 / len(items):.2f}")

if __name__ == "__main__":
    main()
