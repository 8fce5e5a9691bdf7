#!/usr/bin/env bash
# Table 1 in miniature on the embedded model (docs/embedded/TRAINING.md, "Evaluation"): the prior's
# raster samples, sd_live and sd_live_sds (scratch with --scratch), with and without retrieval,
# on held-out captions; then pixel R-Precision against the held-out artists' icons, the
# memorisation check and the gallery.
#
#   scripts/embedded/run_eval.sh [PRESET] [CAPTION_SET...]    # defaults: fast, fluent
#   CAPTION_SET: fluent (docs/embedded/heldout_fluent48.txt vs fluent-emoji-flat), fluentb (a
#                second, disjoint 48: heldout_fluent48b.txt),
#                openmoji (heldout_openmoji48.txt vs openmoji), paper (the paper's 128 captions;
#                IconClip scores only), colour (colour60.txt: colour binding, docs/embedded/COLOUR.md),
#                valnoto / valtwemoji (the validation protocol that settings are chosen on:
#                val_captions.txt, captions the prior never trained on, judged by a training set's
#                drawings that retrieval leaves out; docs/embedded/TRAINING.md, "Validation")
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
# METHODS="samples sd_live_sds" narrows the rows; SCRATCH=1 adds `scratch` (SDS from random
# paths: it samples nothing, so it runs once, in the retrieval pass).
# MODES=retrieval runs one pass; JSON_DIR moves the eval reports (default docs/embedded).
# EVAL_ARGS="--samples 4" passes more `eval` flags; TAG names such a variant's outputs.
read -r -a extra <<<"${EVAL_ARGS:-}"
tag="$preset${TAG:+_$TAG}"
if [ -n "${METHODS:-}" ]; then methods=(); for m in $METHODS; do methods+=(--method "$m"); done; fi
for s in "${sets[@]}"; do
  exclude=
  case "$s" in
    fluent) prompts=docs/embedded/heldout_fluent48.txt; ref=fluent-emoji-flat ;;
    fluentb) prompts=docs/embedded/heldout_fluent48b.txt; ref=fluent-emoji-flat ;;
    openmoji) prompts=docs/embedded/heldout_openmoji48.txt; ref=openmoji ;;
    paper) prompts=../shared/bench/svg_bench_prompts.txt; ref= ;;
    colour) prompts=docs/embedded/colour60.txt; ref= ;;
    valnoto) prompts=docs/embedded/val_captions.txt; ref=noto; exclude=noto,noto-v1 ;;
    valtwemoji) prompts=docs/embedded/val_captions.txt; ref=twemoji; exclude=twemoji ;;
    *) echo "unknown caption set $s" >&2; exit 2 ;;
  esac
  for mode in ${MODES:-retrieval noise}; do
    flag=(); [ "$mode" = noise ] && flag=(--no-retrieval)
    run=("${methods[@]}")
    [ -n "${SCRATCH:-}" ] && [ "$mode" = retrieval ] && run+=(--method scratch)
    dir="$out/$s-$mode${TAG:+-$TAG}"
    VF_RETRIEVAL_EXCLUDE_SETS="${exclude:-}" "$vf" eval --prompts "$prompts" "${run[@]}" "${flag[@]}" "${extra[@]}" --preset "$preset" \
      --scorer models/vf-icon --out-dir "$dir" --json "${JSON_DIR:-docs/embedded}/eval_${s}_${mode}_$tag.json"
    if [ -n "$ref" ]; then
      for ((i = 1; i < ${#run[@]}; i += 2)); do
        m=${run[$i]}
        "$py" scripts/embedded/pixel_rprecision.py score --captions "$prompts" --set "$ref" \
          --dir "$dir/$m" --vf "$vf" --json "$dir/$m.pixel_rprecision.json"
      done
    fi
  done
done
