#!/usr/bin/env python3
"""The pictures of docs/SERVICE.md's "Controls" section: one row per control, drawn by
`vectorfusion generate` on the embedded default model (draft preset, fixed seeds), rendered by
`vectorfusion render` and laid side by side over a checkerboard (so a transparent background
shows). The export picture is the playground page's result area, cropped from the browser test's
screenshot (tests/playground_page.rs writes target/tmp/playground/playground-variations.png;
run it first).

Usage: scripts/controls_gallery.py [OUT_DIR]   (default docs/img; VF_BIN names the binary,
default target/debug/vectorfusion; VF_ROWS=controls_fill,... draws only those rows and no
export picture). Python standard library only: PNGs are decoded and written
here (8-bit RGB/RGBA, non-interlaced, as resvg and Chromium write them).
"""

import os
import struct
import subprocess
import sys
import tempfile
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BIN = os.environ.get("VF_BIN", str(ROOT / "target/debug/vectorfusion"))
HEIGHT = 112  # px, every picture of a row
GAP = 8
PAGE_BG = (238, 240, 243)
CHECK = ((255, 255, 255), (214, 218, 224))

# (file, caption, [(seed, extra generate args)]): one picture per entry, left to right.
ROWS = [
    ("controls_canvas", "a red apple",
     [(3, []), (3, ["--aspect", "16:9"]), (3, ["--aspect", "9:16"])]),
    ("controls_variations", "a red apple", [(3, ["--variations", "3", "--samples", "3"])]),
    ("controls_negative", "a bird",
     [(5, []), (5, ["--negative-prompt", "blue"])]),
    ("controls_colours", "a red apple",
     [(3, []), (3, ["--colors", "2"]), (3, ["--palette", "#1d3557,#e63946,#f1faee"])]),
    ("controls_background", "a red apple",
     [(3, []), (3, ["--background", "transparent"]), (3, ["--background", "#ffe8a3"])]),
    ("controls_fill", "a red apple",
     [(3, []), (3, ["--fill", "linear"]), (3, ["--fill", "radial"])]),
]


def read_png(path):
    """(width, height, rows of (r, g, b, a) tuples) of an 8-bit RGB or RGBA PNG."""
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat, head = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            head = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    w, h, depth, ctype, _, _, interlace = head
    assert depth == 8 and ctype in (2, 6) and interlace == 0, (path, head)
    bpp = 4 if ctype == 6 else 3
    raw, stride, prev, rows, i = zlib.decompress(idat), w * bpp, bytearray(w * bpp), [], 0
    for _ in range(h):
        f, line = raw[i], bytearray(raw[i + 1:i + 1 + stride])
        i += 1 + stride
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            b, c = prev[x], prev[x - bpp] if x >= bpp else 0
            if f == 1:
                line[x] = (line[x] + a) & 255
            elif f == 2:
                line[x] = (line[x] + b) & 255
            elif f == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else b if pb <= pc else c
                line[x] = (line[x] + pred) & 255
        prev = line
        px = [tuple(line[x:x + bpp]) + ((255,) if bpp == 3 else ()) for x in range(0, stride, bpp)]
        rows.append(px)
    return w, h, rows


def write_png(path, w, h, rows):
    """An 8-bit RGB PNG of `rows` (lists of (r, g, b))."""
    raw = b"".join(b"\0" + bytes(v for px in row for v in px) for row in rows)

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    Path(path).write_bytes(png)


def scaled(img, height):
    """`img` box-filtered (or nearest, when enlarging) to `height` px high."""
    w, h, rows = img
    nw = max(1, round(w * height / h))
    out = []
    for y in range(height):
        y0, y1 = y * h // height, max(y * h // height + 1, (y + 1) * h // height)
        line = []
        for x in range(nw):
            x0, x1 = x * w // nw, max(x * w // nw + 1, (x + 1) * w // nw)
            px = [rows[yy][xx] for yy in range(y0, y1) for xx in range(x0, x1)]
            line.append(tuple(sum(p[k] for p in px) // len(px) for k in range(4)))
        out.append(line)
    return nw, height, out


def row_png(path, pictures):
    """`pictures` (RGBA images of one height) side by side over a checkerboard."""
    h = pictures[0][1]
    w = sum(p[0] for p in pictures) + GAP * (len(pictures) + 1)
    canvas = [[PAGE_BG] * w for _ in range(h + 2 * GAP)]
    x0 = GAP
    for pw, ph, rows in pictures:
        for y in range(ph):
            for x in range(pw):
                r, g, b, a = rows[y][x]
                bg = CHECK[(x // 8 + y // 8) % 2]
                canvas[GAP + y][x0 + x] = tuple((v * a + u * (255 - a)) // 255 for v, u in zip((r, g, b), bg))
        x0 += pw + GAP
    write_png(path, w, h + 2 * GAP, canvas)


def generate(tmp, name, caption, seed, extra):
    """The SVGs of one `generate` run (one per variation)."""
    out = tmp / f"{name}.svg"
    cmd = [BIN, "generate", caption, "--preset", "draft", "--seed", str(seed), "-o", str(out)] + extra
    subprocess.run(cmd, check=True, capture_output=True)
    return [out] if out.exists() else sorted(tmp.glob(f"{name}-*.svg"))


def render(svg, height):
    """`svg` rendered by `vectorfusion render`, `height` px high (at 4x, then box-filtered)."""
    png = svg.with_suffix(".png")
    text = svg.read_text()
    vb = text.split('viewBox="', 1)[1].split('"', 1)[0].split()
    w, h = float(vb[2]), float(vb[3])
    size = str(round(4 * height * w / h))
    subprocess.run([BIN, "render", str(svg), "-o", str(png), "--size", size], check=True, capture_output=True)
    return scaled(read_png(png), height)


def export_picture(out_dir):
    """The page's controls, variation thumbnails and download buttons, half size."""
    shot = ROOT / "target/tmp/playground/playground-variations.png"
    if not shot.exists():
        print(f"skip controls_export: {shot} missing (cargo test --test playground_page)")
        return
    _, _, rows = read_png(shot)
    # The form's canvas, variations and colour controls beside the variation picker and the
    # downloads (the test scrolls the picker to the middle of a 1280 px wide window).
    crop = [r[20:1230] for r in rows[100:560]]
    img = scaled((1210, len(crop), crop), len(crop) // 2)
    row_png(out_dir / "controls_export.png", [img])


def main():
    out_dir = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs/img"
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        only = [r for r in os.environ.get("VF_ROWS", "").split(",") if r]
        for name, caption, runs in ROWS:
            if only and name not in only:
                continue
            pictures = []
            for k, (seed, extra) in enumerate(runs):
                for svg in generate(tmp, f"{name}{k}", caption, seed, extra):
                    pictures.append(render(svg, HEIGHT))
            row_png(out_dir / f"{name}.png", pictures)
            print(f"{name}.png: {len(pictures)} pictures")
    if not only:
        export_picture(out_dir)


if __name__ == "__main__":
    main()
