#!/bin/sh
# Rhubarb Lip Sync's own output for two committed GRID clips, in each format facespace writes,
# so that tests/visemes.rs can check our exporters against the tool itself (not only against
# its README's examples). Rhubarb 1.14.0 built from its source beside the project, never
# committed (tools/rhubarb_compare.py says how); its bundled continuous acoustic model was not
# in the copy at hand, so pocketsphinx's en-us PTM model (the one facespace reads) stood in.
# The shapes are Rhubarb's; what the test checks is their layout.
#
#     sh tests/reference/rhubarb_outputs.sh /path/to/rhubarb
set -e
R=${1:?the rhubarb binary}
OUT=tests/data/rhubarb
mkdir -p $OUT
for clip in bbbf9a lrwz5a; do
    in=tests/data/grid/$clip.wav
    "$R" -q --threads 1 -f tsv -o $OUT/$clip.tsv "$in"
    "$R" -q --threads 1 -f json -o $OUT/$clip.json "$in"
    "$R" -q --threads 1 -f dat -o $OUT/$clip.dat "$in"
    "$R" -q --threads 1 -f dat --datFrameRate 30 --datUsePrestonBlair -o $OUT/$clip-30-preston-blair.dat "$in"
    "$R" -q --threads 1 -f tsv --extendedShapes "" -o $OUT/$clip-basic.tsv "$in"
    "$R" -q --threads 1 -f dat --extendedShapes "" -o $OUT/$clip-basic.dat "$in"
done
