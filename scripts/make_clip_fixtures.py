#!/usr/bin/env python3
"""Builds tests/fixtures/clip-tiny: a tiny random-weight CLIP (transformers layout) with a small
but real byte-level BPE vocabulary learned from the benchmark captions, plus reference outputs.

Run from the repository root:  /work/venv/bin/python scripts/make_clip_fixtures.py
Outputs (all committed, no Python needed by `cargo test`):
  config.json, model.safetensors          CLIPModel (text: quick_gelu, vision: gelu)
  vocab.json, merges.txt, tokenizer.json, tokenizer_config.json, special_tokens_map.json?
  preprocessor_config.json                CLIPImageProcessorPil (PIL bicubic)
  text_encoder/{config.json,model.safetensors}  the same text tower as a standalone CLIPTextModel
  images/*.png                            deterministic test images (RGB and RGBA)
  reference/tokens.json                   captions -> input_ids (padding=max_length, truncation)
  reference/outputs.safetensors           hidden states, pooled, embeddings, pixel values, logits
"""
import collections
import json
import os
import sys

import numpy as np
import torch
from PIL import Image
from safetensors.torch import save_file
from transformers import (CLIPConfig, CLIPImageProcessorPil, CLIPModel, CLIPTextModel,
                          CLIPTokenizer)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "tests", "fixtures", "clip-tiny")
PROMPTS = os.path.join(ROOT, "..", "shared", "bench", "svg_bench_prompts.txt")
if not os.path.exists(PROMPTS):
    PROMPTS = "/work/shared/bench/svg_bench_prompts.txt"
N_MERGES = 400


def bytes_to_unicode():
    bs = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(
        range(ord("®"), ord("ÿ") + 1))
    cs = bs[:]
    n = 0
    for b in range(256):
        if b not in bs:
            bs.append(b)
            cs.append(256 + n)
            n += 1
    return dict(zip(bs, [chr(c) for c in cs]))


def main():
    os.makedirs(os.path.join(OUT, "reference"), exist_ok=True)
    os.makedirs(os.path.join(OUT, "images"), exist_ok=True)
    with open(PROMPTS, encoding="utf-8") as f:
        captions = [line.rstrip("\n") for line in f if line.strip()]
    assert len(captions) == 128, len(captions)
    extra = [
        # longer than the 77-token context: truncated keeping <|endoftext|>
        " ".join(captions[:6]),
        "  Mixed   CASE\twhitespace, punctuation!! and numbers 12345 ",
        "it's the dog's toy; they've gone, we'll see, I'd say, you're right, I'm here",
        "café naïve façade 自転車 ÀÉÎ",
    ]
    texts = captions + extra

    # --- a small real BPE vocabulary learned from the captions -------------------------------
    b2u = bytes_to_unicode()
    alphabet = list(b2u.values())
    base = {c: i for i, c in enumerate(alphabet + [c + "</w>" for c in alphabet])}
    base["<|startoftext|>"] = len(base)
    base["<|endoftext|>"] = len(base)
    splitter = CLIPTokenizer(vocab=dict(base), merges=[])
    pre = splitter.backend_tokenizer
    words = collections.Counter()
    for t in captions:
        norm = pre.normalizer.normalize_str(t)
        for piece, _ in pre.pre_tokenizer.pre_tokenize_str(norm):
            sym = list(piece)
            sym[-1] = sym[-1] + "</w>"
            words[tuple(sym)] += 1
    merges = []
    for _ in range(N_MERGES):
        pairs = collections.Counter()
        for w, c in words.items():
            for a, b in zip(w, w[1:]):
                pairs[(a, b)] += c
        if not pairs:
            break
        best = max(pairs.items(), key=lambda kv: (kv[1], kv[0]))[0]
        merges.append(best)
        new = collections.Counter()
        for w, c in words.items():
            out, i = [], 0
            while i < len(w):
                if i + 1 < len(w) and (w[i], w[i + 1]) == best:
                    out.append(w[i] + w[i + 1])
                    i += 2
                else:
                    out.append(w[i])
                    i += 1
            new[tuple(out)] += c
        words = new
    vocab_list = alphabet + [c + "</w>" for c in alphabet] + ["".join(m) for m in merges]
    vocab_list += ["<|startoftext|>", "<|endoftext|>"]
    vocab = {}
    for t in vocab_list:  # a merge can repeat a symbol already present; keep first id (as CLIP)
        vocab.setdefault(t, len(vocab))
    with open(os.path.join(OUT, "vocab.json"), "w", encoding="utf-8") as f:
        json.dump(vocab, f, ensure_ascii=False)
    with open(os.path.join(OUT, "merges.txt"), "w", encoding="utf-8") as f:
        f.write("#version: 0.2\n")
        for a, b in merges:
            f.write(f"{a} {b}\n")
    tok = CLIPTokenizer(vocab=vocab, merges=list(merges), model_max_length=77)
    tok.save_pretrained(OUT)
    tok = CLIPTokenizer.from_pretrained(OUT)
    assert tok.model_max_length == 77
    enc = tok(texts, padding="max_length", max_length=77, truncation=True)
    ids = enc["input_ids"]
    assert all(len(r) == 77 for r in ids)
    unpadded = [tok(t)["input_ids"] for t in texts]
    assert max(len(r) for r in unpadded) > 77, "need one caption longer than the context"
    with open(os.path.join(OUT, "reference", "tokens.json"), "w", encoding="utf-8") as f:
        json.dump({"texts": texts, "input_ids": ids,
                   "unpadded_lengths": [len(r) for r in unpadded],
                   "pad_token_id": tok.pad_token_id, "eos_token_id": tok.eos_token_id,
                   "bos_token_id": tok.bos_token_id}, f, ensure_ascii=False)

    # --- model --------------------------------------------------------------------------------
    torch.manual_seed(1234)
    V = len(vocab)
    cfg = CLIPConfig(
        text_config=dict(vocab_size=V, hidden_size=32, intermediate_size=64, num_hidden_layers=2,
                         num_attention_heads=2, max_position_embeddings=77, projection_dim=16,
                         hidden_act="quick_gelu", bos_token_id=tok.bos_token_id,
                         eos_token_id=tok.eos_token_id, pad_token_id=tok.pad_token_id),
        vision_config=dict(hidden_size=32, intermediate_size=64, num_hidden_layers=2,
                           num_attention_heads=2, image_size=32, patch_size=4, projection_dim=16,
                           hidden_act="gelu"),
        projection_dim=16,
    )
    model = CLIPModel(cfg).eval()
    with torch.no_grad():  # make every weight matter (layer norms are 1/0 at init)
        for name, p in model.named_parameters():
            if name == "logit_scale":
                continue
            p.add_(torch.randn_like(p) * 0.1)
    model.save_pretrained(OUT, safe_serialization=True)
    text_only = CLIPTextModel(cfg.text_config).eval()
    sd = {k: v for k, v in model.state_dict().items() if k.startswith("text_model.")}
    own = set(text_only.state_dict())
    if not own & set(sd):  # newer transformers keep the text tower at the top level
        sd = {k[len("text_model."):]: v for k, v in sd.items()}
    res = text_only.load_state_dict(sd, strict=False)
    assert not res.unexpected_keys and not res.missing_keys, res
    text_only.save_pretrained(os.path.join(OUT, "text_encoder"), safe_serialization=True)

    proc = CLIPImageProcessorPil(size={"shortest_edge": 32}, crop_size={"height": 32, "width": 32})
    proc.save_pretrained(OUT)

    # --- images -------------------------------------------------------------------------------
    rng = np.random.default_rng(7)
    imgs = {}
    y, x = np.mgrid[0:40, 0:48]
    imgs["gradient_48x40.png"] = Image.fromarray(np.stack(
        [x * 5, y * 6, (x + y) * 3], -1).astype(np.uint8), "RGB")
    a = np.zeros((53, 37, 4), np.uint8)
    a[..., :3] = rng.integers(0, 256, (53, 37, 3))
    yy, xx = np.mgrid[0:53, 0:37]
    a[..., 3] = np.clip(255 - 6 * np.hypot(xx - 18, yy - 26), 0, 255).astype(np.uint8)
    imgs["alpha_37x53.png"] = Image.fromarray(a, "RGBA")
    imgs["noise_32x32.png"] = Image.fromarray(rng.integers(0, 256, (32, 32, 3)).astype(np.uint8),
                                              "RGB")
    big = np.zeros((75, 101, 3), np.uint8)
    big[::2, :, 0] = 255
    big[:, ::3, 1] = 200
    big[20:50, 30:80, 2] = 180
    imgs["stripes_101x75.png"] = Image.fromarray(big, "RGB")
    names = sorted(imgs)
    pil_rgb = []
    for n in names:
        imgs[n].save(os.path.join(OUT, "images", n))
        arr = np.asarray(Image.open(os.path.join(OUT, "images", n)).convert("RGBA"))
        # Composite over white exactly as the Rust side does (f32, premultiplied, round half up).
        f = arr.astype(np.float32) / np.float32(255.0)
        al = f[..., 3:4]
        rgb = f[..., :3] * al + (np.float32(1.0) - al)
        u8 = np.clip(np.floor(rgb * np.float32(255.0) + np.float32(0.5)), 0, 255).astype(np.uint8)
        pil_rgb.append(Image.fromarray(u8, "RGB"))
    pixel_values = proc(images=pil_rgb, return_tensors="pt")["pixel_values"].float()
    assert pixel_values.shape == (len(names), 3, 32, 32), pixel_values.shape

    # --- reference outputs --------------------------------------------------------------------
    ids_t = torch.tensor(ids, dtype=torch.long)
    with torch.no_grad():
        tout = model.text_model(input_ids=ids_t, output_hidden_states=True)
        text_embeds = model.text_projection(tout.pooler_output)
        vout = model.vision_model(pixel_values=pixel_values)
        image_embeds = model.visual_projection(vout.pooler_output)
        full = model(input_ids=ids_t[:8], pixel_values=pixel_values)
        sa = text_only(input_ids=ids_t)
    assert torch.allclose(sa.last_hidden_state, tout.last_hidden_state, atol=1e-6)
    sel = [0, 1, 28, 128, 131]  # includes 自転車 (line 29) and the long caption
    ref = {
        "text_sel": torch.tensor(sel, dtype=torch.long),
        "text_last_hidden_state_sel": tout.last_hidden_state[sel].contiguous(),
        "text_penultimate_sel": tout.hidden_states[-2][sel].contiguous(),
        "text_pooled": tout.pooler_output.contiguous(),
        "text_embeds": text_embeds.contiguous(),
        "pixel_values": pixel_values.contiguous(),
        "vision_pooled": vout.pooler_output.contiguous(),
        "image_embeds": image_embeds.contiguous(),
        "logits_per_image": full.logits_per_image.contiguous(),
    }
    save_file({k: v.detach().clone() for k, v in ref.items()},
              os.path.join(OUT, "reference", "outputs.safetensors"))
    with open(os.path.join(OUT, "reference", "images.json"), "w") as f:
        json.dump({"images": names}, f)
    make_openclip(vocab, merges, texts, tok, names, pil_rgb)
    print("vocab", V, "merges", len(merges), "texts", len(texts), "images", names)
    print("max unpadded length", max(len(r) for r in unpadded))


def make_openclip(vocab, merges, texts, tok, names, pil_rgb):
    """tests/fixtures/openclip-tiny: the same tokenizer, a tiny open_clip CLIP (exact GELU)."""
    import shutil
    import open_clip
    from open_clip.transform import image_transform
    out = os.path.join(ROOT, "tests", "fixtures", "openclip-tiny")
    os.makedirs(os.path.join(out, "reference"), exist_ok=True)
    for f in ["vocab.json", "merges.txt"]:
        shutil.copy(os.path.join(OUT, f), os.path.join(out, f))
    model_cfg = dict(embed_dim=16,
                     vision_cfg=dict(layers=2, width=32, head_width=16, patch_size=4, image_size=32),
                     text_cfg=dict(context_length=77, vocab_size=len(vocab), width=32, heads=2,
                                   layers=2),
                     quick_gelu=False)
    torch.manual_seed(99)
    model = open_clip.model.CLIP(**model_cfg).eval()
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name != "logit_scale":
                p.add_(torch.randn_like(p) * 0.1)
    sd = {k: v.detach().clone().contiguous() for k, v in model.state_dict().items()}
    save_file(sd, os.path.join(out, "open_clip_model.safetensors"))
    with open(os.path.join(out, "open_clip_config.json"), "w") as f:
        json.dump({"model_cfg": model_cfg,
                   "preprocess_cfg": {"mean": list(open_clip.OPENAI_DATASET_MEAN),
                                      "std": list(open_clip.OPENAI_DATASET_STD),
                                      "interpolation": "bicubic", "resize_mode": "shortest"}},
                  f, indent=1)
    # open_clip.tokenize layout: sot, tokens, eot (truncated keeping eot), zero padding.
    rows = []
    for t in texts:
        ids = tok(t)["input_ids"]
        if len(ids) > 77:
            ids = ids[:76] + [tok.eos_token_id]
        rows.append(ids + [0] * (77 - len(ids)))
    ids_t = torch.tensor(rows, dtype=torch.long)
    tf = image_transform(32, is_train=False, mean=open_clip.OPENAI_DATASET_MEAN,
                         std=open_clip.OPENAI_DATASET_STD)
    px = torch.stack([tf(im) for im in pil_rgb]).float()
    with torch.no_grad():
        te = model.encode_text(ids_t)
        ie = model.encode_image(px)
        logits = model.logit_scale.exp() * F_normalize(ie) @ F_normalize(te[:8]).T
    save_file({"input_ids": ids_t.contiguous(), "text_embeds": te.contiguous(),
               "pixel_values": px.contiguous(), "image_embeds": ie.contiguous(),
               "logits_per_image": logits.contiguous()},
              os.path.join(out, "reference", "outputs.safetensors"))
    shutil.copytree(os.path.join(OUT, "images"), os.path.join(out, "images"), dirs_exist_ok=True)
    with open(os.path.join(out, "reference", "images.json"), "w") as f:
        json.dump({"images": names}, f)


def F_normalize(x):
    return x / x.norm(dim=-1, keepdim=True)


if __name__ == "__main__":
    sys.exit(main())
