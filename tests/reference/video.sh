#!/usr/bin/env bash
# Makes tests/data/video/: one second of the FGNet talking face as H.264 High profile with
# B-frames plus an AAC sine tone (as phones and cameras write MP4), and frame 10 of it as
# decoded by ffmpeg (the reference for facespace's built-in reader).
set -euo pipefail
cd "$(dirname "$0")/../data/video"
src=../../../../shared/data/talking-face/franck.mp4
ffmpeg -v error -y -i "$src" -f lavfi -i "sine=frequency=440:sample_rate=44100" -t 1 \
  -c:v libx264 -profile:v high -bf 2 -crf 28 -pix_fmt yuv420p -c:a aac -b:a 64k -shortest \
  high_bframes_aac.mp4
ffmpeg -v error -y -i high_bframes_aac.mp4 -vf "select=eq(n\,10)" -frames:v 1 frame10_ffmpeg.png
