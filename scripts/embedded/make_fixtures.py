"""Fixtures for the Rust BERT/MiniLM text encoder and the IconClip scorer (docs/EMBEDDED.md).

Run with the project venv from the repository root:

    /work/venv/bin/python scripts/embedded/make_fixtures.py

Writes
- tests/fixtures/bert-tiny/: a random BertModel (hidden 16, 2 layers, 4 heads) over the REAL
  all-MiniLM-L6-v2 vocabulary, in the model-root layout (`text_encoder/`, `tokenizer/`), weights
  stored f16 (the reference runs on the same f16-rounded weights in f32); `tokens.json` (ids and
  masks of `transformers.BertTokenizer` for benchmark captions and tricky strings at lengths 32
  and 64), `refs.safetensors` (last_hidden_state at L=32, pooled sentence embeddings at L=64),
  `minilm_refs.safetensors` + `minilm_captions.json` (the real MiniLM's sentence embeddings and
  UNet conditioning for 5 captions);
- tests/fixtures/iconclip-tiny/: a random IconClip (image 32, channels [8, 16], groups 4,
  embed 32) in `scorer/`, whose text tower is bert-tiny; an RGBA PNG; `refs.safetensors`.
"""

import json
import os
import sys

import numpy as np
import torch
from PIL import Image
from safetensors.torch import save_file

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
FIX = os.path.join(ROOT, "tests", "fixtures")
BENCH = os.path.join(ROOT, "..", "shared", "bench", "svg_bench_prompts.txt")

TRICKY = [
    "",
    " ",
    "   multiple    spaces\tand\ttabs\nand newlines  ",
    "Héllo Wörld, café naïve résumé",
    "ÀÉÎÕÜ çedilla Ångström",
    "İstanbul ΟΔΟΣ straße",
    "自転車",
    "a red 自転車 on a hill",
    "ひらがな カタカナ 한국어",
    "emoji 🐱🚲 and 👍🏽 and 👨‍👩‍👧",
    "punctuation!!! ... (parens) [brackets] {braces} \"quotes\" 'single' a-b_c/d\\e",
    "it's a dog's life; isn't it? yes: no.",
    "$100 & 50% off #sale @home ^caret `tick` ~tilde |pipe| <angle>",
    "unaffable unbelievably antidisestablishmentarianism",
    "x" * 101,
    "supercalifragilistic" * 5,
    "zero\u200bwidth\u200djoiner\u00a0nbsp\u2028line",
    "control\x00\x01\x7fchars\ufffd",
    "UPPER lower MiXeD",
    "numbers 3.14159 1,000,000 2nd 1st",
    "½ ① ™ © ® °C",
    "a " * 40,
    "mañana — “smart quotes” … ellipsis – dash",
]


def bench_captions():
    with open(BENCH, encoding="utf-8") as f:
        lines = [l.rstrip("\n") for l in f if l.strip()]
    return lines[::2]  # 64 captions


def round_f16(model):
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(p.half().float())


def perturb(model, g, scale=0.2):
    with torch.no_grad():
        for name, p in model.named_parameters():
            if "LayerNorm" in name or "norm" in name:
                p.add_(torch.randn(p.shape, generator=g) * scale)


def main():
    from transformers import BertConfig, BertModel, BertTokenizer

    minilm = vf_icon.minilm_dir()
    tok = BertTokenizer.from_pretrained(minilm)

    # ---------------------------------------------------------------- bert-tiny
    out = os.path.join(FIX, "bert-tiny")
    os.makedirs(os.path.join(out, "text_encoder"), exist_ok=True)
    os.makedirs(os.path.join(out, "tokenizer"), exist_ok=True)
    with open(os.path.join(minilm, "vocab.txt"), encoding="utf-8") as f:
        vocab = f.read()
    with open(os.path.join(out, "tokenizer", "vocab.txt"), "w", encoding="utf-8") as f:
        f.write(vocab)
    with open(os.path.join(out, "tokenizer", "tokenizer_config.json"), "w") as f:
        json.dump({"do_lower_case": True, "model_max_length": 32, "tokenizer_class": "BertTokenizer"}, f, indent=2)

    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    cfg = BertConfig(
        vocab_size=30522, hidden_size=16, num_hidden_layers=2, num_attention_heads=4, intermediate_size=64,
        max_position_embeddings=64, hidden_act="gelu", layer_norm_eps=1e-12, type_vocab_size=2,
    )
    model = BertModel(cfg, add_pooling_layer=False).eval()
    perturb(model, g)
    round_f16(model)
    model.config.save_pretrained(os.path.join(out, "text_encoder"))
    # keep only what the Rust loader needs from config.json
    with open(os.path.join(out, "text_encoder", "config.json")) as f:
        c = json.load(f)
    keep = ["architectures", "attention_probs_dropout_prob", "hidden_act", "hidden_dropout_prob", "hidden_size",
            "initializer_range", "intermediate_size", "layer_norm_eps", "max_position_embeddings", "model_type",
            "num_attention_heads", "num_hidden_layers", "pad_token_id", "position_embedding_type", "type_vocab_size",
            "vocab_size"]
    with open(os.path.join(out, "text_encoder", "config.json"), "w") as f:
        json.dump({k: c[k] for k in keep if k in c}, f, indent=2)
    save_file({k: v.half().contiguous() for k, v in model.state_dict().items()},
              os.path.join(out, "text_encoder", "model.safetensors"))

    texts = bench_captions() + TRICKY
    cases = []
    for length in (32, 64):
        for t in texts:
            enc = tok(t, padding="max_length", truncation=True, max_length=length)
            cases.append({"text": t, "length": length, "ids": enc["input_ids"], "attention_mask": enc["attention_mask"]})
    with open(os.path.join(out, "tokens.json"), "w", encoding="utf-8") as f:
        json.dump({"tokenizer": "transformers.BertTokenizer on all-MiniLM-L6-v2 vocab.txt", "cases": cases}, f,
                  ensure_ascii=False)

    caps = ["a red bicycle", "", "Héllo, 自転車!", texts[0], "a " * 40]
    with open(os.path.join(out, "captions.json"), "w", encoding="utf-8") as f:
        json.dump(caps, f, ensure_ascii=False)
    hidden = vf_icon.encode_tokens(tok, model, caps, max_len=32)
    pooled = vf_icon.encode_sentence(tok, model, caps, max_len=64)
    save_file({"last_hidden_state": hidden.contiguous(), "pooled": pooled.contiguous()},
              os.path.join(out, "refs.safetensors"))

    # real MiniLM references (checked by Rust only when the weights are available)
    real_tok, real = vf_icon.load_text_model(minilm)
    real_caps = ["a red bicycle", "a cat sitting on a chair", "自転車", "Happy birthday, café!", ""]
    with open(os.path.join(out, "minilm_captions.json"), "w", encoding="utf-8") as f:
        json.dump(real_caps, f, ensure_ascii=False)
    save_file({
        "sentence": vf_icon.encode_sentence(real_tok, real, real_caps).contiguous(),
        "cond0": vf_icon.encode_tokens(real_tok, real, real_caps[:1]).contiguous(),
    }, os.path.join(out, "minilm_refs.safetensors"))

    # ---------------------------------------------------------------- iconclip-tiny
    out = os.path.join(FIX, "iconclip-tiny")
    os.makedirs(os.path.join(out, "scorer"), exist_ok=True)
    torch.manual_seed(2)
    g = torch.Generator().manual_seed(3)
    clip = vf_icon.IconClip(image_size=32, channels=(8, 16), groups=4, embed_dim=32, text_dim=16).eval()
    perturb(clip, g)
    with torch.no_grad():
        clip.logit_scale.fill_(2.3)
    with open(os.path.join(out, "scorer", "config.json"), "w") as f:
        json.dump(clip.config, f, indent=2)
    save_file({k: v.contiguous() for k, v in clip.state_dict().items()},
              os.path.join(out, "scorer", "model.safetensors"))

    # images: three random [0,1] tensors at 32 px, plus one 64 px RGBA PNG through the preprocessing
    gi = torch.Generator().manual_seed(4)
    x = torch.rand(3, 3, 32, 32, generator=gi)
    rng = np.random.default_rng(5)
    rgba = np.zeros((64, 64, 4), dtype=np.uint8)
    yy, xx = np.mgrid[0:64, 0:64]
    rgba[..., 0] = (xx * 4) % 256
    rgba[..., 1] = (yy * 4) % 256
    rgba[..., 2] = rng.integers(0, 256, (64, 64))
    rgba[..., 3] = np.where((xx - 32) ** 2 + (yy - 28) ** 2 < 20 ** 2, 255, rng.integers(0, 256, (64, 64)))
    Image.fromarray(rgba, "RGBA").save(os.path.join(out, "icon64.png"))
    a = torch.from_numpy(rgba.astype(np.float32) / 255.0).permute(2, 0, 1)
    over = a[:3] * a[3:4] + (1 - a[3:4])
    png_px = torch.nn.functional.interpolate(over[None], size=(32, 32), mode="area")
    with torch.no_grad():
        img = clip.encode_image(torch.cat([x, png_px]))
        clip_caps = ["a red bicycle", "a cat", "", "自転車 icon"]
        sent = vf_icon.encode_sentence(tok, model, clip_caps, max_len=vf_icon.SCORER_TEXT_LEN)
        txt = clip.encode_text(sent)
        logits = clip.logits(img, txt)
    with open(os.path.join(out, "captions.json"), "w", encoding="utf-8") as f:
        json.dump(clip_caps, f, ensure_ascii=False)
    save_file({
        "pixels": torch.cat([x, png_px]).contiguous(),
        "image_embeds": img.contiguous(),
        "text_embeds": txt.contiguous(),
        "logits": logits.contiguous(),
    }, os.path.join(out, "refs.safetensors"))
    print("wrote", os.path.join(FIX, "bert-tiny"), "and", out)


if __name__ == "__main__":
    main()
