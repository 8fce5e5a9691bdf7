"""Precomputes the frozen MiniLM text features for every unique caption of a split, once.

    python scripts/embedded/encode_text.py data/icons/train [data/icons/eval ...]

Writes into each split directory:
  text_captions.json   list of unique captions; index 0 is "" (the unconditional caption)
  text_index.npy       int32 [N]: caption index of each image (captions.jsonl order)
  text_tokens.f16      fp16 [U, 32, 384]: `vf_icon.encode_tokens` (UNet conditioning, L=32)
  text_sentence.f16    fp16 [U, 384]:     `vf_icon.encode_sentence` (IconClip text input, L=64)
  text_tokens_article.f16  fp16 [U, 32, 384]: the same for `vf_icon.with_article(caption)` ("a horse"),
                       the second caption template of train_prior.py
"""

import json
import os
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
import vf_icon  # noqa: E402

torch.set_num_threads(int(os.environ.get("VF_THREADS", "2")))


def main():
    tok, model = vf_icon.load_text_model()
    for split in sys.argv[1:]:
        caps = [json.loads(l)["caption"] for l in open(os.path.join(split, "captions.jsonl"))]
        uniq = [""] + sorted(set(caps) - {""})
        index = {c: i for i, c in enumerate(uniq)}
        np.save(os.path.join(split, "text_index.npy"), np.array([index[c] for c in caps], dtype=np.int32))
        json.dump(uniq, open(os.path.join(split, "text_captions.json"), "w"))
        toks, sents, arts = [], [], []
        for i in range(0, len(uniq), 256):
            batch = uniq[i : i + 256]
            h = vf_icon.encode_tokens(tok, model, batch)
            # The sentence embedding (L=64) pools only real tokens, and with the attention mask
            # real tokens do not see padding, so it equals the masked mean of the L=32 states
            # whenever the caption fits in 32 tokens (checked below); longer ones are re-encoded.
            m = tok(batch, padding="max_length", truncation=True, max_length=vf_icon.UNET_TEXT_LEN, return_tensors="pt").attention_mask
            s = torch.nn.functional.normalize((h * m[..., None]).sum(1) / m.sum(1, keepdim=True), dim=-1)
            long = [j for j, c in enumerate(batch) if len(tok.tokenize(c)) > vf_icon.UNET_TEXT_LEN - 2]
            if long:
                s[long] = vf_icon.encode_sentence(tok, model, [batch[j] for j in long])
            if i == 0:
                ref = vf_icon.encode_sentence(tok, model, batch[:16])
                assert torch.allclose(ref, s[:16], atol=1e-4), (ref - s[:16]).abs().max()
            toks.append(h.half().numpy())
            arts.append(vf_icon.encode_tokens(tok, model, [vf_icon.with_article(c) for c in batch]).half().numpy())
            sents.append(s.half().numpy())
            print(f"  {i + len(batch)}/{len(uniq)}", flush=True)
        np.concatenate(toks).tofile(os.path.join(split, "text_tokens.f16"))
        np.concatenate(sents).tofile(os.path.join(split, "text_sentence.f16"))
        np.concatenate(arts).tofile(os.path.join(split, "text_tokens_article.f16"))
        print(f"{split}: {len(caps)} images, {len(uniq)} unique captions")


if __name__ == "__main__":
    main()
