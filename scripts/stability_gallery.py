#!/usr/bin/env python3
"""Contact sheet of runs saved by `vectorfusion bench stability --save DIR --json`.

Usage: scripts/stability_gallery.py REPORT.json SAVE_DIR OUT.png [N]
Shows every failed run and, per method × style, the worst-PSNR run (the typical failure), labelled
with method, style, seed, PSNR and failure kinds; N caps the tiles (default 24). Needs Pillow.
"""
import json, os, sys
from PIL import Image, ImageDraw

rep, d, out = json.load(open(sys.argv[1])), sys.argv[2], sys.argv[3]
cap = int(sys.argv[4]) if len(sys.argv) > 4 else 24
runs = [r for r in rep.get("runs", []) if r.get("file")]
pick = [r for r in runs if r["failures"]]
for key in sorted({(r["method"], r["style"]) for r in runs}):
    cell = [r for r in runs if (r["method"], r["style"]) == key and r["psnr"] is not None]
    if cell:
        w = min(cell, key=lambda r: r["psnr"])
        if w not in pick:
            pick.append(w)
pick = pick[:cap]
T, L, cols = 128, 30, 6
rows = max(1, (len(pick) + cols - 1) // cols)
sheet = Image.new("RGB", (cols * T, rows * (T + L)), "white")
draw = ImageDraw.Draw(sheet)
for i, r in enumerate(pick):
    x, y = (i % cols) * T, (i // cols) * (T + L)
    im = Image.open(os.path.join(d, r["file"] + ".png")).convert("RGBA")
    bg = Image.new("RGBA", im.size, "white")
    im = Image.alpha_composite(bg, im).convert("RGB").resize((T - 8, T - 8), Image.NEAREST)
    sheet.paste(im, (x + 4, y + 4))
    ps = "-" if r["psnr"] is None else f'{r["psnr"]:.1f} dB'
    draw.text((x + 4, y + T - 2), f'{r["method"]} {r["style"]} s{r["seed"]}', fill="black")
    draw.text((x + 4, y + T + 10), f'{ps} {",".join(r["failures"]) or "worst"}', fill="red" if r["failures"] else "black")
sheet.save(out)
print(f"{len(pick)} tiles -> {out}")
