#!/usr/bin/env bash
# Editability of `generate`'s SVGs on the embedded model: the 12 everyday captions of
# docs/embedded (scripts/embedded/after_training.sh), seed 0, default settings, written to
# OUT_DIR, then measured by one checker (examples/editability.rs, vector::check) whatever
# binary wrote them, so an older build serves as the baseline.
# Usage: scripts/generate_editability.sh [BIN] [OUT_DIR]
set -euo pipefail
BIN="${1:-target/release/vectorfusion}"
OUT="${2:-/tmp/vf-generate-editability}"
mkdir -p "$OUT"
i=0
for c in "a grinning face" "a horse" "a rocket" "a red heart" "pizza" "a cat" "a car" "a snowman" \
         "a house" "a sun" "a coffee cup" "a tree"; do
  i=$((i + 1))
  s=$(date +%s.%N); "$BIN" generate "$c" -o "$OUT/$i.svg" >/dev/null 2>&1; e=$(date +%s.%N)
  echo "$c: $(echo "$e - $s" | bc) s" >&2
done
cargo run --quiet --release --example editability -- "$OUT"/*.svg | tail -1
