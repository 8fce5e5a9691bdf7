#!/usr/bin/env python3
"""Tiny pixel-space diffusion fixture (docs/EMBEDDED.md layout: no vae/) and the TAESD SDS
reference, with reference outputs from diffusers (torch, CPU, fp32).

Run with the project venv after scripts/make_sd_fixtures.py:
    /work/venv/bin/python scripts/make_pixel_fixtures.py
Reads tests/fixtures/sd-tiny (text encoder + tokenizer are copied; its UNet is used for the TAESD
reference) and tests/fixtures/taesd-tiny. Writes (committed, small):
  tests/fixtures/sd-tiny-pixel/   model_index.json (no "vae"), unet/ (in/out 3 channels,
                                  sample_size 16, fp16 weights file), scheduler/ (DDIM,
                                  squaredcos_cap_v2, epsilon), text_encoder/, tokenizer/,
                                  refs.safetensors
  tests/fixtures/taesd-tiny/sds_refs.safetensors   one SDS image gradient with TAESD as the
                                  encoder in front of the sd-tiny UNet
The Rust tests (tests/models_pixel.rs, tests/sds_sd.rs) compare against these.
"""

import json
import os
import shutil

import torch
import torch.nn.functional as F
from safetensors.torch import load_file, save_file

import diffusers
from diffusers import AutoencoderTiny, DDIMScheduler, UNet2DConditionModel
from transformers import CLIPTextModel, CLIPTokenizer

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures")
torch.set_grad_enabled(False)
SIZE = 16


def perturb(model, seed, scale=0.05):
    g = torch.Generator().manual_seed(seed)
    for p in model.parameters():
        p.add_(torch.randn(p.shape, generator=g) * scale)
    model.eval()
    return model


def randn(*shape, seed):
    return torch.randn(*shape, generator=torch.Generator().manual_seed(seed))


def guided(unet, z, t, cond, uncond, g):
    out = unet(torch.cat([z, z]), t, encoder_hidden_states=torch.cat([uncond, cond])).sample
    u, c = out.chunk(2)
    return u + g * (c - u)


def area_encode(x01):
    return F.interpolate(x01, size=(SIZE, SIZE), mode="area") * 2 - 1


def tanh_gelu():
    from diffusers.models import activations

    exact = activations.GEGLU.gelu
    activations.GEGLU.gelu = lambda self, gate: F.gelu(gate, approximate="tanh")
    return lambda: setattr(activations.GEGLU, "gelu", exact)


def main():
    print("diffusers", diffusers.__version__, "torch", torch.__version__)
    src = os.path.join(ROOT, "sd-tiny")
    path = os.path.join(ROOT, "sd-tiny-pixel")
    shutil.rmtree(path, ignore_errors=True)
    os.makedirs(path)
    for d in ("text_encoder", "tokenizer"):
        shutil.copytree(os.path.join(src, d), os.path.join(path, d))
    tok = CLIPTokenizer.from_pretrained(os.path.join(path, "tokenizer"))
    text = CLIPTextModel.from_pretrained(os.path.join(path, "text_encoder")).eval()

    torch.manual_seed(21)
    unet = perturb(
        UNet2DConditionModel(
            sample_size=SIZE,
            in_channels=3,
            out_channels=3,
            down_block_types=("CrossAttnDownBlock2D", "DownBlock2D"),
            up_block_types=("UpBlock2D", "CrossAttnUpBlock2D"),
            block_out_channels=(32, 64),
            layers_per_block=1,
            norm_num_groups=32,
            cross_attention_dim=16,
            attention_head_dim=2,
        ),
        seed=22,
    )
    unet = unet.half().float()  # references use exactly the fp16-rounded weights
    unet.save_pretrained(os.path.join(path, "unet"), safe_serialization=True)
    wf = os.path.join(path, "unet", "diffusion_pytorch_model.safetensors")
    save_file({k: v.half() for k, v in load_file(wf).items()}, wf)
    sched = DDIMScheduler(
        num_train_timesteps=1000,
        beta_schedule="squaredcos_cap_v2",
        prediction_type="epsilon",
        clip_sample=False,
        set_alpha_to_one=False,
        steps_offset=0,
        timestep_spacing="leading",
    )
    sched.save_pretrained(os.path.join(path, "scheduler"))
    with open(os.path.join(path, "model_index.json"), "w") as f:
        json.dump(
            {
                "_class_name": "VectorFusionPixelPipeline",
                "_diffusers_version": diffusers.__version__,
                "scheduler": ["diffusers", "DDIMScheduler"],
                "text_encoder": ["transformers", "CLIPTextModel"],
                "tokenizer": ["transformers", "CLIPTokenizer"],
                "unet": ["diffusers", "UNet2DConditionModel"],
            },
            f,
            indent=2,
        )

    def embed(prompt):
        ids = tok([prompt], padding="max_length", max_length=77, truncation=True, return_tensors="pt").input_ids
        return text(ids)[0]

    refs = {}
    cond, uncond = embed("a red cat"), embed("")
    refs["text.cond"], refs["text.uncond"] = cond, uncond
    guidance = 7.5
    z = randn(1, 3, SIZE, SIZE, seed=200)
    refs["unet.z"] = z
    for t in (999, 500, 10):
        refs[f"unet.cond.t{t}"] = unet(z, t, encoder_hidden_states=cond).sample
        refs[f"unet.guided.t{t}"] = guided(unet, z, t, cond, uncond, guidance)
    restore = tanh_gelu()
    for t in (999, 500, 10):
        refs[f"unet_tanh.guided.t{t}"] = guided(unet, z, t, cond, uncond, guidance)
    restore()

    # 4-step DDIM from fixed noise with CFG (eta = 0).
    s = DDIMScheduler.from_pretrained(os.path.join(path, "scheduler"))
    s.set_timesteps(4)
    x = randn(1, 3, SIZE, SIZE, seed=201)
    refs["ddim.init"] = x
    for i, t in enumerate(s.timesteps):
        x = s.step(guided(unet, x, t, cond, uncond, guidance), t, x, eta=0.0).prev_sample
        refs[f"ddim.step{i}"] = x
    refs["ddim.timesteps"] = s.timesteps.to(torch.int64)
    refs["sched.alphas_cumprod"] = s.alphas_cumprod.to(torch.float32)

    # Pixel "encode": area resize to sample_size, x*2-1 (integer and non-integer ratios) + VJP.
    for side in (64, 40):
        img = torch.rand(1, 3, side, side, generator=torch.Generator().manual_seed(202 + side))
        refs[f"encode.image{side}"] = img
        with torch.enable_grad():
            xi = img.clone().requires_grad_(True)
            lat = area_encode(xi)
            d = randn(1, 3, SIZE, SIZE, seed=203)
            (lat * d).sum().backward()
        refs[f"encode.latents{side}"] = lat.detach()
        refs[f"encode.d_image{side}"] = xi.grad
    refs["encode.d_latents"] = randn(1, 3, SIZE, SIZE, seed=203)

    # One SDS image gradient at t = 600, CFG 7.5, w = 1 - alpha_bar, on a 64 px image.
    img = refs["encode.image64"]
    ac = s.alphas_cumprod[600]
    noise = randn(1, 3, SIZE, SIZE, seed=204)
    refs["sds.noise"] = noise
    with torch.enable_grad():
        xi = img.clone().requires_grad_(True)
        lat = area_encode(xi)
        z_t = ac.sqrt() * lat.detach() + (1 - ac).sqrt() * noise
        with torch.no_grad():
            eps = guided(unet, z_t, 600, cond, uncond, guidance)
        grad = (1 - ac) * (eps - noise)
        (lat * grad).sum().backward()
    refs["sds.grad_latents"] = grad
    refs["sds.d_image"] = xi.grad
    save_file({k: v.contiguous().float() if v.dtype != torch.int64 else v.contiguous() for k, v in refs.items()},
              os.path.join(path, "refs.safetensors"))

    # ---------------- TAESD as the SDS encoder of sd-tiny ----------------
    sd_unet = UNet2DConditionModel.from_pretrained(os.path.join(src, "unet")).float().eval()
    sd_refs = load_file(os.path.join(src, "refs.safetensors"))
    sd_sched = DDIMScheduler.from_pretrained(os.path.join(src, "scheduler"))
    taesd = AutoencoderTiny.from_pretrained(os.path.join(ROOT, "taesd-tiny")).float().eval()
    for p in taesd.parameters():
        p.requires_grad_(False)
    img = torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(210))
    ac = sd_sched.alphas_cumprod[600]
    noise = randn(1, 4, 8, 8, seed=211)
    with torch.enable_grad():
        xi = img.clone().requires_grad_(True)
        lat = taesd.encode(xi * 2 - 1).latents
        z_t = ac.sqrt() * lat.detach() + (1 - ac).sqrt() * noise
        with torch.no_grad():
            eps = guided(sd_unet, z_t, 600, sd_refs["text.cond"], sd_refs["text.uncond"], guidance)
        grad = (1 - ac) * (eps - noise)
        (lat * grad).sum().backward()
    save_file(
        {"image": img, "noise": noise, "latents": lat.detach().contiguous(), "grad_latents": grad.contiguous(),
         "d_image": xi.grad.contiguous()},
        os.path.join(ROOT, "taesd-tiny", "sds_refs.safetensors"),
    )

    total = 0
    for r, _, fs in os.walk(path):
        total += sum(os.path.getsize(os.path.join(r, f)) for f in fs)
    print(f"sd-tiny-pixel written, {total / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
