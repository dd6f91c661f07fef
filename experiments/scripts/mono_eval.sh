#!/usr/bin/env bash
# Mono pose accuracy of tubeloc refine on a paper-preset subset: the first N "no-tags" images of
# a paper-preset benchmark (default /tmp/synth_paper, from `tubeloc synth --preset paper`),
# seeds = exact poses perturbed by 10 mm / 5 degrees: seeds alone, mono, mono + --ground auto.
# Usage: experiments/scripts/mono_eval.sh [WORKDIR] [N] [BENCHMARK]   (tubeloc in release on PATH or
# in $TUBELOC)
set -euo pipefail
W=${1:-/tmp/refine_mono_eval}
N=${2:-60}
B=${3:-/tmp/synth_paper}
T=${TUBELOC:-tubeloc}
mkdir -p "$W/sub"
ln -sfn "$B/images" "$W/sub/images"
python3 - "$B/annotations.json" "$W/sub/annotations.json" "$N" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
ims = [i for i in d["images"] if i.get("split") == "no-tags"][: int(sys.argv[3])]
ids = {i["id"] for i in ims}
d["images"] = ims
d["annotations"] = [a for a in d["annotations"] if a["image_id"] in ids]
json.dump(d, open(sys.argv[2], "w"))
PY
D=(--dataset "$W/sub" --gt-seeds 10,5)
"$T" refine "${D[@]}" --out "$W/mono.json" --seeds-out "$W/seeds.json"
"$T" refine "${D[@]}" --ground auto --out "$W/mono_ground.json"
"$T" eval --gt "$W/sub/annotations.json" --out "$W/eval" --poses seeds="$W/seeds.json" mono="$W/mono.json" mono_ground="$W/mono_ground.json"
