#!/usr/bin/env bash
# The learned detector and the underexposure guard on darkened copies of real validation
# composite sets (exposure_sweep.py): per gain, the frames the guard flags (`tubeloc detect`
# warns on each), segm AP50 / AR, and precision / recall / false detections kept at the
# shipped calibration's threshold.
#
# usage: experiments/scripts/exposure_sweep.sh WORKDIR SIGMA SET_DIR... (gains in $GAINS)
set -euo pipefail
T=${TUBELOC:-tubeloc}
PY=${PYTHON:-python3}
W=$1; SIGMA=$2; shift 2
GAINS=${GAINS:-"1 0.6 0.4 0.3 0.2 0.12"}
HERE=$(cd "$(dirname "$0")" && pwd)
CAL=$HERE/../../data/models/tubenet.calibration.json
mkdir -p "$W"
for set in "$@"; do
  name=$(basename "$set")
  for g in $GAINS; do
    d=$W/${name}_g$g
    [ -f "$d/annotations.json" ] || "$PY" "$HERE/exposure_sweep.py" "$set" "$d" "$g" "$SIGMA" 7
    "$T" detect --method learned --dataset "$d" --out "$d/dets.json" 2> "$d/detect.log" >/dev/null
    flagged=$(grep -c "underexposed" "$d/detect.log" || true)
    "$T" eval --gt "$d/annotations.json" --dt "$d/dets.json" --calibration "$CAL" --out "$d/eval" > "$d/eval.log" 2>&1 || true
    "$PY" - "$d" "$name" "$g" <<'PYEOF'
import json, sys
d, name, g = sys.argv[1:4]
n = len(json.load(open(f"{d}/annotations.json"))["images"])
flagged = sum("underexposed" in l for l in open(f"{d}/detect.log"))
s = json.load(open(f"{d}/eval/metrics.json"))["stats"]
c = json.load(open(f"{d}/eval/calibration.json"))
fp = c["false_positives_per_image"]
f = lambda v: "-" if v is None or v < 0 else f"{v:.3f}"
print(f"{name} gain {g}: flagged {flagged}/{n}; AP50 {f(s[1]['value'])} AR {f(s[8]['value'])}; at threshold: kept {c['kept']}, precision {f(c['precision_at_threshold'])}, recall {f(c['recall_at_threshold'])}, false per image {f(fp)}")
PYEOF
  done
done
