#!/usr/bin/env python3
"""Pack the CMU Pronouncing Dictionary for embedding: first pronunciation of each word,
stress digits dropped, comments removed, gzip -9. Output: data/cmudict/cmudict.txt.gz
(lines `word ph ph ph`). Run once; the output and LICENSE are committed."""
import gzip, pathlib, re, shutil

ROOT = pathlib.Path(__file__).resolve().parents[1]
SRC = ROOT.parent / "shared/data/cmudict"
out = []
seen = set()
for line in (SRC / "cmudict.dict").read_text(encoding="utf-8").splitlines():
    line = line.split("#")[0].strip()
    if not line:
        continue
    word, *phones = line.split()
    word = re.sub(r"\(\d+\)$", "", word)
    if word in seen:
        continue
    seen.add(word)
    out.append(word + " " + " ".join(re.sub(r"\d", "", p) for p in phones))
dst = ROOT / "data/cmudict"
dst.mkdir(parents=True, exist_ok=True)
with gzip.GzipFile(dst / "cmudict.txt.gz", "wb", compresslevel=9, mtime=0) as f:
    f.write(("\n".join(out) + "\n").encode())
shutil.copy(SRC / "LICENSE", dst / "LICENSE")
print(len(out), "words")
