#!/usr/bin/env bash
# The real stage of `tubeloc bench` (the test part) for a candidate learned model, with its
# score calibration, pose evidence and fused calibration refitted on the real validation
# composites by the shipped rules (data/models/README.md), as record 0073 measured its candidates.
#
# Usage: scripts/test_candidate_model.sh MODEL.safetensors OUT_DIR [REAL_DATA]
#
# The program embeds the model and its calibrations, so they are copied into data/models/
# and the program rebuilt; the shipped files are put back (and the program rebuilt) when the
# script ends, whether it succeeds or not. OUT_DIR receives the validation sets, the fitted
# files (calibration/), and the bench's output (B/real/report.md). About 20 min on 2 cores.
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: $0 MODEL.safetensors OUT_DIR [REAL_DATA]" >&2; exit 2; }
model=$(realpath "$1")
out=$(mkdir -p "$2" && realpath "$2")
data=$(realpath "${3:-../shared/data/real_mars}")
[ -f "$model" ] || { echo "$0: no model file $1" >&2; exit 1; }
[ -f "$data/MANIFEST.tsv" ] || { echo "$0: $data is not the real data folder (no MANIFEST.tsv)" >&2; exit 1; }
cd "$(dirname "$0")/.."
if ! git diff --quiet -- data/models; then
  echo "$0: data/models has uncommitted changes; commit or stash them first" >&2
  exit 1
fi

shipped=(data/models/tubenet.safetensors data/models/tubenet.calibration.json data/models/tubenet.pose_evidence.json data/models/fused.calibration.json)
restore() {
  git checkout -- "${shipped[@]}"
  cargo build --release -p tubeloc >/dev/null 2>&1 || echo "$0: rebuilding with the shipped model failed: run cargo build --release" >&2
}
trap restore EXIT

T=target/release/tubeloc
val="$out/real_val_all"
fit="tubeloc synth real --split val --kind all --per-view 4 --tubes 0:4 --min-size 300 --seed 21 --randomize false"
build() { cargo build --release -p tubeloc 2>&1 | tail -1; }

cp "$model" data/models/tubenet.safetensors
build
[ -f "$val/annotations.json" ] || $T synth real --data "$data" --split val --kind all --per-view 4 --tubes 0:4 --min-size 300 --seed 21 --randomize false --out "$val"
mkdir -p "$out/calibration"
$T detect --method learned --dataset "$val" --out "$out/calibration/d.json"
$T eval --gt "$val/annotations.json" --dt "$out/calibration/d.json" --calibrate data/models/tubenet.calibration.json \
  --max-false-per-image 0.1 --max-false-per-negative-image 0.05 \
  --fitted-on "$fit; learned detections of the candidate $(basename "$model") at the working scale; threshold: precision >= 0.95, at most 0.1 false detections per image and at most 0.05 per image without a tube"
$T refine --dataset "$val" --detections "$out/calibration/d.json" --ground auto --out "$out/calibration/p.json" --snapped-out "$out/calibration/s.json"
$T eval --gt "$val/annotations.json" --dt "$out/calibration/s.json" --fit-pose-evidence data/models/tubenet.pose_evidence.json \
  --evidence-poses "$out/calibration/p.json" --fitted-on "$fit; the candidate's detections refined with --ground auto and snapped"
build
$T detect --method fused --dataset "$val" --out "$out/calibration/f.json"
$T eval --gt "$val/annotations.json" --dt "$out/calibration/f.json" --calibrate data/models/fused.calibration.json \
  --max-false-per-image 0.1 --max-false-per-negative-image 0.05 \
  --fitted-on "$fit; fused detections with the candidate, its pose evidence, the default template library and the shipped Line2D pose verifier"
build
cp data/models/tubenet.calibration.json data/models/tubenet.pose_evidence.json data/models/fused.calibration.json "$out/calibration/"
$T bench --only real --real-data "$data" --out "$out/B"
echo "test part of $(basename "$model"): $out/B/real/report.md (fitted files in $out/calibration)"
