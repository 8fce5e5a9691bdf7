#!/usr/bin/env python3
"""Renders resvg's own test suite with `vectorfusion render` and compares every picture with
resvg's reference PNG at the reference's size.

Usage:
    git --git-dir=<resvg checkout>/.git archive HEAD crates/resvg/tests/tests \
        crates/resvg/tests/resources crates/resvg/tests/fonts | tar -x -C /tmp/resvg-suite
    scripts/resvg_suite.py /tmp/resvg-suite/crates/resvg/tests/tests \
        [--bin target/release/vectorfusion] [--json out.json] [--fails] [--jobs N] [--fonts DIR]
        [--pdf] [--antialias exact|supersampled]

Reads the folders shapes, painting, structure, paint-servers and masking (filters and the
`text` folder are out of scope; text inside the other folders is drawn). Text is drawn with the
fonts of `--fonts` (default: `../fonts` beside TESTS, resvg's test fonts, when it exists) and
no system fonts (`VF_FONT_DIRS`, `VF_SYSTEM_FONTS=0`), as resvg's harness draws it. A test passes when, over premultiplied RGBA in 0..255 units, the mean absolute
difference is at most 1.5 and at most 1 % of the pixels differ by more than 16 in some channel;
an SVG that `render` refuses fails. Pictures are drawn with `render --antialias supersampled`
(16 samples a pixel, as tiny-skia anti-aliases resvg's references); `--antialias exact` measures
the exact area coverage the optimisers use instead. Prints the pass counts per folder and per
feature (sub-folder) as Markdown tables; `--fails` lists every failing test with its numbers or error
and `--json` writes every test's result (warnings included: `render` prints them on stderr).
`--pdf` measures the PDF export instead: `render -o OUT.pdf`, drawn by poppler's `pdftocairo`
(cairo's anti-aliasing is close to resvg's; `pdftoppm` snaps thin strokes and rectangles to
pixels) at the reference's size, against the reference over white (both opaque), by the same
rule.
Standard library only (its own PNG reader), and `pdftocairo` for `--pdf`.
"""

import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile
import zlib
from concurrent.futures import ThreadPoolExecutor

FOLDERS = ["shapes", "painting", "structure", "paint-servers", "masking"]
MAX_MEAN_ABS = 1.5
OFF_BY = 16
MAX_OFF_SHARE = 0.01


def read_png(path):
    """(width, height, straight RGBA bytes) of a non-interlaced PNG of 8 bits per channel, or of
    1, 2, 4 or 8 bits per palette index or grey level."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos, idat, palette, trns = 8, [], None, None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
        elif kind == b"PLTE":
            palette = body
        elif kind == b"tRNS":
            trns = body
        elif kind == b"IDAT":
            idat.append(body)
    if interlace or (depth != 8 and ctype not in (0, 3)) or depth > 8:
        raise ValueError(f"{path}: interlaced or 16-bit PNGs are not read")
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[ctype]
    raw = zlib.decompress(b"".join(idat))
    stride = (w * channels * depth + 7) // 8
    out = bytearray(h * stride)
    prev = bytearray(stride)
    for y in range(h):
        ftype = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1 : (y + 1) * (stride + 1)])
        if ftype == 1:
            for i in range(channels, stride):
                line[i] = (line[i] + line[i - channels]) & 255
        elif ftype == 2:
            line = bytearray((a + b) & 255 for a, b in zip(line, prev))
        elif ftype == 3:
            for i in range(stride):
                left = line[i - channels] if i >= channels else 0
                line[i] = (line[i] + ((left + prev[i]) >> 1)) & 255
        elif ftype == 4:
            for i in range(stride):
                a = line[i - channels] if i >= channels else 0
                b = prev[i]
                c = prev[i - channels] if i >= channels else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[i] = (line[i] + pred) & 255
        out[y * stride : (y + 1) * stride] = line
        prev = line
    if depth < 8:
        per = 8 // depth
        mask = (1 << depth) - 1
        unpacked = bytearray(w * h)
        for y in range(h):
            row = out[y * stride : (y + 1) * stride]
            for x in range(w):
                v = (row[x // per] >> (8 - depth * (x % per + 1))) & mask
                unpacked[y * w + x] = v if ctype == 3 else v * 255 // mask
        out = unpacked
    if ctype == 6:
        return w, h, bytes(out)
    rgba = bytearray()
    for i in range(0, len(out), channels):
        px = out[i : i + channels]
        if ctype == 0:
            rgba += bytes([px[0], px[0], px[0], 255])
        elif ctype == 4:
            rgba += bytes([px[0], px[0], px[0], px[1]])
        elif ctype == 2:
            rgba += bytes([px[0], px[1], px[2], 255])
        else:
            k = px[0]
            alpha = trns[k] if trns is not None and k < len(trns) else 255
            rgba += palette[3 * k : 3 * k + 3] + bytes([alpha])
    return w, h, bytes(rgba)


def compare(ours, ref):
    """Mean absolute difference and share of pixels off by more than OFF_BY (premultiplied)."""
    total, off, n = 0.0, 0, len(ref) // 4
    for i in range(0, len(ref), 4):
        a1, a2 = ours[i + 3], ref[i + 3]
        worst = abs(a1 - a2)
        total += worst
        for c in range(3):
            d = abs(ours[i + c] * a1 - ref[i + c] * a2) / 255.0
            total += d
            worst = max(worst, d)
        off += worst > OFF_BY
    return total / (4 * n), off / n


def over_white(rgba):
    """Straight RGBA composited over white, opaque."""
    out = bytearray(rgba)
    for i in range(0, len(out), 4):
        a = out[i + 3]
        for c in range(3):
            out[i + c] = (out[i + c] * a + 255 * (255 - a) + 127) // 255
        out[i + 3] = 255
    return bytes(out)


def run_one(binary, root, svg, tmp, env, pdf, antialias):
    rel = os.path.relpath(svg, root)
    parts = rel.split(os.sep)
    result = {
        "test": rel[:-4],
        "folder": parts[0],
        "feature": "/".join(parts[:-1]),
        "pass": False,
        "warnings": [],
    }
    try:
        w, h, ref = read_png(svg[:-4] + ".png")
        stem = os.path.join(tmp, rel.replace(os.sep, "__")[:-4])
        out = stem + (".pdf" if pdf else ".png")
        proc = subprocess.run(
            [binary, "render", svg, "-o", out, "--size", str(w)]
            + ([] if pdf else ["--antialias", antialias]),
            capture_output=True,
            text=True,
            timeout=60,
            env=env,
        )
        result["warnings"] = [
            line[len("warning: ") :]
            for line in proc.stderr.splitlines()
            if line.startswith("warning: ")
        ]
        if proc.returncode != 0:
            result["error"] = proc.stderr.strip().splitlines()[-1] if proc.stderr else "failed"
            return result
        if pdf:
            drawn = subprocess.run(
                ["pdftocairo", "-png", "-singlefile", "-scale-to-x", str(w), "-scale-to-y", str(h),
                 out, stem + "-pdf"],
                capture_output=True,
                text=True,
                timeout=60,
            )
            if drawn.returncode != 0:
                result["error"] = "pdftocairo: " + (drawn.stderr.strip() or "failed")
                return result
            out, ref = stem + "-pdf.png", over_white(ref)
        ow, oh, ours = read_png(out)
        if (ow, oh) != (w, h):
            result["error"] = f"size {ow}x{oh} vs reference {w}x{h}"
            return result
        mean, share = compare(ours, ref)
        result.update(mean_abs=mean, off_share=share)
        result["pass"] = mean <= MAX_MEAN_ABS and share <= MAX_OFF_SHARE
    except (OSError, ValueError, subprocess.TimeoutExpired) as e:
        result["error"] = str(e)
    return result


def table(title, rows):
    print(f"\n| {title} | pass | tests | % |\n|---|---:|---:|---:|")
    p = n = 0
    for k in sorted(rows):
        ok, total = rows[k]
        print(f"| {k} | {ok} | {total} | {100 * ok / total:.0f} |")
        p, n = p + ok, n + total
    print(f"| **all** | {p} | {n} | {100 * p / max(n, 1):.0f} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("tests", help="resvg's crates/resvg/tests/tests")
    ap.add_argument("--bin", default="target/release/vectorfusion")
    ap.add_argument("--json")
    ap.add_argument("--fails", action="store_true")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--fonts", help="font directory (default: TESTS/../fonts if it exists)")
    ap.add_argument(
        "--only",
        help="only the tests whose path under TESTS starts with one of these (comma-separated, "
        "e.g. paint-servers/pattern,painting/stroke)",
    )
    ap.add_argument("--pdf", action="store_true", help="measure the PDF export (needs pdftocairo)")
    ap.add_argument(
        "--antialias",
        choices=("exact", "supersampled"),
        default="supersampled",
        help="render's anti-aliasing of the PNG (default supersampled: 4 x 4 samples a pixel, as "
        "resvg anti-aliases its references; exact: area coverage, the optimisers' model)",
    )
    args = ap.parse_args()
    fonts = args.fonts or os.path.join(args.tests, os.pardir, "fonts")
    env = dict(os.environ, VF_SYSTEM_FONTS="0")
    if os.path.isdir(fonts):
        env["VF_FONT_DIRS"] = os.path.abspath(fonts)
    else:
        print(f"note: no font directory {fonts}: text is not drawn", file=sys.stderr)
    svgs = []
    for folder in FOLDERS:
        for d, _, files in os.walk(os.path.join(args.tests, folder)):
            for f in files:
                p = os.path.join(d, f)
                if f.endswith(".svg") and os.path.exists(p[:-4] + ".png"):
                    svgs.append(p)
    if args.only:
        keep = tuple(args.only.split(","))
        svgs = [p for p in svgs if os.path.relpath(p, args.tests).startswith(keep)]
    svgs.sort()
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        def one(svg):
            return run_one(args.bin, args.tests, svg, tmp, env, args.pdf, args.antialias)

        results = list(pool.map(one, svgs))
    folders, features = {}, {}
    for r in results:
        for rows, key in ((folders, r["folder"]), (features, r["feature"])):
            ok, total = rows.get(key, (0, 0))
            rows[key] = (ok + r["pass"], total + 1)
        if args.fails and not r["pass"]:
            if "error" in r:
                print(f"FAIL {r['test']}: {r['error']}")
            else:
                print(f"FAIL {r['test']}: mean {r['mean_abs']:.2f}, off {100 * r['off_share']:.1f} %")
    table("folder", folders)
    table("feature", features)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
