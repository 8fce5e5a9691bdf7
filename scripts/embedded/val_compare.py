"""The validation protocol's table (docs/embedded/TRAINING.md, "Validation"): for each swept
value under SWEEP/out (val_sweep.sh), pixel R-Precision and mean rank over both judges (noto,
twemoji) and all seeds, and the difference from a baseline value, paired per caption (each
caption's judgements averaged, then the mean and standard error over the captions).

    python scripts/embedded/val_compare.py --sweep /tmp/sweep --baseline retrieval:sdedit_strength0.3 \
        retrieval:sdedit_strength0.2 retrieval:sdedit_strength0.4 [--json out.json]
"""

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import pixel_rprecision as pr  # noqa: E402

JUDGES = ("noto", "twemoji")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", nargs="+", help="MODE:TAG, e.g. noise:sample_guidance3")
    ap.add_argument("--baseline", required=True, help="MODE:TAG the others are compared with")
    ap.add_argument("--sweep", default="/tmp/sweep")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--method", default="samples")
    ap.add_argument("--captions", default="docs/embedded/val_captions.txt")
    ap.add_argument("--train", default="data/icons/train")
    ap.add_argument("--json")
    args = ap.parse_args()
    caps = [l.strip() for l in open(args.captions) if l.strip()]
    raw, tcaps = pr.load_split(args.train)
    refs = {}
    for j in JUDGES:
        by = pr.first_by_caption(raw, tcaps, j)
        refs[j] = np.stack([pr.small(by[c]) for c in caps])
    seeds = [int(s) for s in args.seeds.split(",")]
    vf = os.environ.get("VF", "target/release/vectorfusion")

    def judged(run):
        """[judgements, captions] hits and ranks of one MODE:TAG."""
        mode, tag = run.split(":", 1)
        hits, rank_rows = [], []
        for s in seeds:
            pictures = {}  # from noise both judges read one folder
            for j in JUDGES:
                folder = "valnoto" if mode == "noise" or j == "noto" else f"val{j}"
                if folder not in pictures:
                    d = os.path.join(args.sweep, "out", f"{folder}-{mode}-{tag}-s{s}", args.method)
                    pictures[folder] = pr.load_pictures(d, len(caps), vf)
                rank = pr.ranks(pictures[folder], refs[j])
                hits.append(rank == 0)
                rank_rows.append(rank)
        return np.array(hits, float), np.array(rank_rows, float)

    judgements = {run: judged(run) for run in dict.fromkeys([args.baseline] + args.runs)}
    base_h, base_r = judgements[args.baseline]
    rows = []
    for run, (h, r) in judgements.items():
        dh, dr = (h - base_h).mean(0), (r - base_r).mean(0)  # per caption
        se = lambda x: float(x.std(ddof=1) / np.sqrt(len(x)))
        row = {"run": run, "pixel_r_precision": float(h.mean()), "mean_rank": float(r.mean()),
               "per_judge": {j: float(h[k::len(JUDGES)].mean()) for k, j in enumerate(JUDGES)},
               "minus_baseline": {"pixel_r_precision": float(dh.mean()), "se": se(dh),
                                  "mean_rank": float(dr.mean()), "mean_rank_se": se(dr)}}
        rows.append(row)
        m = row["minus_baseline"]
        print(f"{run:45} R-Prec {100 * row['pixel_r_precision']:5.1f} % (noto {100 * row['per_judge']['noto']:.1f}, "
              f"twemoji {100 * row['per_judge']['twemoji']:.1f})  rank {row['mean_rank']:.2f}  vs baseline "
              f"{100 * m['pixel_r_precision']:+.1f} ± {100 * m['se']:.1f} pts, rank {m['mean_rank']:+.2f} ± {m['mean_rank_se']:.2f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"captions": args.captions, "seeds": seeds, "judges": JUDGES, "baseline": args.baseline,
                       "method": args.method, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
