#!/usr/bin/env bash
# Times tubeloc SGM (criterion, 1024x768, 128 disparities) and OpenCV StereoSGBM (modes SGBM =
# default and 3WAY) on the same synthetic pair in one run; prints medians, ratios and bad-2.0
# against the exact disparity (visible pixels, invalid = bad).
# Usage: scripts/stereo_bench.sh   (needs python3 with opencv-contrib-python-headless, numpy)
set -euo pipefail
cd "$(dirname "$0")/.."
TARGET="${CARGO_TARGET_DIR:-target}"
cargo bench -p tubeloc-stereo --bench sgm -- --noplot
python3 scripts/stereo_peer.py bench --left "$TARGET/stereo_bench/left.png" --right "$TARGET/stereo_bench/right.png" \
  --gt "$TARGET/stereo_bench/gt.pfm" --visible "$TARGET/stereo_bench/visible.png" --ndisp 128 --threads 2 \
  --ours "$TARGET/stereo_bench/ours_eight_paths.pfm" --ours-criterion "$TARGET/criterion/sgm_1024x768_d128"
