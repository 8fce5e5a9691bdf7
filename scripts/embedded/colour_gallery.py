"""Before/after grid of `generate` SVGs for docs pictures (docs/embedded/COLOUR.md): one column
per caption, one row per directory of SVGs (NNNN.svg for caption line N), rendered with
`vectorfusion render`.

    python scripts/embedded/colour_gallery.py --captions CAPTIONS.txt --out docs/embedded/colour.png \
        --row "before=DIR" --row "after=DIR" [--vf target/debug/vectorfusion]
"""

import argparse
import os
import subprocess
import tempfile

from PIL import Image, ImageDraw

T, LABEL, LEFT = 96, 14, 52


def render(vf, svg, size):
    with tempfile.TemporaryDirectory() as td:
        png = os.path.join(td, "r.png")
        subprocess.run([vf, "render", svg, "-o", png, "--size", str(size)], check=True, capture_output=True)
        im = Image.open(png).convert("RGBA")
        bg = Image.new("RGBA", im.size, "white")
        return Image.alpha_composite(bg, im).convert("RGB")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--captions", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--row", action="append", required=True, help="LABEL=DIR")
    ap.add_argument("--vf", default="target/debug/vectorfusion")
    args = ap.parse_args()
    captions = [l.strip() for l in open(args.captions) if l.strip()]
    rows = [r.split("=", 1) for r in args.row]
    sheet = Image.new("RGB", (LEFT + len(captions) * T, LABEL + len(rows) * T), "white")
    draw = ImageDraw.Draw(sheet)
    for j, caption in enumerate(captions):
        draw.text((LEFT + j * T + 2, 1), caption[:16], fill="black")
    for i, (label, d) in enumerate(rows):
        y = LABEL + i * T
        draw.text((2, y + T // 2 - 6), label[:8], fill="black")
        for j in range(len(captions)):
            svg = os.path.join(d, f"{j + 1:04}.svg")
            sheet.paste(render(args.vf, svg, T - 6), (LEFT + j * T + 3, y + 3))
    sheet.save(args.out)
    print(f"{len(captions)} captions x {len(rows)} rows -> {args.out}")


if __name__ == "__main__":
    main()
