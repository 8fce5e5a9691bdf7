"""Trains the IconClip scorer (docs/EMBEDDED.md) contrastively against frozen MiniLM sentence
embeddings, and evaluates retrieval on the held-out split.

    nice -n 15 python scripts/embedded/train_scorer.py --train data/icons/train --eval data/icons/eval \
        --out data/scorer --export models/vf-icon/scorer --epochs 4

Symmetric InfoNCE; images that share a caption in a batch (the same emoji from several sets) are
all positives (soft targets). Light augmentation: horizontal flip and a random shift/scale
(pad with white, crop/resize back); colours are never changed (they are part of the caption).
`--hard F`: a fraction F of each batch is the nearest other captions (by MiniLM similarity) of
the rest, so the scorer learns "red heart" from "orange heart", not only from "taxi". `--bf16`:
autocast on CPUs with AVX-512 BF16. `--minutes` bounds the wall time (the cosine schedule runs
over --epochs). `--ema D` keeps a moving average of the weights beside them, evaluated at each
--eval-every (OUT/eval_ema.csv) and exported to EXPORT_ema. `--channels` widens the image tower
(config.json carries the widths), `--half` exports f16 weights, `--eval-seeds N` repeats the final
R-Precision over N draws of the distractors. Writes OUT/metrics.json,
OUT/loss.csv, a restartable OUT/ckpt.pt, and EXPORT/{config.json, model.safetensors}.
"""

import argparse
import csv
import json
import os
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402


def load(path):
    raw = np.fromfile(os.path.join(path, "images_64.u8"), dtype=np.uint8).reshape(-1, 64, 64, 3)
    idx = np.load(os.path.join(path, "text_index.npy")).astype(np.int64)
    caps = json.load(open(os.path.join(path, "text_captions.json")))
    sent = np.fromfile(os.path.join(path, "text_sentence.f16"), dtype=np.float16).reshape(len(caps), 384)
    meta = [json.loads(l) for l in open(os.path.join(path, "captions.jsonl"))]
    return torch.from_numpy(raw), torch.from_numpy(idx), torch.from_numpy(sent.astype(np.float32)), caps, meta


def to01(u8):
    return u8.permute(0, 3, 1, 2).float() / 255.0


def outline(x, gen, p):
    """For a fraction `p` of the batch, dark outlines along colour edges and the shape's border
    (1-2 px, near-black): some artists (openmoji) draw them, the training sets mostly do not."""
    b = x.shape[0]
    pick = torch.rand(b, generator=gen) < p
    if not pick.any():
        return x
    sx = torch.tensor([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]])
    k = torch.stack([sx, sx.t()])[:, None].repeat(3, 1, 1, 1)  # [6, 1, 3, 3]: x and y per channel
    g = F.conv2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), k, groups=3).abs().amax(1, keepdim=True)
    edge = (g > 0.6).float()
    wide = torch.rand(b, generator=gen) < 0.3
    edge = torch.where(wide[:, None, None, None], F.max_pool2d(edge, 3, 1, 1), edge)
    ink = 0.1 * torch.rand(b, 1, 1, 1, generator=gen)
    out = x * (1 - edge) + ink * edge
    return torch.where(pick[:, None, None, None], out, x)


def augment(x, gen, strong=False, outline_p=0.0):
    b = x.shape[0]
    flip = torch.rand(b, generator=gen) < 0.5
    x = torch.where(flip[:, None, None, None], x.flip(-1), x)
    # random scale and shift (up to 4 px), white fill; `strong` widens the scale range and adds a
    # small rotation and, for a third of the batch, a blur (renders of traced SVGs are softer)
    lo, span = (0.7, 0.4) if strong else (0.8, 0.25)
    s = lo + span * torch.rand(b, generator=gen)
    sh = (torch.rand(b, 2, generator=gen) * 2 - 1) * (4 / 32)
    a = (torch.rand(b, generator=gen) * 2 - 1) * (0.17 if strong else 0.0)
    theta = torch.zeros(b, 2, 3)
    theta[:, 0, 0] = torch.cos(a) / s
    theta[:, 0, 1] = -torch.sin(a) / s
    theta[:, 1, 0] = torch.sin(a) / s
    theta[:, 1, 1] = torch.cos(a) / s
    theta[:, :, 2] = sh
    grid = F.affine_grid(theta, x.shape, align_corners=False)
    x = 1 - F.grid_sample(1 - x, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    if strong:
        blur = torch.rand(b, generator=gen) < 0.33
        k = torch.tensor([1.0, 2.0, 1.0])
        k = (k[:, None] * k[None, :] / 16).expand(3, 1, 3, 3)
        soft = F.conv2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), k, groups=3)
        x = torch.where(blur[:, None, None, None], soft, x)
    if outline_p > 0:
        x = outline(x, gen, outline_p)
    return x


@torch.no_grad()
def evaluate(model, raw, idx, sent, caps, meta, seed=0, distractors=99):
    """Image->text retrieval over the split's unique captions (excluding "")."""
    model.eval()
    keep = idx != 0  # images with an empty caption cannot be retrieved
    raw, idx, meta = raw[keep], idx[keep], [m for m, k in zip(meta, keep.tolist()) if k]
    img = torch.cat([model.encode_image(to01(raw[i : i + 512])) for i in range(0, len(raw), 512)])
    used = sorted(set(idx.tolist()) - {0})
    pos = {c: j for j, c in enumerate(used)}
    txt = model.encode_text(sent[used])
    sim = img @ txt.t()
    target = torch.tensor([pos[int(c)] for c in idx])
    rank = (sim > sim.gather(1, target[:, None])).sum(1)
    r1 = (rank == 0).float().mean().item()
    r5 = (rank < 5).float().mean().item()
    # R-Precision style: true caption vs `distractors` random other captions
    g = torch.Generator().manual_seed(seed)
    hits = []
    for i in range(len(img)):
        d = torch.randint(0, len(used) - 1, (distractors,), generator=g)
        d = d + (d >= target[i]).long()
        hits.append(bool(sim[i, target[i]] > sim[i, d].max()))
    rp = float(np.mean(hits))
    per_set = {}
    sets = np.array([m["set"] for m in meta])
    for s in sorted(set(sets)):
        m = torch.from_numpy(sets == s)
        per_set[s] = {"n": int(m.sum()), "r1": (rank[m] == 0).float().mean().item()}
    base = torch.tensor(["skin tone" not in caps[c] and not caps[c].endswith((" light", " dark", " medium", " medium light", " medium dark")) for c in idx.tolist()])
    model.train()
    return {"n_images": len(img), "n_captions": len(used), "r1": r1, "r5": r5, "chance_r1": 1 / len(used),
            f"r_precision_1_of_{distractors + 1}": rp, "chance_r_precision": 1 / (distractors + 1),
            "r1_without_skin_tone_variants": (rank[base] == 0).float().mean().item(), "n_without_skin_tone_variants": int(base.sum()),
            "per_set": per_set}


def export(model, out_dir, half=False):
    """EXPORT/{model.safetensors, config.json}; `half` stores f16 (half the file; the Rust loader
    and `--init` upcast to f32)."""
    from safetensors.torch import save_file

    os.makedirs(out_dir, exist_ok=True)
    dt = torch.float16 if half else torch.float32
    sd = {k: v.detach().to(dt).contiguous() for k, v in model.state_dict().items()}
    save_file(sd, os.path.join(out_dir, "model.safetensors"))
    with open(os.path.join(out_dir, "config.json"), "w") as f:
        json.dump(model.config, f, indent=2)
        f.write("\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--train", default="data/icons/train")
    ap.add_argument("--eval", default="data/icons/eval")
    ap.add_argument("--out", default="data/scorer")
    ap.add_argument("--export", default="models/vf-icon/scorer")
    ap.add_argument("--epochs", type=float, default=4)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--seed", type=int, default=4321)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--eval-only", action="store_true")
    ap.add_argument("--hard", type=float, default=0.0, help="fraction of each batch drawn as hard negatives")
    ap.add_argument("--bf16", action="store_true")
    ap.add_argument("--minutes", type=float, default=1e9)
    ap.add_argument("--distractors", type=int, default=63, help="R-Precision: the true caption among this many + 1")
    ap.add_argument("--strong-aug", action="store_true", help="wider scale, rotation, blur")
    ap.add_argument("--eval-every", type=int, default=0, help="log held-out R-Precision every N steps (OUT/eval.csv)")
    ap.add_argument("--init", default=None,
                    help="start from this exported scorer (DIR/model.safetensors) when OUT has no checkpoint: "
                         "a new schedule (warm-up and cosine over --epochs) continues trained weights")
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--outline", type=float, default=0.0,
                    help="fraction of each batch given dark outlines along its colour edges (augmentation)")
    ap.add_argument("--channels", default="32,64,128,256",
                    help="the image tower's widths, stem then one per block (config.json 'channels'; the Rust loader reads them)")
    ap.add_argument("--ema", type=float, default=0.0,
                    help="also keep an exponential moving average of the weights (decay per step, 0: off); "
                         "evaluated beside the raw weights (OUT/eval_ema.csv) and exported to EXPORT_ema")
    ap.add_argument("--eval-seeds", type=int, default=1,
                    help="the final R-Precision also over this many draws of the distractors (metrics.json "
                         "'r_precision_over_seeds'): the spread of the measure itself")
    ap.add_argument("--half", action="store_true", help="export f16 weights (the evaluation still runs in f32)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    os.makedirs(args.out, exist_ok=True)

    raw, idx, sent, caps, meta = load(args.train)
    ev = load(args.eval)
    torch.manual_seed(args.seed)
    model = vf_icon.IconClip(channels=tuple(int(c) for c in args.channels.split(",")))
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=0.05)
    steps_per_epoch = len(raw) // args.batch
    total = int(args.epochs * steps_per_epoch)
    gen = torch.Generator().manual_seed(args.seed)
    step, elapsed0 = 0, 0.0
    ckpt = os.path.join(args.out, "ckpt.pt")
    if os.path.exists(ckpt):
        ck = torch.load(ckpt, weights_only=False)
        model.load_state_dict(ck["model"])
        opt.load_state_dict(ck["opt"])
        gen.set_state(ck["gen"])
        step, elapsed0 = ck["step"], ck["elapsed"]
        print(f"resumed at step {step}", flush=True)
    elif args.init:
        from safetensors.torch import load_file

        model.load_state_dict(load_file(os.path.join(args.init, "model.safetensors")))
        print(f"initialised from {args.init}", flush=True)
    logf = open(os.path.join(args.out, "loss.csv"), "a", newline="")
    log = csv.writer(logf)
    if step == 0:
        log.writerow(["step", "loss", "lr", "elapsed_s"])
    t0 = time.time()
    last = t0
    print(f"train {len(raw)} images, {total} steps", flush=True)
    # hard negatives: for each caption its 8 nearest other captions (MiniLM cosine), and the images of each caption
    by_cap = [[] for _ in caps]
    for i, c in enumerate(idx.tolist()):
        by_cap[c].append(i)
    near = None
    if args.hard > 0:
        with torch.no_grad():
            sims = sent @ sent.t()
            sims.fill_diagonal_(-2)
            sims[:, 0] = -2
            near = sims.topk(8, dim=1).indices
    amp = torch.autocast("cpu", dtype=torch.bfloat16, enabled=args.bf16)
    ema = None
    if args.ema > 0:
        import copy

        ema = copy.deepcopy(model)
        if os.path.exists(ckpt) and "ema" in ck:
            ema.load_state_dict(ck["ema"])
        for p in ema.parameters():
            p.requires_grad_(False)
    rp_key = f"r_precision_1_of_{args.distractors + 1}"

    def log_eval(net, name, label):
        """Held-out R-Precision of `net` at this step, appended to OUT/`name`."""
        m = evaluate(net, *ev, distractors=args.distractors)
        path = os.path.join(args.out, name)
        new_file = not os.path.exists(path)
        with open(path, "a", newline="") as f:
            w = csv.writer(f)
            if new_file:
                w.writerow(["step", "r1", "r5", rp_key, "elapsed_s"])
            w.writerow([step, f"{m['r1']:.4f}", f"{m['r5']:.4f}", f"{m[rp_key]:.4f}", f"{elapsed0 + time.time() - t0:.1f}"])
        print(f"eval step {step}{label}: R-Precision {m[rp_key]:.3f}", flush=True)

    while step < total and not args.eval_only and time.time() - t0 < args.minutes * 60:
        nh = int(args.hard * args.batch) if near is not None else 0
        b = torch.randint(0, len(raw), (args.batch - nh,), generator=gen)
        if nh:
            src = idx[b[:nh]]
            pick = near[src, torch.randint(0, 8, (nh,), generator=gen)]
            extra = [by_cap[int(c)][int(torch.randint(0, len(by_cap[int(c)]), (1,), generator=gen))]
                     if by_cap[int(c)] else int(b[0]) for c in pick]
            b = torch.cat([b, torch.tensor(extra)])
        x = augment(to01(raw[b]), gen, args.strong_aug, args.outline)
        ci = idx[b]
        with amp:
            img = model.encode_image(x).float()
        txt = model.encode_text(sent[ci])
        logits = model.logits(img, txt)
        same = (ci[:, None] == ci[None, :]).float()
        tgt = same / same.sum(1, keepdim=True)
        loss = 0.5 * (-(tgt * F.log_softmax(logits, 1)).sum(1).mean() - (tgt * F.log_softmax(logits.t(), 1)).sum(1).mean())
        lr = args.lr * min(1.0, (step + 1) / args.warmup) * 0.5 * (1 + np.cos(np.pi * step / total))
        for g in opt.param_groups:
            g["lr"] = lr
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        with torch.no_grad():
            model.logit_scale.clamp_(0, 4.6052)
            if ema is not None:
                for pe, pm in zip(ema.parameters(), model.parameters()):
                    pe.lerp_(pm, 1 - args.ema)
        step += 1
        if step % 10 == 0:
            log.writerow([step, f"{loss.item():.4f}", f"{lr:.2e}", f"{elapsed0 + time.time() - t0:.1f}"])
            logf.flush()
            print(f"step {step}/{total} loss {loss.item():.3f}", flush=True)
        if args.eval_every and step % args.eval_every == 0:
            log_eval(model, "eval.csv", "")
            if ema is not None:
                log_eval(ema, "eval_ema.csv", " (EMA)")
        if time.time() - last > 600 or step == total:
            state = {"model": model.state_dict(), "opt": opt.state_dict(), "gen": gen.get_state(), "step": step,
                     "elapsed": elapsed0 + time.time() - t0}
            if ema is not None:
                state["ema"] = ema.state_dict()
                export(ema, args.export + "_ema", args.half)
            torch.save(state, ckpt)
            export(model, args.export, args.half)
            last = time.time()
    m = evaluate(model, *ev, distractors=args.distractors)
    if args.eval_seeds > 1:
        rs = [evaluate(model, *ev, seed=s, distractors=args.distractors)[rp_key] for s in range(args.eval_seeds)]
        m["r_precision_over_seeds"] = {"seeds": list(range(args.eval_seeds)), "values": rs, "mean": float(np.mean(rs))}
        print(f"R-Precision over {len(rs)} distractor draws: {' '.join(f'{r:.4f}' for r in rs)}, mean {np.mean(rs):.4f}",
              flush=True)
    m["train_steps"] = step
    m["train_wall_s"] = elapsed0 + time.time() - t0
    m["args"] = vars(args)
    if ema is not None:
        m["ema"] = evaluate(ema, *ev, distractors=args.distractors)
        export(ema, args.export + "_ema", args.half)
    json.dump(m, open(os.path.join(args.out, "metrics.json"), "w"), indent=1)
    export(model, args.export, args.half)
    print(json.dumps({k: v for k, v in m.items() if k != "per_set"}), flush=True)


if __name__ == "__main__":
    main()
