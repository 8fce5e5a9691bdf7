"""Reference outputs of the REAL exported vf-icon model, for the Rust loader tests.

    python scripts/embedded/make_refs.py [--model models/vf-icon] [--out tests/fixtures/vf-icon-refs/refs.safetensors]

All tensors f32 unless noted; computed on CPU in f32 from the exported weights (fp16 weights are
upcast exactly, so a Rust f32 forward over the same files should match to ~1e-4).
Metadata (safetensors header `__metadata__`): "captions" (JSON list), "unet_caption",
"seed", "model_sha256_unet", "model_sha256_scorer".

Keys:
  unet_input_ids        i64 [3, 32]   BertTokenizer ids for CAPTIONS, padded to 32
  unet_attention_mask   i64 [3, 32]
  unet_cond             [3, 32, 384]  vf_icon.encode_tokens (MiniLM last_hidden_state, all 32 positions)
  unet_x_t              [1, C, S, S] torch.randn(generator seed 0); C, S = the UNet's in_channels and
                                      sample_size (latent model: 4, 16; pixel model: 3, 32)
  unet_t                [1]           500.0 (timestep)
  unet_eps              [1, C, S, S]  UNet(unet_x_t, 500, encoder_hidden_states=unet_cond[0:1]) ("a crown")
  ddim_uncond           [1, 32, 384]  encode_tokens([""])
  ddim_init             [1, C, S, S]  torch.randn(generator seed 2)
  ddim_step{0..3}       [1, C, S, S]  x after each step of a 4-step DDIM (eta 0) with the shipped
                                      scheduler, guidance 5 on unet_cond[0:1]
  vae_image             [1, 3, 64, 64] (latent model only) clip_images[0:1] in [0, 1]
  vae_latent            [1, 4, 16, 16] scaling_factor * VAE posterior mean of vae_image*2-1
  vae_decoded           [1, 3, 64, 64] (VAE.decode(ddim_step3 / scaling_factor) + 1) / 2, clamped to [0, 1]
  ddim_timesteps        i64 [4]       the scheduler's timesteps for 4 steps
  clip_images           [2, 3, 64, 64] RGB in [0,1]: seeded (seed 1) 8x8 uniform noise upsampled bilinearly
  clip_image_emb        [2, 384]      IconClip.encode_image(clip_images), L2-normalised
  clip_input_ids        i64 [3, 64]   ids for CAPTIONS padded to 64 (scorer text length)
  clip_attention_mask   i64 [3, 64]
  clip_sentence         [3, 384]      vf_icon.encode_sentence (mean-pooled, normalised MiniLM)
  clip_text_emb         [3, 384]      IconClip.encode_text(clip_sentence)
  clip_logit_scale      [1]           the scorer's logit_scale (log space)
  clip_logits           [2, 3]        exp(logit_scale) * clip_image_emb @ clip_text_emb.T
"""

import argparse
import hashlib
import json
import os
import sys

import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402

CAPTIONS = ["a crown", "red heart", ""]


DDIM_GUIDANCE = 5.0


def sha(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


@torch.no_grad()
def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", default="models/vf-icon")
    ap.add_argument("--out", default="tests/fixtures/vf-icon-refs/refs.safetensors")
    args = ap.parse_args()
    from diffusers import DDIMScheduler, UNet2DConditionModel
    from safetensors.torch import load_file, save_file

    torch.set_num_threads(2)
    tok, text = vf_icon.load_text_model()
    unet = UNet2DConditionModel.from_pretrained(os.path.join(args.model, "unet")).float().eval()
    cfg = json.load(open(os.path.join(args.model, "scorer", "config.json")))
    clip = vf_icon.IconClip(image_size=cfg["image_size"], channels=cfg["channels"], groups=cfg["groups"], embed_dim=cfg["embed_dim"])
    clip.load_state_dict(load_file(os.path.join(args.model, "scorer", "model.safetensors")))
    clip.eval()

    out = {}
    enc = tok(CAPTIONS, padding="max_length", truncation=True, max_length=vf_icon.UNET_TEXT_LEN, return_tensors="pt")
    out["unet_input_ids"] = enc.input_ids
    out["unet_attention_mask"] = enc.attention_mask
    cond = vf_icon.encode_tokens(tok, text, CAPTIONS)
    out["unet_cond"] = cond
    shape = (1, unet.config.in_channels, unet.config.sample_size, unet.config.sample_size)
    x_t = torch.randn(shape, generator=torch.Generator().manual_seed(0))
    out["unet_x_t"] = x_t
    out["unet_t"] = torch.tensor([500.0])
    out["unet_eps"] = unet(x_t, torch.tensor([500]), encoder_hidden_states=cond[0:1]).sample

    # A 4-step guided DDIM trajectory with the shipped scheduler (prediction type, spacing, clip_sample).
    sched = DDIMScheduler.from_pretrained(os.path.join(args.model, "scheduler"))
    sched.set_timesteps(4)
    uncond = vf_icon.encode_tokens(tok, text, [""])
    out["ddim_uncond"] = uncond
    x = torch.randn(shape, generator=torch.Generator().manual_seed(2))
    out["ddim_init"] = x
    for i, t in enumerate(sched.timesteps):
        eu = unet(x, t, encoder_hidden_states=uncond).sample
        ec = unet(x, t, encoder_hidden_states=cond[0:1]).sample
        x = sched.step(eu + DDIM_GUIDANCE * (ec - eu), t, x, eta=0.0).prev_sample
        out[f"ddim_step{i}"] = x
    out["ddim_timesteps"] = sched.timesteps.to(torch.int64)

    small = torch.rand((2, 3, 8, 8), generator=torch.Generator().manual_seed(1))
    imgs = F.interpolate(small, size=(64, 64), mode="bilinear", align_corners=False).clamp(0, 1)
    out["clip_images"] = imgs
    out["clip_image_emb"] = clip.encode_image(imgs)
    enc = tok(CAPTIONS, padding="max_length", truncation=True, max_length=vf_icon.SCORER_TEXT_LEN, return_tensors="pt")
    out["clip_input_ids"] = enc.input_ids
    out["clip_attention_mask"] = enc.attention_mask
    sent = vf_icon.encode_sentence(tok, text, CAPTIONS)
    out["clip_sentence"] = sent
    out["clip_text_emb"] = clip.encode_text(sent)
    out["clip_logit_scale"] = clip.logit_scale.detach().reshape(1)
    out["clip_logits"] = clip.logits(out["clip_image_emb"], out["clip_text_emb"])

    vae_dir = os.path.join(args.model, "vae")
    if os.path.isdir(vae_dir):
        from diffusers import AutoencoderKL

        vae = AutoencoderKL.from_pretrained(vae_dir).float().eval()
        k = vae.config.scaling_factor
        out["vae_image"] = imgs[0:1].clone()
        out["vae_latent"] = vae.encode(imgs[0:1] * 2 - 1).latent_dist.mean * k
        out["vae_decoded"] = ((vae.decode(out["ddim_step3"] / k).sample + 1) / 2).clamp(0, 1)

    out = {k: v.contiguous() if v.dtype == torch.int64 else v.float().contiguous() for k, v in out.items()}
    meta = {
        "captions": json.dumps(CAPTIONS),
        "unet_caption": CAPTIONS[0],
        "seed": "x_t: 0, clip_images: 1, ddim_init: 2",
        "ddim_guidance": str(DDIM_GUIDANCE),
        "model_sha256_unet": sha(os.path.join(args.model, "unet", "diffusion_pytorch_model.safetensors")),
        "model_sha256_scorer": sha(os.path.join(args.model, "scorer", "model.safetensors")),
    }
    if os.path.isdir(vae_dir):
        meta["model_sha256_vae"] = sha(os.path.join(vae_dir, "diffusion_pytorch_model.safetensors"))
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    save_file(out, args.out, metadata=meta)
    print(f"wrote {args.out} ({os.path.getsize(args.out)} bytes): {sorted(out)}")


if __name__ == "__main__":
    main()
