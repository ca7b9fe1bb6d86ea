"""Phones recognised by PyPI pocketsphinx (5.1.1) from 16 kHz WAVs, the issue-34 anchors.

Two routes, both on pocketsphinx's own en-us model (the one facespace's aligner reads):
- allphone: the phone loop with its phone language model `en-us-phone.lm.bin`, the settings of
  CMU's phoneme-recognition tutorial (-allphone_ci yes -beam 1e-20 -pbeam 1e-20 -lw 2.0);
- words: Rhubarb Lip Sync's route, words recognised with the general English language model
  (`en-us.lm.bin`, defaults), each turned into the pronunciation the decoder chose.

    pip install pocketsphinx==5.1.1
    python3 tests/reference/pocketsphinx_phones.py DIR

reads DIR/wav/*.wav (written by `cargo run --release --example grid_phones` with
ANCHORS=DIR) and writes DIR/allphone.tsv and DIR/words.tsv: per clip, its id, the seconds
the decoding took (model loading left out) and the phones, silences and fillers left out.
"""
import os
import sys
import time
import wave

from pocketsphinx import Decoder, get_model_path


def read(path):
    with wave.open(path, "rb") as w:
        assert w.getframerate() == 16000 and w.getnchannels() == 1 and w.getsampwidth() == 2
        return w.readframes(w.getnframes())


def decode(decoder, pcm):
    clock = time.perf_counter()
    decoder.start_utt()
    decoder.process_raw(pcm, full_utt=True)
    decoder.end_utt()
    return list(decoder.seg()), time.perf_counter() - clock


def is_phone(name):
    return name not in ("SIL", "<s>", "</s>", "<sil>") and not name.startswith("+") \
        and not name.startswith("[")


def main(root):
    model = get_model_path()
    allphone = Decoder(allphone=os.path.join(model, "en-us/en-us-phone.lm.bin"),
                       allphone_ci=True, beam=1e-20, pbeam=1e-20, lw=2.0, loglevel="FATAL")
    words = Decoder(loglevel="FATAL")
    clips = sorted(f[:-4] for f in os.listdir(os.path.join(root, "wav")) if f.endswith(".wav"))
    with open(os.path.join(root, "allphone.tsv"), "w") as a, \
            open(os.path.join(root, "words.tsv"), "w") as w:
        for clip in clips:
            pcm = read(os.path.join(root, "wav", clip + ".wav"))
            segs, seconds = decode(allphone, pcm)
            phones = [s.word for s in segs if is_phone(s.word)]
            a.write(f"{clip}\t{seconds:.4f}\t{' '.join(phones)}\n")
            segs, seconds = decode(words, pcm)
            phones = []
            for s in segs:
                if is_phone(s.word):
                    phones += [p for p in words.lookup_word(s.word).split() if p != "SIL"]
            w.write(f"{clip}\t{seconds:.4f}\t{' '.join(phones)}\n")


if __name__ == "__main__":
    main(sys.argv[1])
