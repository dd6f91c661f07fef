#!/usr/bin/env bash
# Stereo refinement with and without the two-view contour fit (tubeloc_refine::two_view),
# without and with the ground prior, on a set rendered by stereo_eval.sh (W/st), seeds = exact
# poses moved by 10 mm / 5 degrees; tubes at least half visible (tubeloc eval --min-visible).
# Usage: experiments/scripts/two_view_eval.sh W   (tubeloc built in release on PATH or in $TUBELOC;
# --config FILE with a [stages.two_view] table of TwoViewConfig fields changes the fit's settings)
set -euo pipefail
W=${1:?usage: two_view_eval.sh W}
T=${TUBELOC:-tubeloc}
D=(--dataset "$W/st" --gt-seeds 10,5 --stereo)
"$T" refine "${D[@]}" --no-two-view --out "$W/tv_off.json"
"$T" refine "${D[@]}" --out "$W/tv_on.json"
"$T" refine "${D[@]}" --ground auto --no-two-view --out "$W/tv_off_ground.json"
"$T" refine "${D[@]}" --ground auto --out "$W/tv_on_ground.json"
"$T" eval --gt "$W/st/annotations.json" --out "$W/eval_two_view" --poses stereo_before="$W/tv_off.json" \
  stereo="$W/tv_on.json" stereo_ground_before="$W/tv_off_ground.json" stereo_ground="$W/tv_on_ground.json"
