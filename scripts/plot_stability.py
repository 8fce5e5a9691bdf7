#!/usr/bin/env python3
"""Speed versus accuracy chart from `vectorfusion bench stability --json` reports (no dependencies).

Usage: scripts/plot_stability.py OUT.svg REPORT.json [REPORT.json ...]
One report per preset (or per setting). Three panels (iconography, pixel art, sketch): median PSNR
against the nearest analytic-teacher target (whisker: min..max over seeds) versus median seconds per
run (log x). Colour: method; label: the report's preset (and SDS steps / size). Failed runs are
counted in the label when any.
"""
import json, math, sys

out, files = sys.argv[1], sys.argv[2:]
reports = [json.load(open(f)) for f in files]
colours = {"scratch": "#1f77b4", "sd_live": "#ff7f0e", "sd_live_sds": "#d62728"}
styles = ["iconography", "pixel_art", "sketch"]
rows = []
for r in reports:
    for c in r["cells"]:
        if c["psnr_median"] is None:
            continue
        rows.append({"method": c["method"], "style": c["style"], "label": f'{r["preset"]} {r["size"]}px/{r["steps"]}',
                     "s": max(c["seconds_median"], 1e-3), "p": c["psnr_median"], "lo": c["psnr_min"],
                     "hi": c["psnr_max"], "failed": c["failed"], "runs": c["runs"]})
W, H, M = 360, 320, 50
allx = [r["s"] for r in rows]
lx0, lx1 = math.floor(math.log10(min(allx))), math.ceil(math.log10(max(allx)))
lx1 = max(lx1, lx0 + 1)
ys = [r["lo"] for r in rows] + [r["hi"] for r in rows]
y0, y1 = 0, min(100, 10 * math.ceil(max(ys) / 10))


def panel(ox, style):
    px = lambda v: ox + M + (math.log10(v) - lx0) / (lx1 - lx0) * (W - M - 15)
    py = lambda v: 30 + (y1 - v) / (y1 - y0) * (H - 30 - M)
    s = [f'<rect x="{ox + M}" y="30" width="{W - M - 15}" height="{H - 30 - M}" fill="none" stroke="#888"/>',
         f'<text x="{ox + (W + M) / 2:.0f}" y="24" font-size="13" text-anchor="middle">{style}</text>']
    for e in range(lx0, lx1 + 1):
        x = px(10 ** e)
        s.append(f'<line x1="{x:.1f}" y1="30" x2="{x:.1f}" y2="{H - M}" stroke="#eee"/>')
        s.append(f'<text x="{x:.1f}" y="{H - M + 15}" font-size="11" text-anchor="middle">{10 ** e:g}</text>')
    for v in range(int(y0), int(y1) + 1, 10):
        y = py(v)
        s.append(f'<line x1="{ox + M}" y1="{y:.1f}" x2="{ox + W - 15}" y2="{y:.1f}" stroke="#eee"/>')
        s.append(f'<text x="{ox + M - 5}" y="{y + 4:.1f}" font-size="11" text-anchor="end">{v}</text>')
    s.append(f'<text x="{ox + (W + M) / 2:.0f}" y="{H - M + 32}" font-size="12" text-anchor="middle">seconds per run (log)</text>')
    s.append(f'<text x="{ox + 14}" y="{(H - M) / 2 + 15:.0f}" font-size="12" transform="rotate(-90 {ox + 14} {(H - M) / 2 + 15:.0f})" text-anchor="middle">PSNR dB (median, min..max)</text>')
    mine = [r for r in rows if r["style"] == style]
    for m, c in colours.items():
        pts = sorted([r for r in mine if r["method"] == m], key=lambda r: r["s"])
        if len(pts) > 1:
            d = " ".join(f"{px(r['s']):.1f},{py(r['p']):.1f}" for r in pts)
            s.append(f'<polyline points="{d}" fill="none" stroke="{c}" stroke-width="1"/>')
    for r in mine:
        c = colours.get(r["method"], "#333")
        x = px(r["s"])
        s.append(f'<line x1="{x:.1f}" y1="{py(r["lo"]):.1f}" x2="{x:.1f}" y2="{py(r["hi"]):.1f}" stroke="{c}" stroke-width="1"/>')
        s.append(f'<circle cx="{x:.1f}" cy="{py(r["p"]):.1f}" r="4" fill="{c}"/>')
        fail = f' ✗{r["failed"]}/{r["runs"]}' if r["failed"] else ""
        s.append(f'<text x="{x + 6:.1f}" y="{py(r["p"]) - 5:.1f}" font-size="8" fill="{c}">{r["label"]}{fail}</text>')
    return s


parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{3 * W}" height="{H + 30}" font-family="sans-serif">',
         '<rect width="100%" height="100%" fill="white"/>']
for i, st in enumerate(styles):
    parts += panel(i * W, st)
lx = 60
for m, c in colours.items():
    parts.append(f'<circle cx="{lx}" cy="{H + 12}" r="4" fill="{c}"/><text x="{lx + 8}" y="{H + 16}" font-size="11">{m}</text>')
    lx += 130
parts.append(f'<text x="{lx}" y="{H + 16}" font-size="10" fill="#555">analytic TEST teacher; label: preset size/SDS steps; ✗ failed runs</text>')
parts.append("</svg>")
open(out, "w").write("\n".join(parts))
