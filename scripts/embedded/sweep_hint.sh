#!/usr/bin/env bash
# A sweep of one model hint (docs/embedded/TRAINING.md, "Validation"; val_sweep.sh drives it
# over seeds and both judges): for each value, a copy of models/vf-icon (links to its weights)
# whose model_index.json sets KEY, run through run_eval.sh via VF_DEFAULT_MODEL (METHODS, default
# samples; retrieval on). Choose on the validation sets (valnoto, valtwemoji), never on the
# held-out ones (fluent, fluentb, openmoji: they judge, they do not choose).
#
#   scripts/embedded/sweep_hint.sh _sdedit_strength "0.2 0.3 0.4" valnoto valtwemoji   # repo root
#   METHODS="samples sd_live_sds" MODES="retrieval noise" scripts/embedded/sweep_hint.sh _colour_steer "off svg" colour
#   MODES=noise scripts/embedded/sweep_hint.sh scheduler._class_name EulerAncestralDiscreteScheduler valnoto
#
# HINTS="KEY=VALUE ..." fixes other hints in every copy, and UNET=DIR links a candidate prior's
# weights instead of the shipped ones (TAG_SUFFIX then names the variant); VF,
# PY, EVAL_ARGS as for run_eval.sh; SWEEP (default /tmp/sweep) holds the model copies,
# outputs and reports (eval_SET_retrieval_balanced_KEYVALUE.json, and pixel R-Precision per
# method under out/SET-MODE-KEYVALUE/). MODES (default retrieval) as for run_eval.sh.
set -euo pipefail
cd "$(dirname "$0")/../.."
key=${1:?usage: sweep_hint.sh KEY "VALUES" [CAPTION_SET...]}
values=${2:?usage: sweep_hint.sh KEY "VALUES" [CAPTION_SET...]}
shift 2
sweep=${SWEEP:-/tmp/sweep}
for v in $values; do
  tag="${key#_}$v${TAG_SUFFIX:-}"
  tag="${tag#scheduler.}" && tag="${tag#_}"
  d="$sweep/m-$tag"
  rm -rf "$d" && mkdir -p "$d"
  for c in unet vae scorer text_encoder tokenizer retrieval; do
    [ -e "models/vf-icon/$c" ] && ln -s "$PWD/models/vf-icon/$c" "$d/$c"
  done
  if [ -n "${UNET:-}" ]; then rm "$d/unet" && ln -s "$(realpath "$UNET")" "$d/unet"; fi
  mkdir "$d/scheduler"
  # HINTS="KEY=VALUE ..." sets other hints first (a combination), then KEY=v; a key
  # `scheduler.FIELD` sets FIELD of scheduler_config.json instead (`scheduler._class_name`).
  python3 - "$d" ${HINTS:-} "$key=$v" <<'PY'
import json, sys
m = json.load(open("models/vf-icon/model_index.json"))
sched = json.load(open("models/vf-icon/scheduler/scheduler_config.json"))
for kv in sys.argv[2:]:
    k, v = kv.split("=", 1)
    target = m
    if k.startswith("scheduler."):
        target, k = sched, k.removeprefix("scheduler.")
    try:
        target[k] = int(v) if v.isdigit() else float(v)
    except ValueError:
        target[k] = v  # a word (_colour_steer, a scheduler's class)
json.dump(m, open(sys.argv[1] + "/model_index.json", "w"), indent=2)
json.dump(sched, open(sys.argv[1] + "/scheduler/scheduler_config.json", "w"), indent=2)
PY
  echo "== $key $v $(date -u +%T)"
  VF_DEFAULT_MODEL=$d OUT="$sweep/out" JSON_DIR="$sweep" TAG="$tag" METHODS=${METHODS:-samples} MODES=${MODES:-retrieval} \
    scripts/embedded/run_eval.sh balanced "${@:-fluent}" | { grep -E "pixel_r_precision|colour" || true; }
done
