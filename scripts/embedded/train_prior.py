"""Trains the embedded pixel-space text-conditioned diffusion prior (docs/EMBEDDED.md).

    nice -n 15 python scripts/embedded/train_prior.py --data data/icons/train --out data/prior \
        --until 14:15 --export-every-min 15

Restartable: resumes from OUT/ckpt.pt when present (model, EMA, optimiser, step, RNG states).
Logs OUT/loss.csv (step, loss, ema_loss, lr, elapsed_s, wall_utc). Every --export-every-min
minutes (and at the end) saves the checkpoint and exports the EMA weights to
--export (default models/vf-icon) as unet/ + scheduler/ + model_index.json.
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

UNET_CONFIG = dict(
    sample_size=32,
    in_channels=3,
    out_channels=3,
    block_out_channels=(32, 64, 128),
    layers_per_block=1,
    down_block_types=("DownBlock2D", "DownBlock2D", "CrossAttnDownBlock2D"),
    up_block_types=("CrossAttnUpBlock2D", "UpBlock2D", "UpBlock2D"),
    cross_attention_dim=384,
    attention_head_dim=8,
    norm_num_groups=32,
)

SCHEDULER_CONFIG = dict(
    num_train_timesteps=1000,
    beta_schedule="squaredcos_cap_v2",
    prediction_type="epsilon",
    clip_sample=False,
    set_alpha_to_one=False,
    steps_offset=1,
    timestep_spacing="leading",
)

MODEL_INDEX = {
    "_class_name": "VectorFusionPixelPipeline",
    "unet": ["diffusers", "UNet2DConditionModel"],
    "scheduler": ["diffusers", "DDIMScheduler"],
    "text_encoder": ["transformers", "BertModel"],
    "tokenizer": ["transformers", "BertTokenizer"],
    "scorer": ["vectorfusion", "IconClip"],
    # trained on bare icon names: vectorfusion conditions on the caption without the style suffix
    "_style_suffix": False,
    # CFG 3 gave the most recognisable samples at 12 DDIM steps (7.5 and 15 over-saturate)
    "_sample_guidance": 3.0,
}


def load_split(path, size=32):
    """Images as [N, 3, size, size] float in [-1, 1] (area-downsampled from 64), caption ids, tokens."""
    raw = np.fromfile(os.path.join(path, "images_64.u8"), dtype=np.uint8).reshape(-1, 64, 64, 3)
    x = torch.from_numpy(raw).permute(0, 3, 1, 2).float() / 255.0
    x = F.interpolate(x, size=(size, size), mode="area") * 2 - 1
    idx = torch.from_numpy(np.load(os.path.join(path, "text_index.npy")).astype(np.int64))
    caps = json.load(open(os.path.join(path, "text_captions.json")))
    tok = np.fromfile(os.path.join(path, "text_tokens.f16"), dtype=np.float16).reshape(len(caps), 32, 384)
    return x.contiguous(), idx, torch.from_numpy(tok.astype(np.float32)), caps


def export(ema, out_dir, prediction):
    from diffusers import DDIMScheduler

    os.makedirs(out_dir, exist_ok=True)
    half = copy.deepcopy(ema).to(torch.float16)
    half.save_pretrained(os.path.join(out_dir, "unet"), safe_serialization=True)
    # Sampling: start at t = 999 (trailing spacing) and clamp x0 to [-1, 1] each step (pixel space).
    cfg = {**SCHEDULER_CONFIG, "prediction_type": prediction, "timestep_spacing": "trailing", "clip_sample": True}
    DDIMScheduler(**cfg).save_pretrained(os.path.join(out_dir, "scheduler"))
    with open(os.path.join(out_dir, "model_index.json"), "w") as f:
        json.dump(MODEL_INDEX, f, indent=2)
        f.write("\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data/icons/train")
    ap.add_argument("--out", default="data/prior")
    ap.add_argument("--export", default="models/vf-icon")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--lr", type=float, default=3e-4)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--ema", type=float, default=0.999)
    ap.add_argument("--p-uncond", type=float, default=0.1)
    ap.add_argument("--seed", type=int, default=1234)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--max-steps", type=int, default=10**9)
    ap.add_argument("--prediction", choices=["epsilon", "v_prediction"], default="v_prediction",
                    help="training target; v weights the loss toward the high-noise steps that decide layout")
    ap.add_argument("--init", default=None,
                    help="start from this checkpoint's EMA weights (fresh optimiser, step count kept)")
    ap.add_argument("--until", default=None, help="stop at this UTC time HH:MM")
    ap.add_argument("--export-every-min", type=float, default=15.0)
    args = ap.parse_args()

    from diffusers import DDPMScheduler, UNet2DConditionModel

    torch.set_num_threads(args.threads)
    os.makedirs(args.out, exist_ok=True)
    x, idx, tok, caps = load_split(args.data)
    assert caps[0] == "", "caption index 0 must be the unconditional caption"
    print(f"data: {len(x)} images, {len(caps)} captions", flush=True)

    torch.manual_seed(args.seed)
    unet = UNet2DConditionModel(**UNET_CONFIG)
    ema = copy.deepcopy(unet).eval()
    for p in ema.parameters():
        p.requires_grad_(False)
    print(f"unet params: {sum(p.numel() for p in unet.parameters()) / 1e6:.2f}M", flush=True)
    opt = torch.optim.AdamW(unet.parameters(), lr=args.lr, weight_decay=0.01)
    sched = DDPMScheduler(**{k: v for k, v in SCHEDULER_CONFIG.items() if k not in ("set_alpha_to_one",)})
    acp = sched.alphas_cumprod
    gen = torch.Generator().manual_seed(args.seed)
    step, elapsed0 = 0, 0.0

    ckpt_path = os.path.join(args.out, "ckpt.pt")
    if os.path.exists(ckpt_path):
        ck = torch.load(ckpt_path, weights_only=False)
        unet.load_state_dict(ck["unet"])
        ema.load_state_dict(ck["ema"])
        opt.load_state_dict(ck["opt"])
        gen.set_state(ck["gen"])
        step, elapsed0 = ck["step"], ck["elapsed"]
        trained = ck.get("args", {}).get("prediction", "epsilon")  # older checkpoints: epsilon
        if trained != args.prediction:
            sys.exit(f"{ckpt_path} was trained with --prediction {trained}; resume with the same target "
                     f"(or start a new --out with --init to switch)")
        if args.init:
            print(f"note: --init ignored, {ckpt_path} exists", flush=True)
        print(f"resumed at step {step}", flush=True)
    elif args.init:
        ck = torch.load(args.init, weights_only=False)
        unet.load_state_dict(ck["ema"])
        ema.load_state_dict(ck["ema"])
        step = ck["step"]
        print(f"initialised from {args.init} (EMA weights of step {step}), target {args.prediction}", flush=True)

    deadline = None
    if args.until:
        hh, mm = map(int, args.until.split(":"))
        now = dt.datetime.now(dt.timezone.utc)
        deadline = now.replace(hour=hh, minute=mm, second=0, microsecond=0)

    log_new = not os.path.exists(os.path.join(args.out, "loss.csv"))
    logf = open(os.path.join(args.out, "loss.csv"), "a", newline="")
    log = csv.writer(logf)
    if log_new:
        log.writerow(["step", "loss", "ema_loss", "lr", "elapsed_s", "wall_utc"])

    def save(final=False):
        torch.save(
            {"unet": unet.state_dict(), "ema": ema.state_dict(), "opt": opt.state_dict(), "gen": gen.get_state(),
             "step": step, "elapsed": elapsed0 + time.time() - t0, "args": vars(args)},
            ckpt_path + ".tmp",
        )
        os.replace(ckpt_path + ".tmp", ckpt_path)
        export(ema, args.export, args.prediction)
        print(f"{'final ' if final else ''}checkpoint + export at step {step}", flush=True)

    t0 = time.time()
    last_save = t0
    ema_loss = None
    unet.train()
    n = len(x)
    while step < args.max_steps:
        if deadline and dt.datetime.now(dt.timezone.utc) >= deadline:
            break
        b = torch.randint(0, n, (args.batch,), generator=gen)
        x0 = x[b]
        flip = torch.rand(args.batch, generator=gen) < 0.5
        x0 = torch.where(flip[:, None, None, None], x0.flip(-1), x0)
        ci = idx[b].clone()
        ci[torch.rand(args.batch, generator=gen) < args.p_uncond] = 0
        cond = tok[ci]
        t = torch.randint(0, 1000, (args.batch,), generator=gen)
        noise = torch.randn(x0.shape, generator=gen)
        a = acp[t].view(-1, 1, 1, 1)
        xt = a.sqrt() * x0 + (1 - a).sqrt() * noise
        lr = args.lr * min(1.0, (step + 1) / args.warmup)
        for g in opt.param_groups:
            g["lr"] = lr
        pred = unet(xt, t, encoder_hidden_states=cond).sample
        target = noise if args.prediction == "epsilon" else a.sqrt() * noise - (1 - a).sqrt() * x0
        loss = F.mse_loss(pred, target)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(unet.parameters(), 1.0)
        opt.step()
        step += 1
        d = min(args.ema, (1 + step) / (10 + step))
        with torch.no_grad():
            for pe, pm in zip(ema.parameters(), unet.parameters()):
                pe.mul_(d).add_(pm.detach(), alpha=1 - d)
        lv = loss.item()
        ema_loss = lv if ema_loss is None else 0.98 * ema_loss + 0.02 * lv
        if step % 10 == 0:
            el = elapsed0 + time.time() - t0
            log.writerow([step, f"{lv:.5f}", f"{ema_loss:.5f}", f"{lr:.2e}", f"{el:.1f}",
                          dt.datetime.now(dt.timezone.utc).strftime("%H:%M:%S")])
            logf.flush()
        if step % 100 == 0:
            print(f"step {step} loss {ema_loss:.4f} {(time.time() - t0):.0f}s", flush=True)
        if time.time() - last_save > args.export_every_min * 60:
            save()
            last_save = time.time()
    save(final=True)


if __name__ == "__main__":
    main()
