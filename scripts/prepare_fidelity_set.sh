#!/usr/bin/env bash
# Fetches and prepares the LIVE / vtracer fidelity set into data/fidelity/ (git-ignored):
#   - ICONS (default 36) Twemoji icons from the npm package @iconify-json/twemoji (CC-BY 4.0,
#     Twitter), every k-th non-flag icon in name order, rendered at SIZE px with resvg;
#   - the colour photos shipped inside the scikit-image wheel (pip download, no install),
#     centre-cropped and resized to SIZE px.
# Needs: npm, pip, node, cargo. Deterministic for a given package version.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
OUT="${OUT:-$ROOT/data/fidelity}"
SIZE="${SIZE:-256}"
ICONS="${ICONS:-36}"
TWEMOJI_VERSION="${TWEMOJI_VERSION:-1.2.5}"
SKIMAGE_VERSION="${SKIMAGE_VERSION:-0.26.0}"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT

echo "fetching @iconify-json/twemoji@$TWEMOJI_VERSION" >&2
(cd "$TMP" && npm pack "@iconify-json/twemoji@$TWEMOJI_VERSION" --silent >/dev/null)
tar xzf "$TMP"/iconify-json-twemoji-*.tgz -C "$TMP"
mkdir -p "$TMP/src"
node - "$TMP/package/icons.json" "$TMP/src" "$ICONS" <<'JS'
const fs = require('fs');
const [file, dir, count] = process.argv.slice(2);
const set = JSON.parse(fs.readFileSync(file, 'utf8'));
const names = Object.keys(set.icons).sort()
  .filter(n => !n.startsWith('flag') && !n.startsWith('regional') && !n.startsWith('keycap'));
const step = Math.max(1, Math.floor(names.length / Number(count)));
for (let i = 0, k = 0; i < names.length && k < Number(count); i += step, k++) {
  const icon = set.icons[names[i]];
  const w = icon.width || set.width || 16, h = icon.height || set.height || 16;
  const svg = `<svg xmlns="http://www.w3.org/2000/svg" width="${w}" height="${h}" viewBox="0 0 ${w} ${h}">${icon.body}</svg>`;
  fs.writeFileSync(`${dir}/icon-${names[i]}.svg`, svg);
}
JS

echo "fetching scikit-image $SKIMAGE_VERSION wheel (photos only)" >&2
pip download "scikit-image==$SKIMAGE_VERSION" --no-deps --only-binary=:all: -d "$TMP/wheel" -q
python3 - "$TMP"/wheel/*.whl "$TMP/src" <<'PY'
import sys, zipfile
whl, out = sys.argv[1], sys.argv[2]
photos = ["astronaut.png", "coffee.png", "chelsea.png", "rocket.jpg", "motorcycle_left.png", "logo.png"]
with zipfile.ZipFile(whl) as z:
    names = z.namelist()
    for p in photos:
        hit = [n for n in names if n.endswith("skimage/data/" + p)]
        if hit:
            with open(f"{out}/photo-{p}", "wb") as f:
                f.write(z.read(hit[0]))
PY

rm -rf "$OUT" && mkdir -p "$OUT"
(cd "$ROOT" && cargo run --quiet --example fidelity_render -- "$TMP/src" "$OUT" "$SIZE")
echo "fidelity set ready in $OUT" >&2
