#!/usr/bin/env bash
# After a retrain (docs/embedded/TRAINING.md): reference fixtures and the loader test, then the
# evaluation (Table 1 in miniature on both sets of held-out Fluent captions, `scratch` on the first), the
# memorisation check, the gallery, the `generate` timing over 12 everyday captions with its
# picture, the prior's sample grid and loss curve, and the held-out openmoji captions.
#
#   scripts/embedded/after_training.sh        # from the repo root; about 30 minutes on 2 cores
#
# VF (default target/debug/vectorfusion, a dev build: every dependency optimised), PY (the venv
# with torch/diffusers), OUT (eval outputs, default /tmp/evalout). Run it on an idle machine: the
# seconds it prints are the benchmark's.
set -uo pipefail
cd "$(dirname "$0")/../.."
export VF=${VF:-target/debug/vectorfusion} PY=${PY:-/work/venv/bin/python} OUT=${OUT:-/tmp/evalout}
t() { echo "== $* $(date -u +%T)"; }
# Copies run_eval.sh's pixel R-Precision of every method it ran for caption set $1 into docs/.
keep_pixel_scores() {
  local f base
  for f in "$OUT/$1"-{retrieval,noise}/*.pixel_rprecision.json; do
    [ -f "$f" ] || continue
    base=$(basename "$(dirname "$f")") # SET-MODE
    cp "$f" "docs/embedded/pixel_rprecision_$1_${base#"$1"-}_$(basename "$f" .pixel_rprecision.json).json"
  done
}
t refs; "$PY" scripts/embedded/make_refs.py | tail -1
t test; cargo test --test embedded_model 2>&1 | grep -E "test result|FAILED|panicked"
t fluent; SCRATCH=1 scripts/embedded/run_eval.sh balanced fluent
keep_pixel_scores fluent
t fluentb; scripts/embedded/run_eval.sh balanced fluentb
keep_pixel_scores fluentb
t memorisation
"$PY" scripts/embedded/memorisation.py --vf "$VF" --dir "$OUT/fluent-retrieval/samples" \
  --dir "$OUT/fluent-noise/samples" --dir "$OUT/fluent-retrieval/sd_live_sds" \
  --dir "$OUT/fluent-noise/sd_live_sds" --json docs/embedded/memorisation.json >/dev/null
t gallery
"$PY" scripts/embedded/gallery.py --vf "$VF" --captions docs/embedded/heldout_fluent48.txt --n 24 \
  --with "$OUT/fluent-retrieval" --without "$OUT/fluent-noise" --out docs/embedded/gallery.png
t generate
gen=$(mktemp -d); tiles=()
for c in "a grinning face" "a horse" "a rocket" "a red heart" "pizza" "a cat" "a car" "a snowman" \
  "a house" "a tree" "a sun" "a coffee cup"; do
  svg="$gen/${c// /_}.svg"
  s=$(date +%s.%N); "$VF" generate "$c" -o "$svg" >/dev/null 2>&1; e=$(date +%s.%N)
  echo "$c: $(echo "$e - $s" | bc) s"; tiles+=("$c=$svg")
done
"$PY" scripts/embedded/svg_grid.py docs/embedded/generate_default.png "${tiles[@]}"
t samples
"$PY" scripts/embedded/sample_grid.py --steps 12 --cfg 5 --batch 64 --out docs/embedded/samples.png \
  --loss docs/embedded/prior_loss.csv --loss-out docs/embedded/loss.png | tail -2
t openmoji; scripts/embedded/run_eval.sh balanced openmoji
keep_pixel_scores openmoji
# PAPER=1: the paper's 128 captions too (IconClip scores only; about 15 more minutes)
if [ -n "${PAPER:-}" ]; then
  t paper; METHODS="samples sd_live_sds" MODES=retrieval scripts/embedded/run_eval.sh balanced paper
  METHODS=samples MODES=noise scripts/embedded/run_eval.sh balanced paper
fi
t done
