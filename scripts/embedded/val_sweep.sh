#!/usr/bin/env bash
# The validation protocol's sweep of one model hint (docs/embedded/TRAINING.md, "Validation"):
# for each seed, sweep_hint.sh on the validation captions, once per judge (noto, twemoji) with
# that judge's set left out of retrieval; from noise the pictures do not depend on retrieval, so
# one run per seed serves both judges. Samples only (METHODS overrides); then val_compare.py
# judges every picture by both sets and tabulates the values with paired standard errors.
#
#   scripts/embedded/val_sweep.sh noise _sample_guidance "3 5 7 10" "0 1 2"        # repo root
#   scripts/embedded/val_sweep.sh retrieval _sdedit_strength "0.2 0.3 0.4 0.5" "0 1 2"
#   HINTS=_retrieval_share=1 scripts/embedded/val_sweep.sh retrieval _retrieval_per_caption "1 2" "0 1 2"
#   UNET=OUT/export/unet TAG_SUFFIX=-run7 scripts/embedded/val_sweep.sh noise _sample_guidance 5 "0 1 2"
#
# VF, PY and SWEEP as for run_eval.sh / sweep_hint.sh (SWEEP default /tmp/sweep).
set -euo pipefail
cd "$(dirname "$0")/../.."
mode=${1:?usage: val_sweep.sh noise|retrieval KEY "VALUES" "SEEDS"}
key=${2:?} values=${3:?} seeds=${4:-0 1 2}
export SWEEP=${SWEEP:-/tmp/sweep} METHODS=${METHODS:-samples} MODES=$mode
sets=(valnoto valtwemoji)
[ "$mode" = noise ] && sets=(valnoto)
for s in $seeds; do
  EVAL_ARGS="--seed $s" TAG_SUFFIX="${TAG_SUFFIX:-}-s$s" scripts/embedded/sweep_hint.sh "$key" "$values" "${sets[@]}"
done
