#!/usr/bin/env python3
"""Build tiny random-weight Stable Diffusion components in the diffusers layout and save
reference outputs computed with diffusers/transformers (torch, CPU, fp32).

Run with the project venv:  /work/venv/bin/python scripts/make_sd_fixtures.py
Outputs (committed, small):
  tests/fixtures/sd-tiny/     model_index.json, unet/, vae/, scheduler/, text_encoder/, tokenizer/
                              refs.safetensors (reference tensors), refs.json (scalars)
  tests/fixtures/sd-tiny-v/   SD2-style UNet (linear projection, per-block heads, fp16 weights
                              file variant) + v_prediction scheduler; refs.safetensors
  tests/fixtures/taesd-tiny/  AutoencoderTiny (madebyollin/taesd layout) + refs.safetensors
The Rust tests (tests/models_*.rs) compare against these; Python is never needed by CI.
"""

import json
import os
import shutil

import torch
from safetensors.torch import save_file

import diffusers
from diffusers import (
    AutoencoderKL,
    AutoencoderTiny,
    DDIMScheduler,
    EulerDiscreteScheduler,
    UNet2DConditionModel,
)
from transformers import CLIPTextConfig, CLIPTextModel, CLIPTokenizer

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures")
torch.set_grad_enabled(False)


def perturb(model, seed, scale=0.05):
    """Default inits leave norms at 1/0 and some layers at zero: add seeded noise everywhere so
    every weight influences the reference outputs."""
    g = torch.Generator().manual_seed(seed)
    for p in model.parameters():
        p.add_(torch.randn(p.shape, generator=g) * scale)
    model.eval()
    return model


def randn(*shape, seed):
    return torch.randn(*shape, generator=torch.Generator().manual_seed(seed))


def fresh(path):
    shutil.rmtree(path, ignore_errors=True)
    os.makedirs(path)


def unet_tiny(sd2):
    torch.manual_seed(1 if not sd2 else 2)
    return perturb(
        UNet2DConditionModel(
            sample_size=16,
            in_channels=4,
            out_channels=4,
            down_block_types=("CrossAttnDownBlock2D", "DownBlock2D"),
            up_block_types=("UpBlock2D", "CrossAttnUpBlock2D"),
            # candle-transformers' UNet resnets always use 32 groups, so 32 is the minimum width
            block_out_channels=(32, 64),
            layers_per_block=1,
            norm_num_groups=32,
            cross_attention_dim=16,
            attention_head_dim=(2, 4) if sd2 else 2,
            use_linear_projection=sd2,
        ),
        seed=11 if not sd2 else 12,
    )


def vae_tiny():
    torch.manual_seed(3)
    return perturb(
        AutoencoderKL(
            in_channels=3,
            out_channels=3,
            down_block_types=("DownEncoderBlock2D", "DownEncoderBlock2D"),
            up_block_types=("UpDecoderBlock2D", "UpDecoderBlock2D"),
            block_out_channels=(16, 32),
            layers_per_block=1,
            latent_channels=4,
            norm_num_groups=8,
            sample_size=32,
            scaling_factor=0.18215,
        ),
        seed=13,
    )


def text_tiny(path):
    """A tiny CLIP text model + a byte-level BPE tokenizer with a handful of merges."""
    bs = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), ord("ÿ") + 1))
    cs = bs[:]
    n = 0
    for b in range(256):
        if b not in bs:
            bs.append(b)
            cs.append(256 + n)
            n += 1
    chars = [chr(c) for c in cs]
    merges = ["a t</w>", "c at</w>", "t h", "th e</w>", "d o", "do g</w>", "r e", "re d</w>"]
    vocab_list = chars + [c + "</w>" for c in chars]
    for m in merges:
        vocab_list.append(m.replace(" ", ""))
    vocab_list += ["<|startoftext|>", "<|endoftext|>"]
    vocab = {t: i for i, t in enumerate(vocab_list)}
    tok_dir = os.path.join(path, "tokenizer")
    os.makedirs(tok_dir, exist_ok=True)
    with open(os.path.join(tok_dir, "vocab.json"), "w") as f:
        json.dump(vocab, f, ensure_ascii=False)
    with open(os.path.join(tok_dir, "merges.txt"), "w") as f:
        f.write("#version: 0.2\n" + "\n".join(merges) + "\n")
    tok = CLIPTokenizer(os.path.join(tok_dir, "vocab.json"), os.path.join(tok_dir, "merges.txt"), model_max_length=77)
    tok.save_pretrained(tok_dir)
    torch.manual_seed(4)
    cfg = CLIPTextConfig(
        vocab_size=len(vocab),
        hidden_size=16,
        intermediate_size=37,
        num_hidden_layers=2,
        num_attention_heads=2,
        max_position_embeddings=77,
        projection_dim=16,
        hidden_act="quick_gelu",
        bos_token_id=vocab["<|startoftext|>"],
        eos_token_id=vocab["<|endoftext|>"],
        pad_token_id=vocab["<|endoftext|>"],
    )
    model = perturb(CLIPTextModel(cfg), seed=14)
    model.save_pretrained(os.path.join(path, "text_encoder"), safe_serialization=True)
    return tok, model


def embed(tok, model, prompt):
    ids = tok([prompt], padding="max_length", max_length=77, truncation=True, return_tensors="pt").input_ids
    return ids, model(ids)[0]


def ddim_sched(prediction_type):
    return DDIMScheduler(
        num_train_timesteps=1000,
        beta_start=0.00085,
        beta_end=0.012,
        beta_schedule="scaled_linear",
        clip_sample=False,
        set_alpha_to_one=False,
        steps_offset=1,
        prediction_type=prediction_type,
        timestep_spacing="leading",
    )


def guided(unet, z, t, cond, uncond, g):
    zz = torch.cat([z, z])
    ctx = torch.cat([uncond, cond])
    out = unet(zz, t, encoder_hidden_states=ctx).sample
    u, c = out.chunk(2)
    return u + g * (c - u)


def to_eps(pred, z_t, ac, prediction_type):
    if prediction_type == "epsilon":
        return pred
    # v = sqrt(ac) eps - sqrt(1-ac) x0  =>  eps = sqrt(ac) v + sqrt(1-ac) z_t
    return ac.sqrt() * pred + (1 - ac).sqrt() * z_t


def main():
    print("diffusers", diffusers.__version__, "torch", torch.__version__)
    timesteps = [999, 500, 10]
    guidance = 7.5

    # ---------------- sd-tiny (SD 1.x style, epsilon) ----------------
    path = os.path.join(ROOT, "sd-tiny")
    fresh(path)
    # UNet weights are stored as fp16 data (as SD-Turbo's repos do) to keep fixtures small; the
    # references use exactly those rounded weights, computed in fp32.
    unet = unet_tiny(sd2=False).half().float()
    vae = vae_tiny()
    tok, text = text_tiny(path)
    sched = ddim_sched("epsilon")
    unet.save_pretrained(os.path.join(path, "unet"), safe_serialization=True)
    from safetensors.torch import load_file
    wf0 = os.path.join(path, "unet", "diffusion_pytorch_model.safetensors")
    save_file({k: v.half() for k, v in load_file(wf0).items()}, wf0)
    vae.save_pretrained(os.path.join(path, "vae"), safe_serialization=True)
    sched.save_pretrained(os.path.join(path, "scheduler"))
    with open(os.path.join(path, "model_index.json"), "w") as f:
        json.dump(
            {
                "_class_name": "StableDiffusionPipeline",
                "_diffusers_version": diffusers.__version__,
                "scheduler": ["diffusers", "DDIMScheduler"],
                "text_encoder": ["transformers", "CLIPTextModel"],
                "tokenizer": ["transformers", "CLIPTokenizer"],
                "unet": ["diffusers", "UNet2DConditionModel"],
                "vae": ["diffusers", "AutoencoderKL"],
                "safety_checker": [None, None],
                "feature_extractor": [None, None],
                "requires_safety_checker": False,
            },
            f,
            indent=2,
        )

    refs = {}
    ids_c, cond = embed(tok, text, "a red cat")
    ids_u, uncond = embed(tok, text, "")
    refs["text.ids_cond"] = ids_c.to(torch.int64)
    refs["text.ids_uncond"] = ids_u.to(torch.int64)
    refs["text.cond"] = cond
    refs["text.uncond"] = uncond

    z = randn(1, 4, 16, 16, seed=100)
    refs["unet.z"] = z
    for t in timesteps:
        refs[f"unet.cond.t{t}"] = unet(z, t, encoder_hidden_states=cond).sample
        refs[f"unet.guided.t{t}"] = guided(unet, z, t, cond, uncond, guidance)

    # The same UNet with the tanh approximation of GELU in its GEGLU (diffusers: exact erf; the
    # tanh one is what candle-transformers' UNet computes): the Rust tests check that our UNet
    # is clearly closer to the exact reference than to this one.
    from diffusers.models import activations
    exact_gelu = activations.GEGLU.gelu
    activations.GEGLU.gelu = lambda self, gate: torch.nn.functional.gelu(gate, approximate="tanh")
    for t in timesteps:
        refs[f"unet_tanh.cond.t{t}"] = unet(z, t, encoder_hidden_states=cond).sample
        refs[f"unet_tanh.guided.t{t}"] = guided(unet, z, t, cond, uncond, guidance)
    activations.GEGLU.gelu = exact_gelu

    # VAE: encode (mean/logvar), decode; images in [0,1] are mapped to [-1,1] like the pipeline.
    img = torch.rand(1, 3, 32, 32, generator=torch.Generator().manual_seed(101))
    refs["vae.image"] = img
    dist = vae.encode(img * 2 - 1).latent_dist
    refs["vae.mean"] = dist.mean
    refs["vae.logvar"] = dist.logvar
    zl = randn(1, 4, 16, 16, seed=102)
    refs["vae.z"] = zl
    refs["vae.decoded"] = vae.decode(zl / vae.config.scaling_factor).sample  # raw, in ~[-1,1]

    # Encoder VJP: latents = scaling * mean(2x-1); d_image = J^T d_latents (input only).
    d_lat = randn(1, 4, 16, 16, seed=103)
    refs["vjp.d_latents"] = d_lat
    with torch.enable_grad():
        x = img.clone().requires_grad_(True)
        for p in vae.parameters():
            p.requires_grad_(False)
        lat = vae.encode(x * 2 - 1).latent_dist.mean * vae.config.scaling_factor
        (lat * d_lat).sum().backward()
    refs["vjp.latents"] = lat.detach()
    refs["vjp.d_image"] = x.grad

    # DDIM trajectory with CFG (3 steps, eta = 0).
    s = ddim_sched("epsilon")
    s.set_timesteps(3)
    lat = randn(1, 4, 16, 16, seed=104)
    refs["ddim.init"] = lat
    for i, t in enumerate(s.timesteps):
        eps = guided(unet, lat, t, cond, uncond, guidance)
        lat = s.step(eps, t, lat, eta=0.0).prev_sample
        refs[f"ddim.step{i}"] = lat
    refs["ddim.timesteps"] = s.timesteps.to(torch.int64)

    # Euler (SD-Turbo style: trailing spacing) trajectory with CFG.
    e = EulerDiscreteScheduler(
        num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear",
        timestep_spacing="trailing", prediction_type="epsilon", steps_offset=1,
    )
    e.set_timesteps(2)
    lat = randn(1, 4, 16, 16, seed=105)
    refs["euler.init"] = lat
    lat = lat * e.init_noise_sigma
    for i, t in enumerate(e.timesteps):
        inp = e.scale_model_input(lat, t)
        eps = guided(unet, inp, t, cond, uncond, guidance)
        lat = e.step(eps, t, lat).prev_sample
        refs[f"euler.step{i}"] = lat
    refs["euler.timesteps"] = e.timesteps.to(torch.float32)
    refs["euler.sigmas"] = e.sigmas.to(torch.float32)

    # One full SDS image-space gradient (VectorFusion/DreamFusion: w(t) = 1 - alpha_bar_t).
    t_sds = 600
    ac = s.alphas_cumprod[t_sds]
    noise = randn(1, 4, 16, 16, seed=106)
    refs["sds.noise"] = noise
    with torch.enable_grad():
        x = img.clone().requires_grad_(True)
        lat = vae.encode(x * 2 - 1).latent_dist.mean * vae.config.scaling_factor
        z_t = ac.sqrt() * lat.detach() + (1 - ac).sqrt() * noise
        with torch.no_grad():
            eps_hat = guided(unet, z_t, t_sds, cond, uncond, guidance)
        grad = (1 - ac) * (eps_hat - noise)
        (lat * grad).sum().backward()
    refs["sds.grad_latents"] = grad
    refs["sds.d_image"] = x.grad
    refs["sched.alphas_cumprod"] = s.alphas_cumprod.to(torch.float32)
    save_file({k: v.contiguous().float() if v.dtype != torch.int64 else v.contiguous() for k, v in refs.items()},
              os.path.join(path, "refs.safetensors"))
    with open(os.path.join(path, "refs.json"), "w") as f:
        json.dump({"timesteps": timesteps, "guidance": guidance, "sds_t": t_sds, "prompt": "a red cat",
                   "ddim_steps": 3, "euler_steps": 2}, f, indent=2)

    # ---------------- sd-tiny-v (SD 2.x style, v_prediction, fp16 weights variant) ----------------
    pv = os.path.join(ROOT, "sd-tiny-v")
    fresh(pv)
    unet_v = unet_tiny(sd2=True)
    unet_v = unet_v.half().float()  # the reference uses exactly the fp16-rounded weights
    unet_v.save_pretrained(os.path.join(pv, "unet"), safe_serialization=True, variant="fp16")
    # rewrite the weights file as real fp16 data (variant file name kept)
    from safetensors.torch import load_file
    wf = os.path.join(pv, "unet", "diffusion_pytorch_model.fp16.safetensors")
    save_file({k: v.half() for k, v in load_file(wf).items()}, wf)
    sv = ddim_sched("v_prediction")
    sv.save_pretrained(os.path.join(pv, "scheduler"))
    refs_v = {"unet.z": z, "text.cond": cond, "text.uncond": uncond}
    for t in timesteps:
        out = guided(unet_v, z, t, cond, uncond, guidance)
        refs_v[f"unet.guided.t{t}"] = out
        refs_v[f"unet.eps.t{t}"] = to_eps(out, z, sv.alphas_cumprod[t], "v_prediction")
    save_file({k: v.contiguous().float() for k, v in refs_v.items()}, os.path.join(pv, "refs.safetensors"))

    # ---------------- taesd-tiny ----------------
    pt = os.path.join(ROOT, "taesd-tiny")
    fresh(pt)
    torch.manual_seed(5)
    taesd = perturb(
        AutoencoderTiny(
            encoder_block_out_channels=(8, 8, 8, 8),
            decoder_block_out_channels=(8, 8, 8, 8),
            num_encoder_blocks=(1, 2, 2, 2),
            num_decoder_blocks=(2, 2, 2, 1),
            latent_channels=4,
        ),
        seed=15,
    )
    taesd.save_pretrained(pt, safe_serialization=True)
    refs_t = {"image": img}
    with torch.enable_grad():
        x = img.clone().requires_grad_(True)
        for p in taesd.parameters():
            p.requires_grad_(False)
        lat = taesd.encode(x * 2 - 1).latents
        d = randn(*lat.shape, seed=107)
        (lat * d).sum().backward()
    refs_t["latents"] = lat.detach()
    refs_t["d_latents"] = d
    refs_t["d_image"] = x.grad
    zt = randn(1, 4, 4, 4, seed=108)
    refs_t["z"] = zt
    refs_t["decoded"] = taesd.decode(zt).sample  # in [-1,1] convention
    save_file({k: v.contiguous().float() for k, v in refs_t.items()}, os.path.join(pt, "refs.safetensors"))

    total = 0
    for d in (path, pv, pt):
        for r, _, fs in os.walk(d):
            total += sum(os.path.getsize(os.path.join(r, f)) for f in fs)
    print(f"fixtures written, {total / 1e6:.2f} MB total")


if __name__ == "__main__":
    main()
