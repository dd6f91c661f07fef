#!/usr/bin/env bash
# Pose accuracy of tubeloc refine on a rendered stereo set (paper preset: 1024 px crops at
# scale 0.5, L20/R20 pair), seeds = exact poses perturbed by 10 mm / 5 degrees:
# seeds alone, mono, mono + ground (world z = 0 of each image), stereo (SGM term only), stereo
# (+ photometric ends and scene occlusion, the default), stereo without the scene-occlusion
# test, stereo + ground, and stereo with the mask-agreement term on the annotations' masks (a
# perfect segmenter). Truths: visible_fraction >= 0.5 (tubeloc eval --min-visible).
# Usage: experiments/scripts/stereo_eval.sh [WORKDIR] [SCENES] [PAIR] [SEED]   (PAIR: L20,R20 (default)
# or L40,R40; SEED: 3; tubeloc built in release on PATH or in $TUBELOC)
set -euo pipefail
W=${1:-/tmp/refine_stereo_eval}
N=${2:-4}
PAIR=${3:-L20,R20}
SEED=${4:-3}
T=${TUBELOC:-tubeloc}
mkdir -p "$W"
[ -f "$W/st/annotations.json" ] || "$T" synth stereo --out "$W/st" --scenes "$N" --seed "$SEED" --pair "$PAIR"
D=(--dataset "$W/st" --gt-seeds 10,5)
"$T" refine "${D[@]}" --out "$W/mono.json" --seeds-out "$W/seeds.json"
"$T" refine "${D[@]}" --ground auto --out "$W/mono_ground.json"
"$T" refine "${D[@]}" --stereo --photo-range-mm 0 --out "$W/stereo_sgm.json"
"$T" refine "${D[@]}" --stereo --out "$W/stereo.json"
"$T" refine "${D[@]}" --stereo --no-scene-occlusion --out "$W/stereo_noocc.json"
"$T" refine "${D[@]}" --stereo --ground auto --out "$W/stereo_ground.json"
"$T" refine "${D[@]}" --stereo --mask-term --out "$W/stereo_gtmask.json"
"$T" eval --gt "$W/st/annotations.json" --out "$W/eval" --poses seeds="$W/seeds.json" mono="$W/mono.json" mono_ground="$W/mono_ground.json" \
  stereo_sgm="$W/stereo_sgm.json" stereo="$W/stereo.json" stereo_noocc="$W/stereo_noocc.json" stereo_ground="$W/stereo_ground.json" stereo_gtmask="$W/stereo_gtmask.json"
