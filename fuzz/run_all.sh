#!/usr/bin/env bash
# Runs fuzz targets one after another for SECS seconds each (default 180), on the stable
# toolchain via RUSTC_BOOTSTRAP=1. Usage: fuzz/run_all.sh [SECS] [target ...]
# Logs go to fuzz/logs/<target>.log (ignored by git); crashes to fuzz/artifacts/<target>/.
set -u
cd "$(dirname "$0")"
secs=${1:-180}; shift || true
targets=${*:-"rle_string obj_mesh tube_toml coco_dataset coco_results detections rig_json jpeg_markers assumed_view confidence_files"}
export RUSTC_BOOTSTRAP=1 CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-/work/targets/fuzz}
mkdir -p logs
for t in $targets; do
  feat=""
  case $t in rig_yaml|tag_detector|jpeg_luma|pds_cameras|pds3_label) feat="--features calib";; line2d_library|pds3_image|line2d_verifier) feat="--features detect";; esac
  case $t in line2d_library) len=65536;; rle_string|tube_toml|tag_detector) len=4096;; *) len=8192;; esac
  mkdir -p corpus/$t && cp -n seeds/$t/* corpus/$t/ 2>/dev/null
  cargo fuzz run -O $feat $t corpus/$t -- -rss_limit_mb=2048 -max_len=$len -timeout=10 \
    -max_total_time=$secs -print_final_stats=1 > logs/$t.log 2>&1
  echo "$t rc=$? $(grep -E '^stat::number_of_executed_units' logs/$t.log)"
done
