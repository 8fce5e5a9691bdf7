"""Trains the embedded model's small image autoencoder (diffusers `AutoencoderKL`, f = 4).

    python scripts/embedded/train_vae.py --data data/icons/train --out /work/vf-train/vae \
        --minutes 20 --bf16

64x64 RGB icons over white -> 16x16x4 latents. Loss: L1 + an edge term (L1 between Sobel
gradients, so flat icons keep sharp boundaries without a perceptual network, of which none is
available here) + a small KL. Restartable: resumes from OUT/ckpt.pt (model, EMA, optimiser, step,
RNG). Logs OUT/loss.csv and a held-out reconstruction PSNR (OUT/val.csv). At the end (and every
--export-every-min) it writes OUT/export/ (fp32 EMA weights, diffusers layout) with
`scaling_factor` = 1 / std of the latents of the training images, as Stable Diffusion's VAE.
"""

import argparse
import copy
import csv
import datetime as dt
import json
import os
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402

VAE_CONFIG = dict(
    in_channels=3,
    out_channels=3,
    down_block_types=("DownEncoderBlock2D",) * 3,
    up_block_types=("UpDecoderBlock2D",) * 3,
    block_out_channels=(32, 64, 128),
    layers_per_block=1,
    latent_channels=4,
    norm_num_groups=32,
    sample_size=64,
    mid_block_add_attention=False,
)


def sobel(x):
    k = torch.tensor([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]], dtype=x.dtype)
    kx = k.view(1, 1, 3, 3).repeat(x.shape[1], 1, 1, 1)
    ky = k.t().contiguous().view(1, 1, 3, 3).repeat(x.shape[1], 1, 1, 1)
    return torch.cat([F.conv2d(x, kx, padding=1, groups=x.shape[1]), F.conv2d(x, ky, padding=1, groups=x.shape[1])], 1)


def psnr(a, b):
    mse = ((a - b) ** 2).mean(dim=(1, 2, 3)).clamp(min=1e-10)
    return (10 * torch.log10(4.0 / mse)).mean().item()  # images in [-1, 1]: peak-to-peak 2


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data/icons/train")
    ap.add_argument("--out", default="/work/vf-train/vae")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--kl", type=float, default=1e-6)
    ap.add_argument("--edge", type=float, default=0.5)
    ap.add_argument("--ema", type=float, default=0.999)
    ap.add_argument("--seed", type=int, default=1234)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--bf16", action="store_true", help="bf16 autocast (AVX-512 BF16 / AMX CPUs)")
    ap.add_argument("--minutes", type=float, default=20.0, help="stop after this much wall time in this run")
    ap.add_argument("--max-steps", type=int, default=10**9)
    ap.add_argument("--export-every-min", type=float, default=10.0)
    ap.add_argument("--init", default=None, help="start from this exported AutoencoderKL (a fine-tune)")
    ap.add_argument("--decoder-only", action="store_true",
                    help="train the decoder only: the encoder, and so the latent space a prior was trained on, stays fixed")
    args = ap.parse_args()

    from diffusers import AutoencoderKL

    torch.set_num_threads(args.threads)
    os.makedirs(args.out, exist_ok=True)
    x, train_i, val_i = vf_icon.load_images_split(args.data, seed=args.seed)
    print(f"data: {len(train_i)} train / {len(val_i)} val images", flush=True)
    xv = x[val_i[:256]]

    torch.manual_seed(args.seed)
    vae = AutoencoderKL.from_pretrained(args.init) if args.init else AutoencoderKL(**VAE_CONFIG)
    ema = copy.deepcopy(vae).eval().requires_grad_(False)
    if args.decoder_only:
        vae.encoder.requires_grad_(False)
        vae.quant_conv.requires_grad_(False)
    params = [p for p in vae.parameters() if p.requires_grad]
    print(f"vae params: {sum(p.numel() for p in vae.parameters()) / 1e6:.2f}M, "
          f"trained {sum(p.numel() for p in params) / 1e6:.2f}M", flush=True)
    opt = torch.optim.AdamW(params, lr=args.lr, weight_decay=0.0, betas=(0.9, 0.99))
    gen = torch.Generator().manual_seed(args.seed)
    step, elapsed0 = 0, 0.0
    ckpt_path = os.path.join(args.out, "ckpt.pt")
    if os.path.exists(ckpt_path):
        ck = torch.load(ckpt_path, weights_only=False)
        vae.load_state_dict(ck["vae"])
        ema.load_state_dict(ck["ema"])
        opt.load_state_dict(ck["opt"])
        gen.set_state(ck["gen"])
        step, elapsed0 = ck["step"], ck["elapsed"]
        print(f"resumed at step {step}", flush=True)

    logs = vf_icon.CsvLog(os.path.join(args.out, "loss.csv"), ["step", "loss", "l1", "edge", "kl", "lr", "elapsed_s", "wall_utc"])
    vlog = vf_icon.CsvLog(os.path.join(args.out, "val.csv"), ["step", "val_psnr_db", "val_l1", "elapsed_s"])
    amp = torch.autocast("cpu", dtype=torch.bfloat16, enabled=args.bf16)

    def validate():
        with torch.no_grad(), amp:
            rec = ema(xv.float(), sample_posterior=False).sample.float().clamp(-1, 1)
        return psnr(rec, xv), (rec - xv).abs().mean().item()

    def save(final=False):
        torch.save({"vae": vae.state_dict(), "ema": ema.state_dict(), "opt": opt.state_dict(), "gen": gen.get_state(),
                    "step": step, "elapsed": elapsed0 + time.time() - t0, "args": vars(args)}, ckpt_path + ".tmp")
        os.replace(ckpt_path + ".tmp", ckpt_path)
        export(ema, x[train_i[:2048]], os.path.join(args.out, "export"))
        p, l1 = validate()
        vlog.row([step, f"{p:.3f}", f"{l1:.5f}", f"{elapsed0 + time.time() - t0:.1f}"])
        print(f"{'final ' if final else ''}checkpoint + export at step {step}: val PSNR {p:.2f} dB", flush=True)

    t0 = time.time()
    last_save = t0
    ema_loss = None
    vae.train()
    ntr = len(train_i)
    while step < args.max_steps and time.time() - t0 < args.minutes * 60:
        b = train_i[torch.randint(0, ntr, (args.batch,), generator=gen)]
        x0 = x[b].float()
        flip = torch.rand(args.batch, generator=gen) < 0.5
        x0 = torch.where(flip[:, None, None, None], x0.flip(-1), x0)
        lr = args.lr * min(1.0, (step + 1) / 200)
        for g in opt.param_groups:
            g["lr"] = lr
        with amp:
            with torch.set_grad_enabled(not args.decoder_only):
                post = vae.encode(x0).latent_dist
            z = post.mean + post.std * torch.randn(post.mean.shape, generator=gen)
            rec = vae.decode(z).sample
        rec = rec.float()
        l1 = (rec - x0).abs().mean()
        edge = (sobel(rec) - sobel(x0)).abs().mean()
        kl = post.kl().float().mean() / (64 * 64)
        loss = l1 + args.edge * edge + args.kl * kl
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params, 1.0)
        opt.step()
        step += 1
        d = min(args.ema, (1 + step) / (10 + step))
        with torch.no_grad():
            for pe, pm in zip(ema.parameters(), vae.parameters()):
                pe.lerp_(pm.detach(), 1 - d)
        lv = loss.item()
        ema_loss = lv if ema_loss is None else 0.98 * ema_loss + 0.02 * lv
        if step % 10 == 0:
            logs.row([step, f"{lv:.5f}", f"{l1.item():.5f}", f"{edge.item():.5f}", f"{kl.item():.3f}", f"{lr:.2e}",
                      f"{elapsed0 + time.time() - t0:.1f}", dt.datetime.now(dt.timezone.utc).strftime("%H:%M:%S")])
        if step % 100 == 0:
            print(f"step {step} loss {ema_loss:.4f} {(time.time() - t0):.0f}s", flush=True)
        if time.time() - last_save > args.export_every_min * 60:
            save()
            last_save = time.time()
    save(final=True)


@torch.no_grad()
def export(ema, sample_images, out_dir):
    """fp32 diffusers layout with scaling_factor = 1 / std of the posterior means of `sample_images`."""
    zs = torch.cat([ema.encode(sample_images[i : i + 256].float()).latent_dist.mean for i in range(0, len(sample_images), 256)])
    ema.register_to_config(scaling_factor=float(1.0 / zs.std()))
    ema.save_pretrained(out_dir, safe_serialization=True)
    with open(os.path.join(out_dir, "latent_stats.json"), "w") as f:
        json.dump({"std": float(zs.std()), "mean": float(zs.mean()), "per_channel_mean": zs.mean(dim=(0, 2, 3)).tolist(),
                   "per_channel_std": zs.std(dim=(0, 2, 3)).tolist(), "n": len(zs)}, f, indent=1)


if __name__ == "__main__":
    main()
