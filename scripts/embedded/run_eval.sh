#!/usr/bin/env bash
# Table 1 in miniature on the embedded model (docs/embedded/TRAINING.md, "Evaluation"): the prior's
# raster samples, sd_live and sd_live_sds (scratch with --scratch), with and without retrieval,
# on held-out captions; then pixel R-Precision against the held-out artists' icons, the
# memorisation check and the gallery.
#
#   scripts/embedded/run_eval.sh [PRESET] [CAPTION_SET...]    # defaults: fast, fluent
#   CAPTION_SET: fluent (docs/embedded/heldout_fluent48.txt vs fluent-emoji-flat),
#                openmoji (heldout_openmoji48.txt vs openmoji), paper (the paper's 128 captions;
#                IconClip scores only)
#
# Needs: a release build (VF overrides the binary), `vectorfusion setup` (MiniLM + retrieval
# index), data/icons from scripts/embedded/prepare_data.sh and the venv's python (PY) for the
# pixel measures.
set -euo pipefail
cd "$(dirname "$0")/../.."
preset="${1:-fast}"
shift || true
sets=("$@")
[ ${#sets[@]} -gt 0 ] || sets=(fluent)
vf="${VF:-target/release/vectorfusion}"
py="${PY:-/work/venv/bin/python}"
out="${OUT:-eval-out}"
methods=(--method samples --method sd_live --method sd_live_sds)
[ -n "${SCRATCH:-}" ] && methods+=(--method scratch)
for s in "${sets[@]}"; do
  case "$s" in
    fluent) prompts=docs/embedded/heldout_fluent48.txt; ref=fluent-emoji-flat ;;
    openmoji) prompts=docs/embedded/heldout_openmoji48.txt; ref=openmoji ;;
    paper) prompts=../shared/bench/svg_bench_prompts.txt; ref= ;;
    *) echo "unknown caption set $s" >&2; exit 2 ;;
  esac
  for mode in retrieval noise; do
    flag=(); [ "$mode" = noise ] && flag=(--no-retrieval)
    dir="$out/$s-$mode"
    "$vf" eval --prompts "$prompts" "${methods[@]}" "${flag[@]}" --preset "$preset" \
      --scorer models/vf-icon --out-dir "$dir" --json "docs/embedded/eval_${s}_${mode}_$preset.json"
    if [ -n "$ref" ]; then
      for m in samples sd_live sd_live_sds; do
        "$py" scripts/embedded/pixel_rprecision.py score --captions "$prompts" --set "$ref" \
          --dir "$dir/$m" --vf "$vf" --json "$dir/$m.pixel_rprecision.json"
      done
    fi
  done
done
