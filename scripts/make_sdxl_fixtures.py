#!/usr/bin/env python3
"""Build a tiny random-weight SDXL pipeline in the diffusers layout (the real SDXL config keys at
tiny widths) and save reference outputs computed with diffusers/transformers (torch, CPU, fp32).

Run with the fixture venv:  /work/venv-torch/bin/python scripts/make_sdxl_fixtures.py
Output (committed, small): tests/fixtures/sdxl-tiny/
  model_index.json (StableDiffusionXLPipeline), unet/ (text_time added conditioning, per-block
  transformer depth, linear projections, fp16 weights), text_encoder/ (CLIPTextModel),
  text_encoder_2/ (CLIPTextModelWithProjection), tokenizer/, tokenizer_2/ (pads with "!"),
  vae/ (scaling_factor 0.13025), scheduler/ (SDXL's Euler, leading spacing),
  refs.safetensors (reference tensors), refs.json (scalars).
The Rust tests (tests/models_sdxl.rs) compare against these; Python is never needed by CI.
"""

import json
import os
import sys

import torch
from safetensors.torch import load_file, save_file

import diffusers
from diffusers import EulerDiscreteScheduler, UNet2DConditionModel
from transformers import CLIPTextConfig, CLIPTextModel, CLIPTextModelWithProjection, CLIPTokenizer

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_sd_fixtures import ROOT, fresh, perturb, randn, text_tiny, vae_tiny  # noqa: E402

torch.set_grad_enabled(False)

TE1, TE2, PROJ, TIME_DIM = 16, 32, 32, 8
CROSS = TE1 + TE2


def unet_tiny():
    torch.manual_seed(21)
    unet = UNet2DConditionModel(
        sample_size=16,
        in_channels=4,
        out_channels=4,
        down_block_types=("DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"),
        up_block_types=("CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "UpBlock2D"),
        block_out_channels=(32, 32, 64),
        layers_per_block=2,
        transformer_layers_per_block=(1, 2, 2),
        attention_head_dim=(2, 2, 4),
        norm_num_groups=32,
        cross_attention_dim=CROSS,
        use_linear_projection=True,
        addition_embed_type="text_time",
        addition_time_embed_dim=TIME_DIM,
        projection_class_embeddings_input_dim=PROJ + 6 * TIME_DIM,
        upcast_attention=None,
    )
    return perturb(unet, seed=22).half().float()


def text2_tiny(path):
    """tokenizer_2 (the same vocabulary, padded with "!" as SDXL's) and a CLIPTextModelWithProjection."""
    tok_dir = os.path.join(path, "tokenizer_2")
    src = os.path.join(path, "tokenizer")
    tok = CLIPTokenizer(os.path.join(src, "vocab.json"), os.path.join(src, "merges.txt"),
                        model_max_length=77, pad_token="!")
    tok.save_pretrained(tok_dir)
    torch.manual_seed(23)
    vocab = tok.get_vocab()
    cfg = CLIPTextConfig(
        vocab_size=len(vocab), hidden_size=TE2, intermediate_size=45, num_hidden_layers=3,
        num_attention_heads=4, max_position_embeddings=77, projection_dim=PROJ, hidden_act="gelu",
        # SDXL's text_encoder_2 carries the legacy eos_token_id 2 (pooled token = largest id)
        bos_token_id=0, eos_token_id=2, pad_token_id=1,
    )
    model = perturb(CLIPTextModelWithProjection(cfg), seed=24)
    model.save_pretrained(os.path.join(path, "text_encoder_2"), safe_serialization=True)
    return tok, model


def time_ids(side):
    # original size, crop top-left, target size (pixels)
    return torch.tensor([[side, side, 0, 0, side, side]], dtype=torch.float32)


def main():
    print("diffusers", diffusers.__version__, "torch", torch.__version__)
    path = os.path.join(ROOT, "sdxl-tiny")
    fresh(path)
    unet = unet_tiny()
    unet.save_pretrained(os.path.join(path, "unet"), safe_serialization=True)
    wf = os.path.join(path, "unet", "diffusion_pytorch_model.safetensors")
    save_file({k: v.half() for k, v in load_file(wf).items()}, wf)
    torch.manual_seed(25)
    vae = vae_tiny()
    vae.register_to_config(scaling_factor=0.13025, force_upcast=True)
    vae.save_pretrained(os.path.join(path, "vae"), safe_serialization=True)
    tok1, te1 = text_tiny(path)
    tok2, te2 = text2_tiny(path)
    sched = EulerDiscreteScheduler(
        num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear",
        timestep_spacing="leading", steps_offset=1, prediction_type="epsilon",
        interpolation_type="linear", use_karras_sigmas=False,
    )
    sched.save_pretrained(os.path.join(path, "scheduler"))
    index = {
        "_class_name": "StableDiffusionXLPipeline",
        "_diffusers_version": diffusers.__version__,
        "force_zeros_for_empty_prompt": True,
        "scheduler": ["diffusers", "EulerDiscreteScheduler"],
        "text_encoder": ["transformers", "CLIPTextModel"],
        "text_encoder_2": ["transformers", "CLIPTextModelWithProjection"],
        "tokenizer": ["transformers", "CLIPTokenizer"],
        "tokenizer_2": ["transformers", "CLIPTokenizer"],
        "unet": ["diffusers", "UNet2DConditionModel"],
        "vae": ["diffusers", "AutoencoderKL"],
    }
    with open(os.path.join(path, "model_index.json"), "w") as f:
        json.dump(index, f, indent=2)

    refs = {}
    prompt = "a red cat"
    # StableDiffusionXLPipeline.encode_prompt (diffusers 0.31; the pipeline class itself does not
    # import beside this transformers version): penultimate states of both encoders concatenated,
    # text_encoder_2's projected pooled output; force_zeros_for_empty_prompt gives zero negatives
    def encode(text):
        states, pooled = [], None
        for tok, te in ((tok1, te1), (tok2, te2)):
            ids = tok([text], padding="max_length", max_length=77, truncation=True, return_tensors="pt").input_ids
            out = te(ids, output_hidden_states=True)
            pooled = out[0]
            states.append(out.hidden_states[-2])
        return torch.cat(states, dim=-1), pooled

    ctx, pooled = encode(prompt)
    neg, neg_pooled = torch.zeros_like(ctx), torch.zeros_like(pooled)
    for name, tok in (("ids1", tok1), ("ids2", tok2)):
        refs[f"text.{name}"] = tok([prompt], padding="max_length", max_length=77, truncation=True,
                                   return_tensors="pt").input_ids.to(torch.int64)
    refs["text.context"] = ctx
    refs["text.pooled"] = pooled
    # and the empty prompt, encoded (what a model without force_zeros would use)
    refs["text.context_empty"], refs["text.pooled_empty"] = encode("")

    side = 16 * 2 ** (len(vae.config.block_out_channels) - 1)  # pixels
    tid = time_ids(side)
    refs["unet.time_ids"] = tid
    z = randn(1, 4, 16, 16, seed=200)
    refs["unet.z"] = z
    # a second, different size/crop conditioning (checks every time id enters)
    tid2 = torch.tensor([[40.0, 24.0, 3.0, 5.0, 32.0, 48.0]])
    refs["unet.time_ids2"] = tid2
    timesteps = [999, 500, 10]
    for t in timesteps:
        cond = {"text_embeds": pooled, "time_ids": tid}
        refs[f"unet.cond.t{t}"] = unet(z, t, encoder_hidden_states=ctx, added_cond_kwargs=cond).sample
        cond2 = {"text_embeds": pooled, "time_ids": tid2}
        refs[f"unet.cond2.t{t}"] = unet(z, t, encoder_hidden_states=ctx, added_cond_kwargs=cond2).sample

    # guided Euler trajectory, driven as StableDiffusionXLPipeline.__call__ does (negative time ids
    # = the positive ones)
    guidance, steps = 5.0, 3
    init = randn(1, 4, 16, 16, seed=201)
    refs["traj.init"] = init
    s = EulerDiscreteScheduler.from_config(sched.config)
    s.set_timesteps(steps)
    lat = init * s.init_noise_sigma
    c2 = torch.cat([neg, ctx])
    p2 = torch.cat([neg_pooled, pooled])
    t2 = torch.cat([tid, tid])
    for i, t in enumerate(s.timesteps):
        inp = s.scale_model_input(torch.cat([lat, lat]), t)
        out = unet(inp, t, encoder_hidden_states=c2, added_cond_kwargs={"text_embeds": p2, "time_ids": t2}).sample
        u, c = out.chunk(2)
        lat = s.step(u + guidance * (c - u), t, lat).prev_sample
        refs[f"traj.step{i}"] = lat
    refs["traj.timesteps"] = s.timesteps.to(torch.float32)
    save_file({k: v.contiguous().float() if v.dtype != torch.int64 else v.contiguous() for k, v in refs.items()},
              os.path.join(path, "refs.safetensors"))
    with open(os.path.join(path, "refs.json"), "w") as f:
        json.dump({"timesteps": timesteps, "guidance": guidance, "steps": steps, "prompt": prompt,
                   "image_side": side}, f, indent=2)
    total = 0
    for r, _, fs in os.walk(path):
        total += sum(os.path.getsize(os.path.join(r, f)) for f in fs)
    print(f"sdxl-tiny written, {total / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
