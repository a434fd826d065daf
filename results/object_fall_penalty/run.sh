#!/usr/bin/env bash
# The teacher-data fall model pooled over objects and used as a soft penalty (docs/experiments/object-fall-penalty.md):
#   1. offline: on the held-out scenes of results/teacher_fall_filter's split, the fall model's risk per cell, or pooled
#      (mean, max) over the object under the cell; the shipped P+S's choice among the labelled picks under a hard mask
#      (thresholds 0.1..0.9) or a soft penalty (Q - lambda * sigma * risk, lambda 0.25..8); the plan's candidate
#      -> penalty_check.json
# Each step skips what is on disk.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
export OMP_NUM_THREADS=1
out=results/object_fall_penalty
shipped=examples/pretrained/p_s.zip
risk=results/teacher_fall_filter/model/p_s_ffbal.fall_risk.pt
[ -f "$out/penalty_check.json" ] || python -m research.fall_risk penalty --data data/teacher --model "$risk" \
    --checkpoint "$shipped" --out "$out/penalty_check.json" > /dev/null
python - "$out/penalty_check.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print(f"unfiltered {r['unfiltered']}  oracle {r['oracle']}  sigma {r['q_sigma']:.3f}")
for how, block in r["poolings"].items():
    print(f"{how}: AUC {block['auc']:.3f}")
    for rule, key in (("hard", "threshold"), ("soft", "penalty")):
        print("  " + rule + ": " + "  ".join(f"{e[key]:g}: {100 * e['invalid']:.1f}% / {e['sorted']:.3f}" for e in block[rule]))
print("candidate:", r["candidate"])
PY
