"""Do our SVGs open the same everywhere? Renders every SVG of a folder with resvg (resvg-py),
headless Chromium and Inkscape (and our own rasteriser, `vectorfusion render`, for reference) at
the SVG's own size over white, and reports the mean absolute difference (in /255 of RGB) of each
pair of renderers, per file and in all (issue #23's target: at most 1.5/255 between each pair).

    python scripts/cross_render.py --svgs DIR [--side 256] [--vf target/debug/vectorfusion] \
        [--json docs/cross_render.json] [--keep OUTDIR]

Needs: resvg-py and pillow/numpy in the Python environment, `chromium` and `inkscape` on PATH
(Debian packages). A renderer that is missing is left out (and said so).
"""

import argparse
import glob
import itertools
import json
import os
import re
import shutil
import subprocess
import tempfile

import numpy as np
from PIL import Image


def svg_size(text):
    w = re.search(r'<svg[^>]*\swidth="([0-9.]+)', text)
    h = re.search(r'<svg[^>]*\sheight="([0-9.]+)', text)
    if not (w and h):
        raise ValueError("the SVG has no numeric width and height")
    return round(float(w.group(1))), round(float(h.group(1)))


def over_white(path, size):
    im = Image.open(path).convert("RGBA")
    if im.size != size:
        raise ValueError(f"{path}: rendered {im.size}, expected {size}")
    a = np.asarray(im, dtype=np.float64) / 255.0
    return (a[..., :3] * a[..., 3:] + (1 - a[..., 3:])) * 255.0


def render_resvg(svg, out, size):
    import resvg_py

    data = resvg_py.svg_to_bytes(svg_path=svg, width=size[0], height=size[1])
    with open(out, "wb") as f:
        f.write(bytes(data))


def render_chromium(svg, out, size, exe):
    # The SVG as the page itself, at 1 CSS px per device px, no scrollbars.
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run(
            [exe, "--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars",
             "--force-device-scale-factor=1", "--default-background-color=ffffffff",
             f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}",
             f"--screenshot={out}", "file://" + os.path.abspath(svg)],
            check=True, capture_output=True, timeout=120)


def render_inkscape(svg, out, size, exe):
    subprocess.run(
        [exe, "--export-type=png", f"--export-filename={out}", "--export-background=white",
         "--export-background-opacity=1", f"--export-width={size[0]}", f"--export-height={size[1]}", svg],
        check=True, capture_output=True, timeout=120)


def render_ours(svg, out, size, vf):
    subprocess.run([vf, "render", svg, "-o", out, "--size", str(size[0])], check=True, capture_output=True, timeout=120)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--svgs", required=True)
    ap.add_argument("--vf", default="target/debug/vectorfusion")
    ap.add_argument("--json")
    ap.add_argument("--keep", help="keep the PNGs here")
    ap.add_argument("--side", type=int, help="draw at this width (the SVG's width/height rewritten, the viewBox scales)")
    args = ap.parse_args()
    files = sorted(glob.glob(os.path.join(args.svgs, "**", "*.svg"), recursive=True))
    if not files:
        raise SystemExit(f"no SVGs under {args.svgs}")
    renderers = {"resvg": lambda s, o, z: render_resvg(s, o, z)}
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    inkscape = shutil.which("inkscape")
    if chromium:
        renderers["chromium"] = lambda s, o, z: render_chromium(s, o, z, chromium)
    else:
        print("chromium not found: left out")
    if inkscape:
        renderers["inkscape"] = lambda s, o, z: render_inkscape(s, o, z, inkscape)
    else:
        print("inkscape not found: left out")
    if os.path.exists(args.vf):
        renderers["ours"] = lambda s, o, z: render_ours(s, o, z, args.vf)
    out_dir = args.keep or tempfile.mkdtemp()
    os.makedirs(out_dir, exist_ok=True)
    pairs = list(itertools.combinations(renderers, 2))
    per_file = []
    for i, svg in enumerate(files):
        text = open(svg, encoding="utf-8").read()
        size = svg_size(text)
        if args.side:
            size = (args.side, round(args.side * size[1] / size[0]))
            head, rest = text.split(">", 1)
            head = re.sub(r'\swidth="[^"]*"', f' width="{size[0]}"', head, count=1)
            head = re.sub(r'\sheight="[^"]*"', f' height="{size[1]}"', head, count=1)
            scaled = os.path.join(out_dir, f"{i:03d}.svg")
            with open(scaled, "w", encoding="utf-8") as f:
                f.write(head + ">" + rest)
            svg_in = scaled
        else:
            svg_in = svg
        imgs = {}
        for name, fn in renderers.items():
            png = os.path.join(out_dir, f"{i:03d}_{name}.png")
            fn(svg_in, png, size)
            imgs[name] = over_white(png, size)
        row = {"file": os.path.relpath(svg, args.svgs), "size": size}
        for a, b in pairs:
            row[f"{a}~{b}"] = float(np.abs(imgs[a] - imgs[b]).mean())
        per_file.append(row)
        print(row["file"], " ".join(f"{k}={v:.3f}" for k, v in row.items() if "~" in k), flush=True)
    summary = {}
    for a, b in pairs:
        k = f"{a}~{b}"
        v = np.array([r[k] for r in per_file])
        summary[k] = {"mean": float(v.mean()), "median": float(np.median(v)), "max": float(v.max()),
                      "files_over_1.5": int((v > 1.5).sum())}
    report = {"files": len(files), "renderers": list(renderers), "unit": "mean |difference| of RGB over white, /255",
              "summary": summary, "per_file": per_file}
    print(json.dumps(summary, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
            f.write("\n")


if __name__ == "__main__":
    main()
