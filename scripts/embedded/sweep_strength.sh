#!/usr/bin/env bash
# SDEdit strength sweep on held-out captions (docs/embedded/TRAINING.md, "SDEdit strength"): for
# each strength, a copy of models/vf-icon (links to its weights) whose model_index.json sets
# `_sdedit_strength`, run through run_eval.sh via VF_DEFAULT_MODEL (samples, retrieval on).
#
#   scripts/embedded/sweep_strength.sh "0.2 0.3 0.4" fluent fluentb     # from the repo root
#
# VF, PY as for run_eval.sh; SWEEP (default /tmp/sweep) holds the model copies, outputs and reports.
set -euo pipefail
cd "$(dirname "$0")/../.."
strengths=${1:-"0.2 0.3 0.4"}
shift || true
sweep=${SWEEP:-/tmp/sweep}
for s in $strengths; do
  d="$sweep/m$s"
  rm -rf "$d" && mkdir -p "$d"
  for c in unet vae scheduler scorer text_encoder tokenizer retrieval; do ln -s "$PWD/models/vf-icon/$c" "$d/$c"; done
  python3 -c 'import json, sys; m = json.load(open("models/vf-icon/model_index.json")); m["_sdedit_strength"] = float(sys.argv[1]); json.dump(m, open(sys.argv[2], "w"), indent=2)' "$s" "$d/model_index.json"
  echo "== strength $s $(date -u +%T)"
  VF_DEFAULT_MODEL=$d OUT="$sweep/out" JSON_DIR="$sweep" TAG="s$s" METHODS=samples MODES=retrieval \
    scripts/embedded/run_eval.sh balanced "${@:-fluent}" | grep pixel_r_precision
done
