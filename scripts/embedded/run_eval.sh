#!/usr/bin/env bash
# Table 1 in miniature on the embedded model (docs/embedded/TRAINING.md, "Evaluation"):
# raster samples, scratch, sd_live and sd_live_sds, scored by the embedded IconClip, on the
# held-out icon names and on the paper's 128 captions.
#
#   scripts/embedded/run_eval.sh [PRESET]        # default preset: draft
#
# VF overrides the binary (default: the dev-profile build, `cargo build` first).
set -euo pipefail
cd "$(dirname "$0")/../.."
preset="${1:-draft}"
vf="${VF:-target/debug/vectorfusion}"
out="${OUT:-eval-out}"
methods=(--method samples --method scratch --method sd_live --method sd_live_sds)
run() { # name prompts
  "$vf" eval --prompts "$2" "${methods[@]}" --preset "$preset" --scorer models/vf-icon \
    --out-dir "$out/$1" --json "docs/embedded/eval_$1_$preset.json"
}
run heldout docs/embedded/heldout_captions.txt
run paper ../shared/bench/svg_bench_prompts.txt
