#!/usr/bin/env bash
# The SDS knobs on the validation captions (docs/embedded/TRAINING.md, "Validation"): each
# argument NAME=FLAGS runs `sd_live_sds` with those `eval` flags (--guidance, --t-min, --t-max,
# --steps, --size, ...) through run_eval.sh (retrieval on) and prints its pixel R-Precision.
#
#   scripts/embedded/sweep_sds.sh "g100=" "g30=--guidance 30" "t200-700=--t-min 200 --t-max 700"
#
# SETS (default "valnoto valtwemoji") the caption sets (a held-out set measures a choice made,
# it never makes one); VF, PY as for run_eval.sh; SWEEP (default /tmp/sweep)
# holds the outputs and reports (eval_SET_retrieval_balanced_sds-NAME.json).
set -euo pipefail
cd "$(dirname "$0")/../.."
sweep=${SWEEP:-/tmp/sweep}
read -r -a sets <<<"${SETS:-valnoto valtwemoji}"
for arg in "$@"; do
  name=${arg%%=*}
  flags=${arg#*=}
  echo "== $name: ${flags:-(defaults)} $(date -u +%T)"
  OUT="$sweep/out" JSON_DIR="$sweep" TAG="sds-$name" EVAL_ARGS="$flags" METHODS=sd_live_sds \
    MODES=retrieval scripts/embedded/run_eval.sh balanced "${sets[@]}" | grep pixel_r_precision
done
