"""Memorisation check: for each generated sample, the nearest training image and its distance.

Distances are RMS colour differences at 32x32 over white (0 = identical, 1 = black vs white). As a
yardstick, the same distance between held-out icons (another artist's drawing of a training
caption) and their nearest training image.

    python scripts/embedded/memorisation.py --dir eval-out/fluent/samples --json docs/embedded/memorisation.json
"""

import argparse
import glob
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from pixel_rprecision import load_split, over_white, read_picture, small  # noqa: E402


def nearest(q, train):
    """Index and RMS distance of each row of q's nearest row of train (|a-b|^2 = |a|^2 + |b|^2 - 2ab,
    a block of queries at a time, so memory stays at block x len(train))."""
    t2 = (train.astype(np.float64) ** 2).sum(1)
    js, ds = [], []
    for i in range(0, len(q), 64):
        b = q[i : i + 64].astype(np.float64)
        d = (b**2).sum(1)[:, None] + t2[None, :] - 2 * b @ train.T.astype(np.float64)
        j = d.argmin(1)
        js.append(j)
        ds.append(np.sqrt(np.maximum(d[np.arange(len(b)), j], 0) / q.shape[1]))
    return np.concatenate(js), np.concatenate(ds)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dir", action="append", required=True, help="folder of NNNN.png / NNNN.svg (repeatable)")
    ap.add_argument("--train", default="data/icons/train")
    ap.add_argument("--eval", default="data/icons/eval")
    ap.add_argument("--vf", default="target/release/vectorfusion")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    traw, tcaps = load_split(args.train)
    train = np.stack([small(x) for x in traw]).astype(np.float32)
    eraw, _ = load_split(args.eval)
    rng = np.random.default_rng(0)
    ref = np.stack([small(x) for x in eraw[rng.choice(len(eraw), 256, replace=False)]]).astype(np.float32)
    _, ref_d = nearest(ref, train)
    res = {"train_images": len(train), "held_out_art_to_nearest_train": {
        "median": float(np.median(ref_d)), "p10": float(np.percentile(ref_d, 10))}, "dirs": {}}
    for d in args.dir:
        files = sorted(glob.glob(os.path.join(d, "*.png")) + glob.glob(os.path.join(d, "*.svg")))
        q = np.stack([small(over_white(read_picture(f, args.vf))) for f in files]).astype(np.float32)
        j, dist = nearest(q, train)
        res["dirs"][d] = {
            "n": len(files), "median": float(np.median(dist)), "p10": float(np.percentile(dist, 10)),
            "min": float(dist.min()), "below_0.05": int((dist < 0.05).sum()),
            "closest": [{"file": os.path.basename(files[i]), "distance": float(dist[i]),
                         "train": f"{tcaps[j[i]]['set']}:{tcaps[j[i]]['name']}"} for i in np.argsort(dist)[:5]],
        }
    print(json.dumps(res, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
