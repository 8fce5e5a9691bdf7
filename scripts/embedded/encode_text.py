"""Precomputes the frozen MiniLM text features for every unique caption of a split, once.

    python scripts/embedded/encode_text.py data/icons/train [data/icons/eval ...]

Writes into each split directory:
  text_captions.json   list of unique captions; index 0 is "" (the unconditional caption)
  text_index.npy       int32 [N]: caption index of each image (captions.jsonl order)
  text_tokens.f16      fp16 [U, 32, 384]: `vf_icon.encode_tokens` (UNet conditioning, L=32)
  text_sentence.f16    fp16 [U, 384]:     `vf_icon.encode_sentence` (IconClip text input, L=64)
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
        toks, sents = [], []
        for i in range(0, len(uniq), 256):
            batch = uniq[i : i + 256]
            toks.append(vf_icon.encode_tokens(tok, model, batch).half().numpy())
            sents.append(vf_icon.encode_sentence(tok, model, batch).half().numpy())
        np.concatenate(toks).tofile(os.path.join(split, "text_tokens.f16"))
        np.concatenate(sents).tofile(os.path.join(split, "text_sentence.f16"))
        print(f"{split}: {len(caps)} images, {len(uniq)} unique captions")


if __name__ == "__main__":
    main()
