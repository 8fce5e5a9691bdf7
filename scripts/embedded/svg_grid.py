"""Labelled grid PNG of SVGs (rendered with resvg via the `resvg-py` package) for docs pictures.

    python scripts/embedded/svg_grid.py OUT.png LABEL=FILE.svg [LABEL=FILE.svg ...]
"""

import io
import sys

import resvg_py  # pip install resvg-py
from PIL import Image, ImageDraw

T, L, COLS = 160, 16, 3
out, items = sys.argv[1], [a.split("=", 1) for a in sys.argv[2:]]
rows = (len(items) + COLS - 1) // COLS
sheet = Image.new("RGB", (COLS * T, rows * (T + L)), "white")
draw = ImageDraw.Draw(sheet)
for i, (label, path) in enumerate(items):
    png = bytes(resvg_py.svg_to_bytes(svg_path=path, width=T - 8, height=T - 8))
    im = Image.open(io.BytesIO(png)).convert("RGBA")
    bg = Image.new("RGBA", im.size, "white")
    im = Image.alpha_composite(bg, im).convert("RGB")
    x, y = (i % COLS) * T, (i // COLS) * (T + L)
    sheet.paste(im, (x + 4, y + 4))
    draw.text((x + 4, y + T - 2), label[:26], fill="black")
sheet.save(out)
print(f"{len(items)} tiles -> {out}")
