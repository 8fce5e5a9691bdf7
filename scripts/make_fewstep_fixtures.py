#!/usr/bin/env python3
"""Reference trajectories of the few-step samplers on the tiny Stable Diffusion fixture, computed
with diffusers (torch, CPU, fp32): Euler ancestral with trailing spacing and no guidance (how
SD-Turbo / SDXL-Turbo sample) and LCM with light guidance. The noise each stochastic step adds
is recorded, so the Rust test replays the same steps.

Run with a venv holding torch, diffusers and safetensors:
    python scripts/make_fewstep_fixtures.py
Output (committed, small): tests/fixtures/sd-tiny/refs_fewstep.safetensors
"""

import os

import torch
from safetensors.torch import load_file, save_file

import diffusers.schedulers.scheduling_euler_ancestral_discrete as ea_module
import diffusers.schedulers.scheduling_lcm as lcm_module
from diffusers import (
    DDIMScheduler,
    EulerAncestralDiscreteScheduler,
    LCMScheduler,
    UNet2DConditionModel,
)

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures", "sd-tiny")
torch.set_grad_enabled(False)


def trajectory(name, scheduler, module, steps, guidance, seed, unet, cond, uncond, out):
    """Runs `steps` steps of `scheduler` from seeded noise; records init, step noises, latents."""
    scheduler.set_timesteps(steps)
    g = torch.Generator().manual_seed(seed)
    shape = (1, unet.config.in_channels, unet.config.sample_size, unet.config.sample_size)
    init = torch.randn(shape, generator=g)
    noises = []

    def recorded_randn(shape, generator=None, device=None, dtype=None, layout=None):
        z = torch.randn(shape, generator=g)
        noises.append(z)
        return z

    module.randn_tensor = recorded_randn
    x = init * scheduler.init_noise_sigma
    for i, t in enumerate(scheduler.timesteps):
        inp = scheduler.scale_model_input(x, t)
        if guidance > 1.0:
            both = unet(torch.cat([inp, inp]), t, encoder_hidden_states=torch.cat([uncond, cond])).sample
            u, c = both.chunk(2)
            pred = u + guidance * (c - u)
        else:
            pred = unet(inp, t, encoder_hidden_states=cond).sample
        x = scheduler.step(pred, t, x, generator=g).prev_sample
        out[f"{name}.step{i}"] = x.contiguous()
    out[f"{name}.init"] = init
    out[f"{name}.timesteps"] = scheduler.timesteps.to(torch.float32)
    for i, z in enumerate(noises):
        out[f"{name}.noise{i}"] = z.contiguous()
    print(name, "timesteps", scheduler.timesteps.tolist(), "noises", len(noises))


def main():
    unet = UNet2DConditionModel.from_pretrained(os.path.join(ROOT, "unet")).eval()
    refs = load_file(os.path.join(ROOT, "refs.safetensors"))
    cond, uncond = refs["text.cond"], refs["text.uncond"]
    config = DDIMScheduler.from_pretrained(ROOT, subfolder="scheduler").config
    out = {}
    ea = EulerAncestralDiscreteScheduler.from_config(config, timestep_spacing="trailing")
    trajectory("ea", ea, ea_module, 2, 0.0, 21, unet, cond, uncond, out)
    lcm = LCMScheduler.from_config(config)
    trajectory("lcm", lcm, lcm_module, 4, 1.5, 22, unet, cond, uncond, out)
    save_file(out, os.path.join(ROOT, "refs_fewstep.safetensors"))


if __name__ == "__main__":
    main()
