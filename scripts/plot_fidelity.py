#!/usr/bin/env python3
"""Plots `vectorfusion bench vectorize --json` output as an SVG chart (no dependencies).

Usage: scripts/plot_fidelity.py BENCH.json OUT.svg [TITLE] [IMAGE_PREFIX]
With IMAGE_PREFIX (e.g. `icon-`), rows are recomputed from `per_image` for those images only.
Left: mean PSNR vs mean seconds per image; right: mean PSNR vs mean SVG bytes (both log x).
One marker per (method, budget) row, labelled with the budget.
"""
import json, math, sys

data = json.load(open(sys.argv[1]))
out = sys.argv[2]
title = sys.argv[3] if len(sys.argv) > 3 else f"LIVE vs vtracer, {data['images']} images"
rows = data["rows"]
if len(sys.argv) > 4:
    pre = sys.argv[4]
    groups = {}
    for s in data["per_image"]:
        if s["image"].startswith(pre):
            groups.setdefault((s["method"], s["budget"]), []).append(s)
    rows = []
    for (m, b), g in groups.items():
        n = len(g)
        rows.append({"method": m, "paths": b if b else round(sum(x["paths"] for x in g) / n),
                     "psnr_mean": sum(min(x["psnr"], 100) for x in g) / n,
                     "seconds_mean": sum(x["seconds"] for x in g) / n,
                     "svg_bytes_mean": sum(x["svg_bytes"] for x in g) / n})
colours = {"live": "#d62728", "live-vtracer-init": "#9467bd", "live-auto": "#ff7f0e",
           "vtracer-default": "#1f77b4", "vtracer-polygon": "#2ca02c", "vtracer-tuned": "#17becf"}
W, H, M = 460, 340, 55
ys = [r["psnr_mean"] for r in rows]
y0, y1 = math.floor(min(ys)) - 1, math.ceil(max(ys)) + 1

def panel(ox, key, xlabel):
    xs = [max(r[key], 1e-4) for r in rows]
    lx0, lx1 = math.floor(math.log10(min(xs))), math.ceil(math.log10(max(xs)))
    if lx1 == lx0:
        lx1 += 1
    px = lambda v: ox + M + (math.log10(max(v, 1e-4)) - lx0) / (lx1 - lx0) * (W - M - 15)
    py = lambda v: 30 + (y1 - v) / (y1 - y0) * (H - 30 - M)
    s = [f'<rect x="{ox + M}" y="30" width="{W - M - 15}" height="{H - 30 - M}" fill="none" stroke="#888"/>']
    for e in range(lx0, lx1 + 1):
        x = px(10 ** e)
        s.append(f'<line x1="{x:.1f}" y1="30" x2="{x:.1f}" y2="{H - M}" stroke="#eee"/>')
        s.append(f'<text x="{x:.1f}" y="{H - M + 15}" font-size="11" text-anchor="middle">1e{e}</text>')
    for v in range(int(y0), int(y1) + 1, 2):
        y = py(v)
        s.append(f'<line x1="{ox + M}" y1="{y:.1f}" x2="{ox + W - 15}" y2="{y:.1f}" stroke="#eee"/>')
        s.append(f'<text x="{ox + M - 5}" y="{y + 4:.1f}" font-size="11" text-anchor="end">{v}</text>')
    s.append(f'<text x="{ox + (W + M) / 2:.0f}" y="{H - M + 32}" font-size="12" text-anchor="middle">{xlabel} (log)</text>')
    s.append(f'<text x="{ox + 14}" y="{(H - M) / 2 + 15:.0f}" font-size="12" transform="rotate(-90 {ox + 14} {(H - M) / 2 + 15:.0f})" text-anchor="middle">PSNR dB (mean)</text>')
    for m in colours:
        pts = sorted([r for r in rows if r["method"] == m], key=lambda r: r[key])
        if len(pts) > 1:
            d = " ".join(f"{px(r[key]):.1f},{py(r['psnr_mean']):.1f}" for r in pts)
            s.append(f'<polyline points="{d}" fill="none" stroke="{colours[m]}" stroke-width="1"/>')
    for r in rows:
        c = colours.get(r["method"], "#333")
        x, y = px(r[key]), py(r["psnr_mean"])
        s.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="4" fill="{c}"/>')
        s.append(f'<text x="{x + 6:.1f}" y="{y - 5:.1f}" font-size="9" fill="{c}">{r["paths"]}</text>')
    return s

parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{2 * W}" height="{H + 40}" font-family="sans-serif">',
         f'<rect width="100%" height="100%" fill="white"/>',
         f'<text x="{W}" y="18" font-size="14" text-anchor="middle">{title}</text>']
parts += panel(0, "seconds_mean", "seconds per image")
parts += panel(W, "svg_bytes_mean", "SVG bytes per image")
lx = 60
for m, c in colours.items():
    if any(r["method"] == m for r in rows):
        parts.append(f'<circle cx="{lx}" cy="{H + 20}" r="4" fill="{c}"/><text x="{lx + 8}" y="{H + 24}" font-size="11">{m}</text>')
        lx += 140
parts.append('<text x="10" y="%d" font-size="9" fill="#555">labels: path budget (vtracer default/polygon: mean path count)</text>' % (H + 36))
parts.append("</svg>")
open(out, "w").write("\n".join(parts))
