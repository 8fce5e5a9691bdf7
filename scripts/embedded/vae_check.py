"""Reconstruction check of the embedded autoencoder on the 48 held-out Fluent icons of the
evaluation (an artist never trained on): PSNR, signed and absolute colour error on non-white
pixels, and the pixel R-Precision of the reconstructions against the originals.

    python scripts/embedded/vae_check.py [VAE_DIR]      # default models/vf-icon/vae
"""
import sys, os, json, numpy as np, torch
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pixel_rprecision import load_split, first_by_caption, small, rprecision
from diffusers import AutoencoderKL
torch.set_num_threads(2)
vae = AutoencoderKL.from_pretrained(sys.argv[1] if len(sys.argv) > 1 else "models/vf-icon/vae").eval()
raw, caps = load_split("data/icons/eval")
held = [l.strip() for l in open("docs/embedded/heldout_fluent48.txt") if l.strip()]
fl = first_by_caption(raw, caps, "fluent-emoji-flat")
imgs = np.stack([fl[c] for c in held]).astype(np.float32) / 255.0
x = torch.from_numpy(imgs).permute(0, 3, 1, 2) * 2 - 1
with torch.no_grad():
    z = vae.encode(x).latent_dist.mean
    y = vae.decode(z).sample.clamp(-1, 1)
rec = ((y + 1) / 2).permute(0, 2, 3, 1).numpy()
mse = ((rec - imgs) ** 2).mean()
print("held-out fluent PSNR %.2f dB" % (10 * np.log10(1 / mse)))
print("mean signed error per channel (rec - orig):", (rec - imgs).reshape(-1, 3).mean(0))
# colour error on non-white pixels
m = imgs.reshape(-1, 3).min(1) < 0.9
print("signed error on non-white px:", (rec - imgs).reshape(-1, 3)[m].mean(0), "abs", np.abs(rec - imgs).reshape(-1, 3)[m].mean(0))
P = np.stack([small(r) for r in rec]); R = np.stack([small(i) for i in imgs])
print("pixel R-Precision of reconstructions vs originals: %.3f (mean rank %.2f)" % rprecision(P, R))
