"""Before/after sheet of traced SVGs for the docs: per row the input PNG, then for each SVG its
render and its outlines (every path drawn as a thin line, the ones that cross or touch
themselves in red, by shapely's is_valid on the flattened outline).

    python scripts/before_after.py OUT.png INPUT.png LABEL=A.svg LABEL=B.svg [-- INPUT.png ...]

Needs resvg-py, Pillow, shapely and svgelements (pip, in a virtual environment).
"""

import io
import re
import sys

import resvg_py
from PIL import Image, ImageDraw
from shapely.geometry import Polygon
from svgelements import SVG, Path

T = 200


def render(svg_text):
    png = bytes(resvg_py.svg_to_bytes(svg_string=svg_text, width=T, height=T))
    im = Image.open(io.BytesIO(png)).convert("RGBA")
    bg = Image.new("RGBA", im.size, "white")
    return Image.alpha_composite(bg, im).convert("RGB")


def outlines(svg_text):
    """The SVG's paths as thin outlines; self-intersecting ones in red."""
    doc = SVG.parse(io.StringIO(svg_text))
    w, h = doc.width, doc.height
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}">']
    n_bad = n = 0
    for el in doc.elements():
        if not isinstance(el, Path) or len(el) == 0:
            continue
        n += 1
        bad = False
        for sub in el.as_subpaths():
            sp = Path(sub)
            pts = [sp.point(t / 400) for t in range(400)]
            ring = [(p.x, p.y) for p in pts]
            if len(ring) >= 3 and not Polygon(ring).is_valid:
                bad = True
        n_bad += bad
        colour = "#e00" if bad else "#333"
        out.append(f'<path d="{el.d()}" fill="none" stroke="{colour}" stroke-width="{w / 300:.2f}"/>')
    out.append("</svg>")
    return "\n".join(out), n, n_bad


def main():
    out_path, args = sys.argv[1], sys.argv[2:]
    rows, cur = [], None
    for a in args:
        if a == "--":
            continue
        if "=" in a:
            cur[1].append(a.split("=", 1))
        else:
            cur = (a, [])
            rows.append(cur)
    cols = 1 + 2 * max(len(r[1]) for r in rows)
    sheet = Image.new("RGB", (cols * T, len(rows) * (T + 18)), "white")
    draw = ImageDraw.Draw(sheet)
    for r, (png, svgs) in enumerate(rows):
        y = r * (T + 18)
        im = Image.open(png).convert("RGBA").resize((T, T))
        bg = Image.new("RGBA", im.size, "white")
        sheet.paste(Image.alpha_composite(bg, im).convert("RGB"), (0, y))
        draw.text((4, y + T + 2), "input", fill="black")
        for k, (label, path) in enumerate(svgs):
            text = open(path).read()
            x = (1 + 2 * k) * T
            sheet.paste(render(text), (x, y))
            o, n, bad = outlines(text)
            sheet.paste(render(o), (x + T, y))
            draw.text((x + 4, y + T + 2), f"{label}: {len(text)} B", fill="black")
            draw.text((x + T + 4, y + T + 2), f"{n} paths, {bad} looping", fill="black")
    sheet.save(out_path)
    print(f"{len(rows)} rows -> {out_path}")


main()
