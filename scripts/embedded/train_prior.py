"""Trains the embedded text-conditioned diffusion prior (docs/EMBEDDED.md).

Latent (the default since the 64 px model): the UNet denoises the 16x16x4 latents of the small
autoencoder trained by train_vae.py (--vae DIR), so the embedded model runs the same latent-SDS path
as Stable Diffusion, encoder VJP included. `--vae none` trains the older 32 px pixel-space prior.

    python scripts/embedded/train_prior.py --data data/icons/train --vae /work/vf-train/vae/export \
        --out /work/vf-train/prior --export models/vf-icon --bf16 --batch 64 --until 23:10

v-prediction with min-SNR-gamma loss weighting (Hang et al. 2023: weight min(SNR, gamma) / (SNR + 1)
on the v loss), squaredcos_cap_v2 betas, EMA weights, captions dropped to "" with p = 0.1 for
classifier-free guidance, and each caption seen bare or with an article ("horse" / "a horse") since
users write the latter. Restartable: resumes from OUT/ckpt.pt (model, EMA, optimiser, RNG, step).
Logs OUT/loss.csv and a held-out validation loss (fixed noise and timesteps over the images of 2 % of
the captions, never trained on) in OUT/val.csv.
"""

import argparse
import copy
import datetime as dt
import json
import os
import shutil
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402

UNET_LATENT = dict(
    sample_size=16,
    in_channels=4,
    out_channels=4,
    block_out_channels=(64, 128, 192),
    layers_per_block=1,
    # cross-attention at the 4x4 level only: in bf16 on this CPU the 8x8 attention costs more
    # than it adds (docs/embedded/TRAINING.md, "Architecture and speed")
    down_block_types=("DownBlock2D", "DownBlock2D", "CrossAttnDownBlock2D"),
    up_block_types=("CrossAttnUpBlock2D", "UpBlock2D", "UpBlock2D"),
    cross_attention_dim=384,
    attention_head_dim=8,
    norm_num_groups=32,
)

UNET_PIXEL = dict(
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
    prediction_type="v_prediction",
    clip_sample=False,
    set_alpha_to_one=False,
    steps_offset=1,
    timestep_spacing="trailing",
)


def model_index(latent, guidance, strength, share, per_caption):
    idx = {
        "_class_name": "VectorFusionLatentPipeline" if latent else "VectorFusionPixelPipeline",
        "unet": ["diffusers", "UNet2DConditionModel"],
        "scheduler": ["diffusers", "DDIMScheduler"],
        "text_encoder": ["transformers", "BertModel"],
        "tokenizer": ["transformers", "BertTokenizer"],
        "scorer": ["vectorfusion", "IconClip"],
        # trained on icon names: vectorfusion conditions on the caption without the style suffix
        "_style_suffix": False,
        "_sample_guidance": guidance,
        # SDEdit strength of samples started from retrieved icons (tuned on held-out captions)
        "_sdedit_strength": strength,
        # the share of the K samples started from retrieved icons (the others from noise)
        "_retrieval_share": share,
        # at most this many retrieved icons of one caption (two artists' drawings of it, ...)
        "_retrieval_per_caption": per_caption,
        # a small prior: the pipeline's presets for small models, not Stable Diffusion's
        "_small_prior": True,
        # the prior does not bind colour words: steer samples toward the caption's colour
        # (docs/embedded/COLOUR.md)
        "_colour_steer": "svg",
    }
    if latent:
        idx["vae"] = ["diffusers", "AutoencoderKL"]
    return idx


def export(ema, out_dir, vae_dir, guidance, strength, share, per_caption):
    from diffusers import DDIMScheduler

    os.makedirs(out_dir, exist_ok=True)
    copy.deepcopy(ema).to(torch.float16).save_pretrained(os.path.join(out_dir, "unet"), safe_serialization=True)
    # Sampling starts at t = 999 (trailing spacing); pixel space clamps x0 to [-1, 1] each step.
    cfg = {**SCHEDULER_CONFIG, "clip_sample": vae_dir is None}
    DDIMScheduler(**cfg).save_pretrained(os.path.join(out_dir, "scheduler"))
    if vae_dir is not None:
        from diffusers import AutoencoderKL

        AutoencoderKL.from_pretrained(vae_dir).to(torch.float16).save_pretrained(os.path.join(out_dir, "vae"), safe_serialization=True)
    elif os.path.isdir(os.path.join(out_dir, "vae")):
        shutil.rmtree(os.path.join(out_dir, "vae"))
    with open(os.path.join(out_dir, "model_index.json"), "w") as f:
        json.dump(model_index(vae_dir is not None, guidance, strength, share, per_caption), f, indent=2)
        f.write("\n")


@torch.no_grad()
def encode_dataset(vae_dir, x, cache):
    """Posterior mean and std of every image and of its mirror image, scaled by scaling_factor:
    [N, 2, 4, 16, 16] each (fp16), cached in `cache`."""
    if os.path.exists(cache):
        return torch.load(cache)
    from diffusers import AutoencoderKL

    vae = AutoencoderKL.from_pretrained(vae_dir).eval()
    s = vae.config.scaling_factor
    means, stds = [], []
    # small batches: 256 images at 64 px make 270 MB activations, which glibc maps and unmaps per
    # op (the encode then spends most of its time in the kernel)
    for i in range(0, len(x), 32):
        xb = x[i : i + 32].float()
        d = vae.encode(torch.cat([xb, xb.flip(-1)])).latent_dist
        m, sd = d.mean * s, d.std * s
        n = len(xb)
        means.append(torch.stack([m[:n], m[n:]], 1).half())
        stds.append(torch.stack([sd[:n], sd[n:]], 1).half())
        if (i // 32) % 64 == 0:
            print(f"  encoded {i + n}/{len(x)}", flush=True)
    out = (torch.cat(means), torch.cat(stds))
    torch.save(out, cache)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default="data/icons/train")
    ap.add_argument("--vae", default="/work/vf-train/vae/export", help="autoencoder dir, or 'none' for pixel space")
    ap.add_argument("--out", default="/work/vf-train/prior")
    ap.add_argument("--export", default="models/vf-icon")
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--lr", type=float, default=2e-4)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--ema", type=float, default=0.9995)
    ap.add_argument("--min-snr", type=float, default=5.0, help="min-SNR gamma (0: plain v loss)")
    ap.add_argument("--p-uncond", type=float, default=0.1)
    ap.add_argument("--guidance", type=float, default=5.0, help="sampling CFG scale written to model_index.json")
    ap.add_argument("--sdedit-strength", type=float, default=0.4,
                    help="SDEdit strength of retrieved starts written to model_index.json")
    ap.add_argument("--retrieval-share", type=float, default=0.5,
                    help="share of the K samples started from retrieved icons, written to model_index.json")
    ap.add_argument("--retrieval-per-caption", type=int, default=1,
                    help="at most this many retrieved icons of one caption, written to model_index.json")
    ap.add_argument("--seed", type=int, default=1234)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--bf16", action="store_true", help="bf16 autocast (AVX-512 BF16 / AMX CPUs)")
    ap.add_argument("--max-steps", type=int, default=10**9)
    ap.add_argument("--until", default=None, help="stop at this UTC time HH:MM")
    ap.add_argument("--cooldown-min", type=float, default=0.0,
                    help="warmup-stable-decay: over the last M minutes before --until the LR falls linearly to --lr-floor x --lr")
    ap.add_argument("--cooldown-steps", type=int, default=0,
                    help="the same decay over the last N steps before --max-steps (with --until too, the lower LR wins)")
    ap.add_argument("--lr-floor", type=float, default=0.05)
    ap.add_argument("--export-every-min", type=float, default=15.0)
    ap.add_argument("--val-every", type=int, default=500)
    ap.add_argument("--init", default=None,
                    help="start from an exported model directory's unet/ (e.g. models/vf-icon: the committed "
                         "weights, when no checkpoint survived); fresh optimiser, step count from --init-step")
    ap.add_argument("--init-step", type=int, default=0)
    args = ap.parse_args()
    vae_dir = None if args.vae == "none" else args.vae

    from diffusers import DDPMScheduler, UNet2DConditionModel

    torch.set_num_threads(args.threads)
    os.makedirs(args.out, exist_ok=True)
    x, train_i, val_i = vf_icon.load_images_split(args.data, seed=args.seed)
    idx = torch.from_numpy(np.load(os.path.join(args.data, "text_index.npy")).astype(np.int64))
    caps = json.load(open(os.path.join(args.data, "text_captions.json")))
    assert caps[0] == "", "caption index 0 must be the unconditional caption"
    # [templates, U, 32, 384]: template 0 the bare caption, 1 with an article (encode_text.py)
    tok = torch.from_numpy(np.stack([
        np.fromfile(os.path.join(args.data, f), dtype=np.float16).reshape(len(caps), 32, 384)
        for f in ("text_tokens.f16", "text_tokens_article.f16")
    ]))
    no_flip = torch.tensor([("left" in c or "right" in c) for c in caps])
    print(f"data: {len(train_i)} train / {len(val_i)} val images, {len(caps)} captions", flush=True)
    if vae_dir is not None:
        zmean, zstd = encode_dataset(vae_dir, x, os.path.join(args.out, "latents.pt"))
        cfg = UNET_LATENT
    else:
        x32 = torch.nn.functional.interpolate(x.float(), size=(32, 32), mode="area").half()
        zmean, zstd = torch.stack([x32, x32.flip(-1)], 1), torch.zeros(1, dtype=torch.float16)
        cfg = UNET_PIXEL

    torch.manual_seed(args.seed)
    unet = UNet2DConditionModel(**cfg)
    # Plain matmul attention: for the 16-token attention here PyTorch's CPU flash-attention
    # backward in bf16 took a third of each step; this is ~35 % faster per step (same maths).
    from diffusers.models.attention_processor import AttnProcessor

    unet.set_attn_processor(AttnProcessor())
    ema = copy.deepcopy(unet).eval().requires_grad_(False)
    print(f"unet params: {sum(p.numel() for p in unet.parameters()) / 1e6:.2f}M", flush=True)
    opt = torch.optim.AdamW(unet.parameters(), lr=args.lr, weight_decay=0.01)
    sched = DDPMScheduler(**{k: v for k, v in SCHEDULER_CONFIG.items() if k not in ("set_alpha_to_one", "timestep_spacing")})
    acp = sched.alphas_cumprod.float()
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
        print(f"resumed at step {step}", flush=True)
    elif args.init:
        init = UNet2DConditionModel.from_pretrained(os.path.join(args.init, "unet")).float()
        unet.load_state_dict(init.state_dict())
        ema.load_state_dict(init.state_dict())
        step = args.init_step
        print(f"initialised from {args.init}/unet at step {step}", flush=True)

    # The warm-up counts this run's steps: a run continued with a fresh optimiser (--init, or a
    # resume) ramps its learning rate again instead of jumping to --lr.
    run_start = step
    deadline = None
    if args.until:
        hh, mm = map(int, args.until.split(":"))
        now = dt.datetime.now(dt.timezone.utc)
        deadline = now.replace(hour=hh, minute=mm, second=0, microsecond=0)
        if deadline <= now:
            deadline += dt.timedelta(days=1)

    logs = vf_icon.CsvLog(os.path.join(args.out, "loss.csv"), ["step", "loss", "ema_loss", "lr", "elapsed_s", "wall_utc"])
    vlog = vf_icon.CsvLog(os.path.join(args.out, "val.csv"), ["step", "val_loss", "val_loss_t_lo", "val_loss_t_mid", "val_loss_t_hi", "elapsed_s"])
    amp = torch.autocast("cpu", dtype=torch.bfloat16, enabled=args.bf16)

    def batch(ids, g, templates=True):
        n = len(ids)
        flip = ((torch.rand(n, generator=g) < 0.5) & ~no_flip[idx[ids]]).long()
        std = zstd[ids, flip].float() if vae_dir is not None else 0.0
        z0 = zmean[ids, flip].float() + std * torch.randn((n,) + tuple(zmean.shape[2:]), generator=g)
        tmpl = torch.randint(0, 2, (n,), generator=g) if templates else torch.zeros(n, dtype=torch.long)
        return z0, tok[tmpl, idx[ids]].float()

    def v_loss(model, z0, cond, t, noise, weighted=True):
        a = acp[t].view(-1, 1, 1, 1)
        zt = a.sqrt() * z0 + (1 - a).sqrt() * noise
        with amp:
            pred = model(zt, t, encoder_hidden_states=cond).sample
        target = a.sqrt() * noise - (1 - a).sqrt() * z0
        per = ((pred.float() - target) ** 2).mean(dim=(1, 2, 3))
        if weighted and args.min_snr > 0:
            snr = a.flatten() / (1 - a.flatten())
            per = per * snr.clamp(max=args.min_snr) / (snr + 1)
        return per

    vgen = torch.Generator().manual_seed(4321)
    vids = val_i[torch.randperm(len(val_i), generator=vgen)[:256]]
    vz0, vcond = batch(vids, vgen, templates=False)
    vt = torch.linspace(0, 999, len(vids)).long()
    vnoise = torch.randn(vz0.shape, generator=vgen)

    @torch.no_grad()
    def validate(model=None):
        model = ema if model is None else model
        per = torch.cat([v_loss(model, vz0[i : i + 64], vcond[i : i + 64], vt[i : i + 64], vnoise[i : i + 64], weighted=False)
                         for i in range(0, len(vids), 64)])
        k = len(per) // 3
        return per.mean().item(), per[:k].mean().item(), per[k : 2 * k].mean().item(), per[2 * k :].mean().item()

    def save(final=False):
        torch.save({"unet": unet.state_dict(), "ema": ema.state_dict(), "opt": opt.state_dict(), "gen": gen.get_state(),
                    "step": step, "elapsed": elapsed0 + time.time() - t0, "args": vars(args)}, ckpt_path + ".tmp")
        os.replace(ckpt_path + ".tmp", ckpt_path)
        export(ema, args.export, vae_dir, args.guidance, args.sdedit_strength, args.retrieval_share,
               args.retrieval_per_caption)
        print(f"{'final ' if final else ''}checkpoint + export at step {step}", flush=True)

    t0 = time.time()
    last_save = t0
    ema_loss = None
    unet.train()
    while step < args.max_steps:
        if deadline and dt.datetime.now(dt.timezone.utc) >= deadline:
            break
        z0, cond = batch(train_i[torch.randint(0, len(train_i), (args.batch,), generator=gen)], gen)
        drop = torch.rand(args.batch, generator=gen) < args.p_uncond
        cond[drop] = tok[0, 0].float()
        t = torch.randint(0, 1000, (args.batch,), generator=gen)
        noise = torch.randn(z0.shape, generator=gen)
        lr = args.lr * min(1.0, (step - run_start + 1) / args.warmup)
        f = 1.0
        if deadline and args.cooldown_min > 0:
            left = (deadline - dt.datetime.now(dt.timezone.utc)).total_seconds() / 60
            f = min(f, max(0.0, left / args.cooldown_min))
        if args.cooldown_steps > 0:
            f = min(f, max(0.0, (args.max_steps - step) / args.cooldown_steps))
        lr *= args.lr_floor + (1 - args.lr_floor) * f
        for g in opt.param_groups:
            g["lr"] = lr
        loss = v_loss(unet, z0, cond, t, noise).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(unet.parameters(), 1.0)
        opt.step()
        step += 1
        d = min(args.ema, (1 + step) / (10 + step))
        with torch.no_grad():
            for pe, pm in zip(ema.parameters(), unet.parameters()):
                pe.lerp_(pm.detach(), 1 - d)
        lv = loss.item()
        ema_loss = lv if ema_loss is None else 0.98 * ema_loss + 0.02 * lv
        el = elapsed0 + time.time() - t0
        if step % 10 == 0:
            logs.row([step, f"{lv:.5f}", f"{ema_loss:.5f}", f"{lr:.2e}", f"{el:.1f}", dt.datetime.now(dt.timezone.utc).strftime("%H:%M:%S")])
        if step % args.val_every == 0:
            v = validate()
            vlog.row([step] + [f"{a:.5f}" for a in v] + [f"{el:.1f}"])
            print(f"step {step} loss {ema_loss:.4f} val {v[0]:.4f} {(time.time() - t0):.0f}s", flush=True)
        if time.time() - last_save > args.export_every_min * 60:
            save()
            last_save = time.time()
    # After a cooldown the raw weights can beat the EMA (its horizon spans the pre-decay weights):
    # export whichever has the lower held-out loss.
    unet.eval()
    v_ema, v_raw = validate()[0], validate(unet)[0]
    print(f"final val loss: ema {v_ema:.5f} raw {v_raw:.5f}", flush=True)
    save(final=True)
    if v_raw < v_ema:
        export(unet, args.export, vae_dir, args.guidance, args.sdedit_strength, args.retrieval_share,
               args.retrieval_per_caption)
        print("exported the raw weights instead (the checkpoint keeps both)", flush=True)


if __name__ == "__main__":
    main()
