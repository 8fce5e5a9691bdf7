#!/usr/bin/env python3
"""Rate-distortion plots of `vectorfusion bench vectorize --rd --json FILE`.

    python scripts/plot_rd.py RD.json [--out-dir docs/img] [--prefix rd]

Writes PREFIX_raw.png (PSNR against raw SVG KB) and PREFIX_gzip.png (against gzip KB), one
panel per image set, one colour per tool: every setting's mean as a faint dot, the tool's
upper envelope (the R-D summary of the JSON) as a line. Needs matplotlib (e.g. in a venv:
python3 -m venv /tmp/vf-rd-venv && /tmp/vf-rd-venv/bin/pip install matplotlib).
"""
import argparse
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

COLORS = {"live": "#d62728", "vtracer": "#1f77b4", "imagetracer": "#2ca02c", "potrace": "#7f7f7f"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("json")
    ap.add_argument("--out-dir", default="docs/img")
    ap.add_argument("--prefix", default="rd")
    args = ap.parse_args()
    with open(args.json) as f:
        data = json.load(f)
    sets = [s["set"] for s in data["sets"]]
    if not sets:
        sys.exit("no image sets in " + args.json)
    os.makedirs(args.out_dir, exist_ok=True)
    for basis, key in (("raw", "svg_bytes"), ("gzip", "svg_gz_bytes")):
        cols = min(len(sets), 2)
        rows = math.ceil(len(sets) / cols)
        fig, axes = plt.subplots(rows, cols, figsize=(6 * cols, 4.2 * rows), squeeze=False)
        for ax, set_name in zip(axes.flat, sets):
            n = next(s["images"] for s in data["sets"] if s["set"] == set_name)
            means = [m for m in data["means"] if m["set"] == set_name]
            summary = next(
                (r for r in data["rd"] if r["set"] == set_name and r["basis"] == basis), None
            )
            tools = []
            for m in means:
                if m["tool"] not in tools:
                    tools.append(m["tool"])
            for tool in tools:
                c = COLORS.get(tool, None)
                pts = [(m[key] / 1000, m["psnr"]) for m in means if m["tool"] == tool]
                ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=10, alpha=0.35, color=c)
                env = next((e["points"] for e in summary["envelopes"] if e["tool"] == tool), [])
                if env:
                    ax.plot([p[0] for p in env], [p[1] for p in env], "-o", ms=3, color=c,
                            label=tool, lw=2 if tool == "live" else 1.3)
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
            ax.xaxis.set_minor_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
            ax.tick_params(axis="x", which="minor", labelsize=7)
            ax.set_title(f"{set_name} ({n} images)")
            ax.set_xlabel(f"mean SVG size, KB ({basis})")
            ax.set_ylabel("mean PSNR over white, dB")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
        for ax in list(axes.flat)[len(sets):]:
            ax.axis("off")
        fig.suptitle(f"Rate-distortion: PSNR vs {basis} SVG size (dots: settings; lines: envelopes)")
        fig.tight_layout()
        out = os.path.join(args.out_dir, f"{args.prefix}_{basis}.png")
        fig.savefig(out, dpi=110)
        plt.close(fig)
        print("wrote", out)


if __name__ == "__main__":
    main()
