"""Gallery of held-out captions: (sample, traced SVG, final SVG), with and without retrieval.

Reads the output folders of `vectorfusion eval --method samples --method sd_live
--method sd_live_sds --out-dir DIR` (NNNN.png for samples, NNNN.svg for the methods) made with
and without `--no-retrieval`, renders the SVGs with `vectorfusion render`, and writes one PNG.

    python scripts/embedded/gallery.py --captions docs/embedded/heldout_fluent48.txt --n 24 \
        --with eval-out/fluent --without eval-out/fluent-noret --out docs/embedded/gallery.png
"""

import argparse
import os
import subprocess
import tempfile

import numpy as np
from PIL import Image, ImageDraw

CELL = 96


def load(path, vf):
    if path.endswith(".svg"):
        with tempfile.TemporaryDirectory() as td:
            png = os.path.join(td, "r.png")
            subprocess.run([vf, "render", path, "-o", png, "--size", str(CELL)], check=True, capture_output=True)
            im = Image.open(png).convert("RGBA")
    else:
        im = Image.open(path).convert("RGBA").resize((CELL, CELL), Image.NEAREST)
    bg = Image.new("RGBA", im.size, (255, 255, 255, 255))
    return Image.alpha_composite(bg, im).convert("RGB")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--captions", required=True)
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--with", dest="with_dir", required=True)
    ap.add_argument("--without", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--vf", default="target/release/vectorfusion")
    args = ap.parse_args()
    caps = [l.strip() for l in open(args.captions) if l.strip()][: args.n]
    cols = [(args.with_dir, "samples", "png"), (args.with_dir, "sd_live", "svg"), (args.with_dir, "sd_live_sds", "svg"),
            (args.without, "samples", "png"), (args.without, "sd_live", "svg"), (args.without, "sd_live_sds", "svg")]
    head = ["sample", "traced", "final", "sample", "traced", "final"]
    label_w, top = 170, 40
    grid = Image.new("RGB", (label_w + CELL * len(cols), top + CELL * len(caps)), "white")
    d = ImageDraw.Draw(grid)
    d.text((label_w + 4, 2), "with retrieval", fill="black")
    d.text((label_w + 3 * CELL + 4, 2), "noise only (--no-retrieval)", fill="black")
    for j, h in enumerate(head):
        d.text((label_w + j * CELL + 4, 20), h, fill="black")
    for i, c in enumerate(caps):
        d.text((4, top + i * CELL + CELL // 2 - 6), c[:28], fill="black")
        for j, (root, m, ext) in enumerate(cols):
            path = os.path.join(root, m, f"{i + 1:04}.{ext}")
            if os.path.exists(path):
                grid.paste(load(path, args.vf), (label_w + j * CELL, top + i * CELL))
    grid.save(args.out, optimize=True)
    print("wrote", args.out, grid.size)


if __name__ == "__main__":
    main()
