#!/usr/bin/env python3
"""PyTorch (CPU, fp32) side of `vectorfusion bench models`: the same full-size architectures
with random weights, same inputs, median wall time per component. Optional; needs the venv.

  /work/venv/bin/python scripts/bench_models_torch.py --arch sd15 --size 256 --reps 3 --json

--arch sdxl: the SDXL base UNet (pooled-text and size/crop conditioning) and its VAE (SD's
architecture); the text encoders are not timed, as on the Rust side.
"""

import argparse
import json
import statistics
import time

import torch
from diffusers import AutoencoderKL, AutoencoderTiny, UNet2DConditionModel
from transformers import CLIPTextConfig, CLIPTextModel


CPU = {}


def timed(fn, reps, key=None, warmup=1):
    """Median wall ms; process CPU ms per run (user + system) goes to CPU[key]."""
    for _ in range(warmup):
        fn()
    ts = []
    c0 = time.process_time()
    for _ in range(max(1, reps)):
        t0 = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) * 1e3)
    if key:
        CPU[key] = (time.process_time() - c0) * 1e3 / max(1, reps)
    return statistics.median(ts)


def unet_for(arch, s):
    """The full-size UNet of `arch` (random weights), a batch-2 context and the added
    conditioning (SDXL: random pooled embeddings, the size time ids of `s` px; else None)."""
    if arch == "sdxl":
        unet = UNet2DConditionModel(
            block_out_channels=(320, 640, 1280),
            down_block_types=("DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"),
            up_block_types=("CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "UpBlock2D"),
            cross_attention_dim=2048,
            attention_head_dim=[5, 10, 20],
            transformer_layers_per_block=[1, 2, 10],
            use_linear_projection=True,
            addition_embed_type="text_time",
            addition_time_embed_dim=256,
            projection_class_embeddings_input_dim=2816,
            sample_size=s // 8,
        ).eval()
        ids = torch.tensor([[s, s, 0, 0, s, s]], dtype=torch.float32).repeat(2, 1)
        added = {"text_embeds": torch.randn(2, 1280), "time_ids": ids}
        return unet, torch.randn(2, 77, 2048), added
    sd21 = arch == "sd21"
    unet = UNet2DConditionModel(
        block_out_channels=(320, 640, 1280, 1280),
        cross_attention_dim=1024 if sd21 else 768,
        attention_head_dim=[5, 10, 20, 20] if sd21 else 8,
        use_linear_projection=sd21,
        sample_size=s // 8,
    ).eval()
    return unet, torch.randn(2, 77, 1024 if sd21 else 768), None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--arch", choices=["sd15", "sd21", "sdxl", "taesd"], default="sd15")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--unet-reps", type=int, default=1)
    ap.add_argument("--warmup", type=int, default=1)
    ap.add_argument("--only", default="")
    ap.add_argument("--unet-precision", choices=["f32", "bf16"], default="f32",
                    help="the UNet's weights and activations (bf16: the baseline for bf16 compute)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    only = [x for x in a.only.split(",") if x]
    want = lambda c: not only or c in only
    torch.manual_seed(0)
    s = a.size
    img = torch.rand(1, 3, s, s)
    lat = torch.randn(1, 4, s // 8, s // 8)
    r = {"arch": a.arch, "size": s, "threads": torch.get_num_threads(), "torch": torch.__version__}

    if a.arch == "taesd":
        vae = AutoencoderTiny().eval()
        enc = lambda x: vae.encode(x * 2 - 1).latents
        dec = lambda z: vae.decode(z).sample
    else:
        vae = AutoencoderKL(
            block_out_channels=(128, 256, 512, 512),
            down_block_types=("DownEncoderBlock2D",) * 4,
            up_block_types=("UpDecoderBlock2D",) * 4,
            layers_per_block=2,
            latent_channels=4,
            sample_size=512,
        ).eval()
        enc = lambda x: vae.encode(x * 2 - 1).latent_dist.mean * 0.18215
        dec = lambda z: vae.decode(z / 0.18215).sample
    for p in vae.parameters():
        p.requires_grad_(False)

    if want("encoder"):
        with torch.no_grad():
            r["encoder_fwd_ms"] = timed(lambda: enc(img), a.reps, "encoder_fwd", a.warmup)
    if want("vjp"):
        def vjp():
            x = img.clone().requires_grad_(True)
            (enc(x) * lat).sum().backward()
            return x.grad
        r["encoder_vjp_ms"] = timed(vjp, a.reps, "encoder_vjp", a.warmup)
    if want("decoder"):
        with torch.no_grad():
            r["decoder_ms"] = timed(lambda: dec(lat), a.reps, "decoder", a.warmup)

    if a.arch != "taesd":
        sd21 = a.arch == "sd21"
        if want("text") and a.arch != "sdxl":
            cfg = (
                CLIPTextConfig(hidden_size=1024, intermediate_size=4096, num_hidden_layers=23,
                               num_attention_heads=16, hidden_act="gelu", projection_dim=512)
                if sd21
                else CLIPTextConfig(hidden_size=768, intermediate_size=3072, num_hidden_layers=12,
                                    num_attention_heads=12, hidden_act="quick_gelu", projection_dim=768)
            )
            te = CLIPTextModel(cfg).eval()
            ids = torch.full((1, 77), 49407, dtype=torch.long)
            ids[0, 0] = 49406
            with torch.no_grad():
                r["text_ms"] = timed(lambda: te(ids), a.reps, "text", a.warmup)
        if want("unet"):
            unet, ctx, added = unet_for(a.arch, s)
            z2 = torch.cat([lat, lat])
            if a.unet_precision == "bf16":
                bf = torch.bfloat16
                unet, ctx, z2 = unet.to(bf), ctx.to(bf), z2.to(bf)
                if added:
                    added = {k: v.to(bf) for k, v in added.items()}
            r["unet_precision"] = a.unet_precision

            def step():
                out = unet(z2, 500, encoder_hidden_states=ctx, added_cond_kwargs=added).sample
                u, c = out.chunk(2)
                return u + 7.5 * (c - u)

            with torch.no_grad():
                r["unet_cfg_ms"] = timed(step, a.unet_reps, "unet_cfg", a.warmup)
    r["cpu_ms"] = CPU
    print(json.dumps(r) if a.json else r)


if __name__ == "__main__":
    main()
