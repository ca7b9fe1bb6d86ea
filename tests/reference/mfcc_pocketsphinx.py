#!/usr/bin/env python3
"""Reference values for the MFCC front end (tests/align.rs): PyPI pocketsphinx 5.1.1's own
front end (its bundled en-us model's feat.params: 25 filters 130-6800 Hz, DCT, lifter 22,
noise removal, batch CMN) on the committed GRID clips' audio.

pocketsphinx does not expose its cepstra, but with batch CMN it reports the utterance's
cepstral mean (the mean of the 13 cepstra over the frames whose c0 >= 0): a check of the
whole front end, frame by frame summed. A fresh decoder gives the mean with the noise
estimate starting at the first frame; a second pass over the same audio gives it with the
estimate carried over from the first pass (what the aligner's warm front end computes).

    python3 tests/reference/mfcc_pocketsphinx.py > tests/data/grid/mfcc_pocketsphinx.json
"""
import json, wave
from pocketsphinx import Decoder

out = {}
for cid in ["bbbf9a", "bbbs7a", "bbwtzp"]:
    with wave.open(f"tests/data/grid/{cid}.wav", "rb") as w:
        pcm = w.readframes(w.getnframes())
    dec = Decoder(loglevel="FATAL")
    means = []
    for _ in range(2):
        dec.start_utt()
        dec.process_raw(pcm, full_utt=True)
        means.append([float(v) for v in dec.get_cmn().split(",")])
        dec.end_utt()
    out[cid] = {"fresh": means[0], "warm": means[1], "frames": dec.n_frames()}
print(json.dumps(out, indent=1))
