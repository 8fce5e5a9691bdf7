#!/usr/bin/env bash
# Prepares the rate-distortion set for `vectorfusion bench vectorize --rd` into OUT_DIR (outside
# the repository; nothing here is committed). One sub-folder per image set, 256 px PNGs:
#   emoji/  colour emoji: @iconify-json/twemoji, noto, emojione (EMOJI each, default 8)
#   flat/   flat colour icons and illustrations: @iconify-json/flat-color-icons and
#           streamline-ultimate-color (FLAT each, default 6)
#   mono/   one-colour icons for the black-and-white peer (potrace): @iconify-json/mdi (MONO, 10)
#   gradient/  colour emoji drawn mostly with gradients, for `--fills`: @iconify-json/noto icons
#           with at least two `url(#…)` fills making up at least half of their shapes (GRADIENT,
#           default 6)
#   photo/  the photos inside the scikit-image wheel (pip download, no install), resized to
#           SIZE px on the longest side (Lanczos, RGB)
#   banner/ non-square strips of the emoji (below)
# Icons: every k-th icon in name order (flags, keycaps, regional letters, skin tones and names
# starting with a digit left out), rendered with resvg at SIZE px (transparent background,
# examples/fidelity_render.rs, as scripts/prepare_fidelity_set.sh does). fluent-emoji* and
# openmoji are never used: they are held out for evaluation.
# Also installs the imagetracerjs peer (npm imagetracerjs + pngjs) into OUT_DIR/_tools
# (TOOLS=DIR elsewhere), which the bench finds there by default.
# Needs: npm, node, pip, python3 (Pillow: taken from PY, else installed into a venv under
# /tmp), cargo. Deterministic for the pinned versions below. Usage: prepare_rd_set.sh OUT_DIR
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
OUT="${1:?usage: prepare_rd_set.sh OUT_DIR}"
SIZE="${SIZE:-256}"
EMOJI="${EMOJI:-8}"
FLAT="${FLAT:-6}"
MONO="${MONO:-10}"
GRADIENT="${GRADIENT:-6}"
TOOLS="${TOOLS:-$OUT/_tools}"
SKIMAGE_VERSION="${SKIMAGE_VERSION:-0.26.0}"
IMAGETRACER_VERSION="${IMAGETRACER_VERSION:-1.2.6}"
PNGJS_VERSION="${PNGJS_VERSION:-7.0.0}"
# set:package@version:count
SETS=(
  "emoji:twemoji@1.2.5:$EMOJI"
  "emoji:noto@1.2.9:$EMOJI"
  "emoji:emojione@1.2.3:$EMOJI"
  "flat:flat-color-icons@1.2.3:$FLAT"
  "flat:streamline-ultimate-color@1.2.2:$FLAT"
  "mono:mdi@1.2.3:$MONO"
  "gradient:noto@1.2.9:$GRADIENT"
)
PHOTOS="${PHOTOS:-astronaut.png camera.png chelsea.png coffee.png hubble_deep_field.jpg ihc.png motorcycle_left.png rocket.jpg}"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
case "$OUT" in "$ROOT"/*) echo "OUT_DIR must be outside the repository" >&2; exit 2 ;; esac

rm -rf "$OUT" && mkdir -p "$OUT"
for entry in "${SETS[@]}"; do
  IFS=: read -r set pkg count <<<"$entry"
  name="${pkg%@*}"
  echo "fetching @iconify-json/$pkg -> $set ($count icons)" >&2
  mkdir -p "$TMP/pk/$name" "$TMP/src/$set"
  (cd "$TMP/pk/$name" && npm pack "@iconify-json/$pkg" --silent >/dev/null && tar xzf ./*.tgz)
  node - "$TMP/pk/$name/package/icons.json" "$TMP/src/$set" "$count" "$name" <<'JS'
const fs = require('fs');
const [file, dir, count, prefix] = process.argv.slice(2);
const set = JSON.parse(fs.readFileSync(file, 'utf8'));
// The gradient set keeps icons painted mostly with gradients.
const gradients = body => {
  const fills = (body.match(/fill="url\(#/g) || []).length;
  const shapes = (body.match(/<(path|circle|ellipse|rect|polygon)\b/g) || []).length;
  return fills >= 2 && 2 * fills >= shapes;
};
const names = Object.keys(set.icons).sort()
  .filter(n => !/^(flag|regional|keycap)/.test(n) && !/tone/.test(n) && !/^[0-9]/.test(n))
  .filter(n => !dir.endsWith('/gradient') || gradients(set.icons[n].body));
const step = Math.max(1, Math.floor(names.length / Number(count)));
for (let i = 0, k = 0; i < names.length && k < Number(count); i += step, k++) {
  const icon = set.icons[names[i]];
  const w = icon.width || set.width || 16, h = icon.height || set.height || 16;
  const svg = `<svg xmlns="http://www.w3.org/2000/svg" width="${w}" height="${h}" viewBox="0 0 ${w} ${h}">${icon.body}</svg>`;
  fs.writeFileSync(`${dir}/${prefix}-${names[i]}.svg`, svg);
}
JS
done
for set in "$TMP"/src/*; do
  (cd "$ROOT" && cargo run --quiet --release --example fidelity_render -- "$set" "$OUT/$(basename "$set")" "$SIZE")
done

echo "fetching scikit-image $SKIMAGE_VERSION wheel (photos only)" >&2
pip download "scikit-image==$SKIMAGE_VERSION" --no-deps --only-binary=:all: -d "$TMP/wheel" -q
PY="${PY:-python3}"
if ! "$PY" -c 'import PIL' 2>/dev/null; then
  PY=/tmp/vf-rd-venv/bin/python
  [ -x "$PY" ] || python3 -m venv /tmp/vf-rd-venv
  "$PY" -c 'import PIL' 2>/dev/null || /tmp/vf-rd-venv/bin/pip install -q pillow
fi
mkdir -p "$OUT/photo"
"$PY" - "$TMP"/wheel/*.whl "$OUT/photo" "$SIZE" $PHOTOS <<'PY'
import io, sys, zipfile
from PIL import Image
whl, out, size, photos = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4:]
with zipfile.ZipFile(whl) as z:
    names = z.namelist()
    for p in photos:
        hit = [n for n in names if n.endswith("skimage/data/" + p)]
        if not hit:
            print(f"photo {p} not in the wheel, skipped", file=sys.stderr)
            continue
        im = Image.open(io.BytesIO(z.read(hit[0]))).convert("RGB")
        k = size / max(im.size)
        im = im.resize((max(1, round(im.width * k)), max(1, round(im.height * k))), Image.LANCZOS)
        im.save(f"{out}/photo-{p.rsplit('.', 1)[0]}.png")
PY

# banner/: strips of the emoji above at 64 px, side by side on white (w4-*: 4 in a row, 256x64;
# w8-*: 8 in a row, 512x64; t8-*: the w8 strips transposed, 64x512), for non-square inputs.
mkdir -p "$OUT/banner"
"$PY" - "$OUT/emoji" "$OUT/banner" <<'PY'
import os, sys
from PIL import Image
src, out = sys.argv[1], sys.argv[2]
names = sorted(n for n in os.listdir(src) if n.endswith(".png"))
ims = [Image.open(os.path.join(src, n)).convert("RGBA").resize((64, 64), Image.LANCZOS) for n in names]
def strip(group):
    b = Image.new("RGBA", (64 * len(group), 64), (255, 255, 255, 255))
    for i, im in enumerate(group):
        b.alpha_composite(im, (64 * i, 0))
    return b
for j in range(len(ims) // 4):
    strip(ims[4 * j:4 * j + 4]).save(f"{out}/w4-{j}.png")
for j in range(len(ims) // 8):
    s = strip(ims[8 * j:8 * j + 8])
    s.save(f"{out}/w8-{j}.png")
    s.transpose(Image.TRANSPOSE).save(f"{out}/t8-{j}.png")
PY

echo "installing imagetracerjs $IMAGETRACER_VERSION + pngjs $PNGJS_VERSION into $TOOLS" >&2
mkdir -p "$TOOLS"
npm install --prefix "$TOOLS" --silent --no-audit --no-fund \
  "imagetracerjs@$IMAGETRACER_VERSION" "pngjs@$PNGJS_VERSION" >/dev/null
(cd "$OUT" && find . -name '*.png' -not -path './_tools/*' | sort | xargs sha256sum) > "$OUT/SHA256SUMS"
for d in "$OUT"/*/; do
  n=$(find "$d" -maxdepth 1 -name '*.png' | wc -l)
  [ "$n" -gt 0 ] && echo "$(basename "$d"): $n images" >&2
done
echo "rate-distortion set ready in $OUT" >&2
