#!/usr/bin/env bash
# A voice set the talker never heard (issue 66): the first ten Harvard sentences (public
# domain, IEEE 1969) spoken by Festival's slt (a woman, HTS), Festival's kal (a man, diphone)
# and espeak-ng, as VOICE_hNN.wav with the words in VOICE_hNN.txt; then how many true
# transcripts `say` accepts with the talker given (default models/grid).
#   tools/voice_set.sh OUT_DIR [TALKER] [FACESPACE_BINARY]
set -euo pipefail
out=${1:?OUT_DIR}; talker=${2:-models/grid}; bin=${3:-target/release/facespace}
mkdir -p "$out"
sentences=(
  "The birch canoe slid on the smooth planks."
  "Glue the sheet to the dark blue background."
  "It's easy to tell the depth of a well."
  "These days a chicken leg is a rare dish."
  "Rice is often served in round bowls."
  "The juice of lemons makes fine punch."
  "The box was thrown beside the parked truck."
  "The hogs were fed chopped corn and garbage."
  "Four hours of steady work faced us."
  "A large size in stockings is hard to sell."
)
for i in "${!sentences[@]}"; do
  n=$(printf "h%02d" $((i + 1))); line=${sentences[$i]}
  for v in slt kal esp; do echo "$line" > "$out/${v}_$n.txt"; done
  [ -f "$out/slt_$n.wav" ] || echo "$line" | text2wave -eval "(voice_cmu_us_slt_arctic_hts)" -o "$out/slt_$n.wav"
  [ -f "$out/kal_$n.wav" ] || echo "$line" | text2wave -eval "(voice_kal_diphone)" -o "$out/kal_$n.wav"
  [ -f "$out/esp_$n.wav" ] || espeak-ng -w "$out/esp_$n.wav" "$line"
done
for v in slt kal esp; do
  ok=0
  for w in "$out"/${v}_h*.wav; do
    if "$bin" say --talker "$talker" --audio "$w" --transcript "${w%.wav}.txt" --renderer cpu \
        -o "$out/said.mp4" > "${w%.wav}.log" 2>&1; then ok=$((ok + 1)); fi
    rm -f "$out/said.mp4"
  done
  echo "$v: $ok of 10 true transcripts accepted"
done
