"""Samples the exported prior (torch DDIM, classifier-free guidance) for a fixed caption list and
writes a labelled grid PNG, plus the loss-curve plot.

    python scripts/embedded/sample_grid.py --model models/vf-icon --out docs/embedded/samples.png \
        --loss data/prior/loss.csv --loss-out docs/embedded/loss.png
"""

import argparse
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402

CAPTIONS = [
    # seen in training (names of the training sets)
    "red heart", "crown", "grinning face", "pizza", "rocket", "sun", "cat face", "christmas tree",
    "green apple", "fire", "ghost", "snowman",
    # not training names (held-out style / compositions)
    "a blue heart", "a red crown", "smiling sun", "a purple cat", "yellow star", "a green car",
    "birthday cake with candles", "a coffee cup",
]


@torch.no_grad()
def sample(unet, sched, cond, uncond, steps, cfg, gen, vae=None):
    """Images in [0, 1]; a latent model (`vae`) decodes its latents at the end."""
    b = cond.shape[0]
    c = unet.config.in_channels
    x = torch.randn((b, c, unet.config.sample_size, unet.config.sample_size), generator=gen)
    sched.set_timesteps(steps)
    for t in sched.timesteps:
        eps = unet(torch.cat([x, x]), t, encoder_hidden_states=torch.cat([uncond.expand(b, -1, -1), cond])).sample
        eu, ec = eps.chunk(2)
        x = sched.step(eu + cfg * (ec - eu), t, x).prev_sample
    if vae is not None:
        x = torch.cat([vae.decode(x[i : i + 16] / vae.config.scaling_factor).sample for i in range(0, b, 16)])
    return ((x + 1) / 2).clamp(0, 1)


def load_vae(model):
    """The model's AutoencoderKL (fp32), or None for a pixel-space model."""
    path = os.path.join(model, "vae")
    if not os.path.isdir(path):
        return None
    from diffusers import AutoencoderKL

    return AutoencoderKL.from_pretrained(path).float().eval()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="models/vf-icon")
    ap.add_argument("--out", default="docs/embedded/samples.png")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--cfg", type=float, default=3.0, help="guidance (the shipped model samples at 3)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--per-caption", type=int, default=3)
    ap.add_argument("--loss", nargs="*", default=None,
                    help="loss.csv files of the training runs, one curve each (named by their folder)")
    ap.add_argument("--loss-out", default="docs/embedded/loss.png")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--clip-sample", choices=["config", "on", "off"], default="config",
                    help="override the scheduler's clip_sample (x0 clamped to [-1, 1] each step)")
    ap.add_argument("--batch", type=int, default=16, help="training batch size, for the loss plot label")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from diffusers import DDIMScheduler, UNet2DConditionModel

    unet = UNet2DConditionModel.from_pretrained(os.path.join(args.model, "unet")).float().eval()
    over = {} if args.clip_sample == "config" else {"clip_sample": args.clip_sample == "on"}
    sched = DDIMScheduler.from_pretrained(os.path.join(args.model, "scheduler"), **over)
    tok, text = vf_icon.load_text_model()
    uncond = vf_icon.encode_tokens(tok, text, [""])
    gen = torch.Generator().manual_seed(args.seed)
    n, k = len(CAPTIONS), args.per_caption
    cond = vf_icon.encode_tokens(tok, text, [c for c in CAPTIONS for _ in range(k)])
    vae = load_vae(args.model)
    imgs_all = sample(unet, sched, cond, uncond, args.steps, args.cfg, gen, vae)
    side = imgs_all.shape[-1]
    rows = imgs_all.split(k)
    cols = 2
    fig, axes = plt.subplots((n + cols - 1) // cols, cols, figsize=(cols * k * 0.9 + 1, (n // cols) * 1.05 + 0.6))
    for i, (c, imgs) in enumerate(zip(CAPTIONS, rows)):
        ax = axes.flat[i]
        strip = imgs.permute(0, 2, 3, 1).numpy()
        strip = np.concatenate([np.pad(s, ((1, 1), (1, 1), (0, 0)), constant_values=0.8) for s in strip], axis=1)
        ax.imshow(strip, interpolation="nearest")
        ax.set_title(c, fontsize=8)
        ax.axis("off")
    fig.suptitle(f"vf-icon prior, DDIM {args.steps} steps, CFG {args.cfg}, clip_sample {sched.config.clip_sample}, "
                 f"seed {args.seed} ({side}x{side})", fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print("wrote", args.out)
    if args.loss:
        import csv

        plt.figure(figsize=(6, 3.2))
        top = 0.3
        for path in args.loss:
            r = list(csv.DictReader(open(path)))
            s = [int(x["step"]) for x in r]
            # OUT/loss.csv is named by its folder, docs/embedded/prior_loss.csv by its prefix
            base = os.path.basename(path)
            name = (base[: -len("_loss.csv")] if base.endswith("_loss.csv")
                    else os.path.basename(os.path.dirname(os.path.abspath(path))) or path)
            plt.plot(s, [float(x["loss"]) for x in r], lw=0.5, alpha=0.35)
            # OUT/loss.csv -> OUT/val.csv; docs/embedded/prior_loss.csv -> prior_val.csv
            val = os.path.join(os.path.dirname(path), os.path.basename(path).replace("loss.csv", "val.csv"))
            if os.path.exists(val):
                v = list(csv.DictReader(open(val)))
                plt.plot([int(x["step"]) for x in v], [float(x["val_loss"]) for x in v], "k.-", lw=1, ms=3,
                         label=f"{name} validation (unweighted, held-out captions)")
            plt.plot(s, [float(x["ema_loss"]) for x in r], lw=1.5, label=f"{name} (EMA 0.98)")
            top = max(top, min(1.0, max(float(x["ema_loss"]) for x in r[len(r) // 10:]) * 1.3))
        plt.xlabel(f"step (batch {args.batch})")
        plt.ylabel("MSE of the training target")
        plt.ylim(0, top)
        plt.legend(fontsize=7)
        plt.title("vf-icon prior training loss")
        plt.tight_layout()
        plt.savefig(args.loss_out, dpi=110)
        print("wrote", args.loss_out)


if __name__ == "__main__":
    main()
