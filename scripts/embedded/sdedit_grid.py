"""SDEdit strengths on the exported latent prior: training icons of some captions, noised to each
strength of a DDIM schedule and denoised with their caption (torch, as `src/stages/sample.rs`).

    python scripts/embedded/sdedit_grid.py --model models/vf-icon --out docs/embedded/sdedit.png
"""

import argparse
import json
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402

CAPTIONS = ["red heart", "grinning face", "rocket", "horse face", "pizza", "christmas tree", "taxi", "sun"]


@torch.no_grad()
def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="models/vf-icon")
    ap.add_argument("--data", default="data/icons/train")
    ap.add_argument("--out", default="docs/embedded/sdedit.png")
    ap.add_argument("--steps", type=int, default=12)
    ap.add_argument("--cfg", type=float, default=3.0)
    ap.add_argument("--strengths", default="0.4,0.5,0.6,0.8,1.0")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from diffusers import AutoencoderKL, DDIMScheduler, UNet2DConditionModel

    unet = UNet2DConditionModel.from_pretrained(os.path.join(args.model, "unet")).float().eval()
    vae = AutoencoderKL.from_pretrained(os.path.join(args.model, "vae")).float().eval()
    sched = DDIMScheduler.from_pretrained(os.path.join(args.model, "scheduler"))
    k = vae.config.scaling_factor
    tok, text = vf_icon.load_text_model()
    uncond = vf_icon.encode_tokens(tok, text, [""])
    raw = np.fromfile(os.path.join(args.data, "images_64.u8"), dtype=np.uint8).reshape(-1, 64, 64, 3)
    caps = [json.loads(l) for l in open(os.path.join(args.data, "captions.jsonl"))]
    strengths = [float(s) for s in args.strengths.split(",")]
    gen = torch.Generator().manual_seed(0)
    fig, axes = plt.subplots(len(CAPTIONS), len(strengths) + 1, figsize=(1.3 * (len(strengths) + 1), 1.4 * len(CAPTIONS)))
    for r, c in enumerate(CAPTIONS):
        i = next(j for j, m in enumerate(caps) if m["caption"] == c)
        x = torch.from_numpy(raw[i]).permute(2, 0, 1)[None].float() / 127.5 - 1
        z0 = vae.encode(x).latent_dist.mean * k
        cond = vf_icon.encode_tokens(tok, text, [c])
        axes[r, 0].imshow(raw[i])
        axes[r, 0].set_title(f"{caps[i]['set']}", fontsize=6)
        axes[r, 0].set_ylabel(c, fontsize=7)
        noise = torch.randn(z0.shape, generator=gen)
        for j, s in enumerate(strengths):
            sched.set_timesteps(args.steps)
            run = round(args.steps * s)
            ts = sched.timesteps[args.steps - run:]
            a = sched.alphas_cumprod[ts[0]]
            z = a.sqrt() * z0 + (1 - a).sqrt() * noise
            for t in ts:
                eu = unet(z, t, encoder_hidden_states=uncond).sample
                ec = unet(z, t, encoder_hidden_states=cond).sample
                z = sched.step(eu + args.cfg * (ec - eu), t, z).prev_sample
            img = ((vae.decode(z / k).sample + 1) / 2).clamp(0, 1)[0].permute(1, 2, 0).numpy()
            axes[r, j + 1].imshow(img)
            if r == 0:
                axes[r, j + 1].set_title(f"strength {s}", fontsize=7)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"SDEdit from training icons, DDIM {args.steps} steps, CFG {args.cfg}", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
