"""Pixel R-Precision against held-out art (docs/embedded/TRAINING.md, "Evaluation").

For each held-out caption, the picture made for it (a PNG, or an SVG rendered with
`vectorfusion render`) is compared with the held-out set's icon of every caption in the list
(32x32, area-downsampled RGB over white, L2); it scores when its own caption's icon is the nearest.
Chance is 1/N. The same measure on another artist's drawing of the same emoji (the training sets'
own icons) gives the ceiling a perfect emoji drawer would reach.

    # choose the caption lists once (captions that name training icons, drawn by held-out artists)
    python scripts/embedded/pixel_rprecision.py choose --n 48 --seed 0
    # score a directory of NNNN.svg / NNNN.png (line N of the caption file)
    python scripts/embedded/pixel_rprecision.py score --captions docs/embedded/heldout_fluent48.txt \
        --set fluent-emoji-flat --dir eval-out/fluent/sd_live_sds [--vf target/release/vectorfusion]
    # the other-artist ceiling (training icons of the same captions, from SET)
    python scripts/embedded/pixel_rprecision.py ceiling --captions docs/embedded/heldout_fluent48.txt \
        --set fluent-emoji-flat --other twemoji

The held-out sets judge; they never choose. Settings are chosen on the validation protocol
(docs/embedded/TRAINING.md, "Validation"): captions of the prior's validation split (never trained
on), judged by a training set's drawings (`--set noto` or `--set twemoji`: references come from
the training split when SET is not a held-out set) while retrieval leaves that set out
(`VF_RETRIEVAL_EXCLUDE_SETS`):

    python scripts/embedded/pixel_rprecision.py choose-val     # docs/embedded/val_captions.txt
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np


def load_split(path):
    raw = np.fromfile(os.path.join(path, "images_64.u8"), dtype=np.uint8).reshape(-1, 64, 64, 3)
    caps = [json.loads(l) for l in open(os.path.join(path, "captions.jsonl"))]
    return raw, caps


def small(img):
    """[64, 64, 3] (or any multiple of 32) uint8/float -> [32*32*3] float in [0, 1], area-downsampled."""
    a = np.asarray(img, dtype=np.float64)
    if a.max() > 1.5:
        a = a / 255.0
    k = a.shape[0] // 32
    return a[: 32 * k, : 32 * k, :3].reshape(32, k, 32, k, 3).mean(axis=(1, 3)).reshape(-1)


def first_by_caption(raw, caps, set_name):
    out = {}
    for img, c in zip(raw, caps):
        if c["set"] == set_name and c["caption"] not in out:
            out[c["caption"]] = img
    return out


def ranks(pictures, refs):
    """pictures, refs: [N, D]; for each i, how many refs are nearer (L2) to picture i than ref i."""
    d = ((pictures[:, None, :] - refs[None, :, :]) ** 2).sum(-1)
    return (d < np.diag(d)[:, None]).sum(1)


def rprecision(pictures, refs):
    """pictures, refs: [N, D]; fraction of i whose nearest ref (L2) is ref i, and the mean rank."""
    rank = ranks(pictures, refs)
    return float((rank == 0).mean()), float(rank.mean())


def load_pictures(folder, n, vf):
    """NNNN.svg (rendered by `vf`) or NNNN.png for N = 1..n in `folder`, as [n, D] over white."""
    pics = []
    for i in range(1, n + 1):
        base = os.path.join(folder, f"{i:04}")
        path = base + ".svg" if os.path.exists(base + ".svg") else base + ".png"
        pics.append(small(over_white(read_picture(path, vf))))
    return np.stack(pics)


def read_picture(path, vf):
    from PIL import Image

    if path.endswith(".svg"):
        with tempfile.TemporaryDirectory() as td:
            png = os.path.join(td, "r.png")
            subprocess.run([vf, "render", path, "-o", png, "--size", "64"], check=True, capture_output=True)
            return np.asarray(Image.open(png).convert("RGBA"), dtype=np.float64) / 255.0
    return np.asarray(Image.open(path).convert("RGBA").resize((64, 64), Image.BOX), dtype=np.float64) / 255.0


def over_white(rgba):
    a = rgba[..., 3:4]
    return rgba[..., :3] * a + (1 - a)


def main():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("choose")
    c.add_argument("--n", type=int, default=48)
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--train", default="data/icons/train")
    c.add_argument("--eval", default="data/icons/eval")
    c.add_argument("--out-dir", default="docs/embedded")
    c.add_argument("--suffix", default="", help="a further set: heldout_fluent48SUFFIX.txt, disjoint from the "
                   "captions already in OUT_DIR's heldout_*48.txt")
    v = sub.add_parser("choose-val")
    v.add_argument("--train", default="data/icons/train")
    v.add_argument("--judges", default="noto,twemoji")
    v.add_argument("--seed", type=int, default=1234, help="train_prior.py's --seed (its validation split)")
    v.add_argument("--out", default="docs/embedded/val_captions.txt")
    for name in ("score", "ceiling"):
        s = sub.add_parser(name)
        s.add_argument("--captions", required=True)
        s.add_argument("--set", required=True, help="held-out set the references come from")
        s.add_argument("--eval", default="data/icons/eval")
        s.add_argument("--train", default="data/icons/train")
        s.add_argument("--json", default=None)
    sub.choices["score"].add_argument("--dir", required=True)
    sub.choices["score"].add_argument("--vf", default="target/release/vectorfusion")
    sub.choices["ceiling"].add_argument("--other", required=True, help="training set drawn by another artist")
    args = ap.parse_args()

    if args.cmd == "choose":
        _, tcaps = load_split(args.train)
        raw, ecaps = load_split(args.eval)
        train_names = {c["caption"] for c in tcaps}
        rng = np.random.default_rng(args.seed)
        for set_name, stem in (("fluent-emoji-flat", "heldout_fluent48"), ("openmoji", "heldout_openmoji48")):
            fname = f"{stem}{args.suffix}.txt"
            taken = set()
            if args.suffix:
                taken = {l.strip() for l in open(os.path.join(args.out_dir, f"{stem}.txt")) if l.strip()}
            pool = sorted(c for c in first_by_caption(raw, ecaps, set_name)
                          if c in train_names and len(c.split()) <= 4 and c not in taken)
            pick = sorted(rng.choice(pool, size=args.n, replace=False).tolist())
            with open(os.path.join(args.out_dir, fname), "w") as f:
                f.write("\n".join(pick) + "\n")
            print(f"{set_name}: {len(pool)} candidate captions, wrote {args.n} to {fname}")
        return

    if args.cmd == "choose-val":
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        import vf_icon

        _, tcaps = load_split(args.train)
        index = np.load(os.path.join(args.train, "text_index.npy")).astype(np.int64)
        n_text = len(json.load(open(os.path.join(args.train, "text_captions.json"))))
        val = vf_icon.val_caption_ids(n_text, args.seed)
        judges = args.judges.split(",")
        sets_of = {}
        for c, i in zip(tcaps, index):
            if int(i) in val:
                sets_of.setdefault(c["caption"], set()).add(c["set"])
        # drawn by every judge, in at most four words as the held-out lists
        pick = sorted(c for c, s in sets_of.items() if all(j in s for j in judges) and len(c.split()) <= 4)
        with open(args.out, "w") as f:
            f.write("\n".join(pick) + "\n")
        print(f"{len(sets_of)} validation captions, {len(pick)} drawn by {judges}: {args.out}")
        return

    captions = [l.strip() for l in open(args.captions) if l.strip()]
    raw, ecaps = load_split(args.eval)
    if not any(c["set"] == args.set for c in ecaps):
        # a training set judges the validation captions (never trained on)
        raw, ecaps = load_split(args.train)
    refs_by = first_by_caption(raw, ecaps, args.set)
    missing = [c for c in captions if c not in refs_by]
    if missing:
        sys.exit(f"no {args.set} icon for: {missing}")
    refs = np.stack([small(refs_by[c]) for c in captions])
    if args.cmd == "ceiling":
        traw, tcaps = load_split(args.train)
        other = first_by_caption(traw, tcaps, args.other)
        keep = [i for i, c in enumerate(captions) if c in other]
        pics = np.stack([small(other[captions[i]]) for i in keep])
        r1, mr = rprecision(pics, refs[keep])
        res = {"set": args.set, "other": args.other, "n": len(keep), "pixel_r_precision": r1, "mean_rank": mr}
    else:
        r1, mr = rprecision(load_pictures(args.dir, len(captions), args.vf), refs)
        res = {"set": args.set, "dir": args.dir, "n": len(captions), "pixel_r_precision": r1, "mean_rank": mr,
               "chance": 1 / len(captions)}
    print(json.dumps(res))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
