#!/usr/bin/env bash
# Fetches the pinned @iconify-json icon sets with `npm pack`, renders them with resvg
# (`examples/icon_dataset.rs`) to 64x64 RGB over white and writes, per split, under data/icons/:
#   <split>/images_64.u8   raw uint8 [N, 64, 64, 3]
#   <split>/captions.jsonl {"set", "name", "caption"} per image, same order
# plus docs/embedded/data_manifest.json (versions, tarball integrity/sha256, counts per set).
#
# Splits: "train" (the sets in TRAIN) and "eval" (EVAL: held out, never trained on).
# NEVER add fluent-emoji, fluent-emoji-flat, fluent-emoji-high-contrast or openmoji to TRAIN.
#
# Usage (repo root): scripts/embedded/prepare_data.sh   (needs npm, cargo, and PYTHON with
# scripts/embedded/vf_icon.py importable, default /work/venv/bin/python, for the MiniLM vocab path)
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
OUT=${VF_DATA_DIR:-data/icons}
TRAIN="twemoji@1.2.5 noto@1.2.9 noto-v1@1.2.5 emojione@1.2.3 emojione-v1@1.2.3 fxemoji@1.2.2 streamline-emojis@1.2.4 flat-color-icons@1.2.3 streamline-color@1.2.2 streamline-plump-color@1.2.2 streamline-flex-color@1.2.2 streamline-kameleon-color@1.2.2 streamline-ultimate-color@1.2.2 streamline-stickies-color@1.2.2"
EVAL="fluent-emoji-flat@1.2.6 openmoji@1.2.29"
for s in $TRAIN; do
  case "${s%@*}" in fluent-emoji*|openmoji) echo "refusing to train on held-out set $s" >&2; exit 1 ;; esac
done

mkdir -p "$OUT/npm" "$OUT/json" docs/embedded
fetch() { # name@version -> json path; also appends a manifest line
  local spec=$1 name=${1%@*}
  local tgz="$OUT/npm/iconify-json-$name-${spec#*@}.tgz"
  if [ ! -f "$tgz" ]; then
    (cd "$OUT/npm" && npm pack --silent "@iconify-json/$spec" >/dev/null 2>&1)
  fi
  local integrity
  integrity=$(npm view "@iconify-json/$spec" dist.integrity 2>/dev/null | tail -1)
  local sha
  sha=$(sha256sum "$tgz" | cut -d' ' -f1)
  mkdir -p "$OUT/json/$name"
  tar -xzf "$tgz" -C "$OUT/json/$name" package/icons.json package/package.json
  echo "{\"package\":\"@iconify-json/$name\",\"version\":\"${spec#*@}\",\"sha256\":\"$sha\",\"integrity\":\"$integrity\",\"license\":$(python3 -c 'import json,sys;p=json.load(open(sys.argv[1]));print(json.dumps(p.get("license")))' "$OUT/json/$name/package/package.json")}" >>"$OUT/packages.jsonl"
}
rm -f "$OUT/packages.jsonl"
train_json=(); eval_json=()
for s in $TRAIN; do fetch "$s"; train_json+=("${s%@*}=$OUT/json/${s%@*}/package/icons.json"); done
for s in $EVAL; do fetch "$s"; eval_json+=("${s%@*}=$OUT/json/${s%@*}/package/icons.json"); done

# MiniLM's WordPiece vocabulary, to split names written without separators (fxemoji).
PY=${PYTHON:-/work/venv/bin/python}
VOCAB=$("$PY" -c 'import sys; sys.path.insert(0, "scripts/embedded"); import vf_icon, os; print(os.path.join(vf_icon.minilm_dir(), "vocab.txt"))')
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
# The dev profile optimises every dependency (Cargo.toml), so reusing a test build is fine here.
PROFILE=${VF_CARGO_PROFILE:-release}
cargo run --profile "$PROFILE" --quiet --example icon_dataset -- "$OUT/train" 64 --words "$VOCAB" "${train_json[@]}" >"$OUT/train.stats.json"
cargo run --profile "$PROFILE" --quiet --example icon_dataset -- "$OUT/eval" 64 --words "$VOCAB" "${eval_json[@]}" >"$OUT/eval.stats.json"

python3 - "$OUT" <<'PY'
import json, sys
out = sys.argv[1]
pk = [json.loads(l) for l in open(f"{out}/packages.jsonl")]
splits = {s: json.load(open(f"{out}/{s}.stats.json")) for s in ("train", "eval")}
m = {"description": "Icon data for the embedded vf-icon model (scripts/embedded/prepare_data.sh). "
     "Rendered with resvg to 64x64 RGB over white; captions from icon names.",
     "image_size": 64, "packages": pk, "splits": splits}
json.dump(m, open("docs/embedded/data_manifest.json", "w"), indent=1)
print(json.dumps({s: v["total"] for s, v in splits.items()}))
PY
