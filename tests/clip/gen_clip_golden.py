#!/usr/bin/python3
"""Golden outputs of the tiny CLIP and of CLIP's preprocessing, for the C tests.

GOLDEN GENERATOR ONLY. Engineers run it when the generator or the reference changes; meson
test never does. It needs Debian's python3-torch (1.13), python3-numpy, python3-regex and
python3-pil: run it with /usr/bin/python3.

  /usr/bin/python3 tests/clip/gen_clip_golden.py --gen-clip BUILD/tests/clip/gen_clip \\
      [--vocab bpe_simple_vocab_16e6.txt.gz] [--out tests/clip/data]

It runs gen_clip to write the tiny OpenAI-named F32 model (seed 0) into a temporary folder,
checks that gen_clip's FNV-1a 64 of the file is the one computed here, builds the reference
model of clip_ref.py from it (float32, CPU) and writes into --out:
  golden_model.txt                   the gen_clip command, the file size and its FNV-1a 64
  golden_dense_input.npy             float32 [1, 3, 40, 60], a preprocessed input: a 5 x 7
                                     grid of 8 px patches (4 px of W left over), so the
                                     positional embedding is interpolated
  golden_dense.npy                   float32 [5, 7, E], MaskCLIP dense features of it
  golden_dense_square_input.npy      float32 [1, 3, 32, 32] (the model's own 4 x 4 grid: no
  golden_dense_square.npy            interpolation); float32 [4, 4, E]
  golden_pooled_input.npy            float32 [2, 3, 32, 32]
  golden_pooled.npy                  float32 [2, E], encode_image
  golden_text_ids.npy                int32 [n, 77], clip.tokenize of TEXTS (below)
  golden_text.npy                    float32 [n, E], encode_text
  preprocess_in.png                  a 90 x 60 RGB test image (gradients and noise)
  preprocess_golden.npy              float32 [3, 32, 48]: CLIP's preprocessing without the
                                     centre crop for a 32 px model (short side 32, long side
                                     int(32 * 90 / 60) = 48, PIL bicubic on the 8-bit image,
                                     / 255, CLIP's mean and std)
  preprocess_in_20x14.png            a 20 x 14 image: the upscaling case
  preprocess_golden_20x14.npy        float32 [3, 32, 45]
The tiny model itself is not kept: tests regenerate it with gen_clip.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

import numpy as np
import torch
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import clip_ref  # noqa: E402

GEN_ARGS = ["--preset", "tiny", "--naming", "openai", "--dtype", "f32", "--seed", "0"]

# Phrases of the text golden: plain words, punctuation, a contraction, digits, accents, and
# one long enough to come close to the 77-token context.
TEXTS = [
    "a photo of a mug",
    "object",
    "A blue ceramic mug on the kitchen table.",
    "Don't grab the screwdriver; it's 3.5cm wide!",
    "caf\u00e9 cr\u00e8me br\u00fbl\u00e9e",
    "a robot arm with a parallel jaw gripper picks up the small red ceramic coffee mug by its "
    "handle from the cluttered wooden kitchen table, next to a metal bowl, a cardboard box, a "
    "yellow tennis ball and a screwdriver, then gently places it upside down on the drying "
    "rack beside the sink, while a second arm holds the door of the cupboard open for it",
]

MEAN = np.array([0.48145466, 0.4578275, 0.40821073], dtype=np.float32)
STD = np.array([0.26862954, 0.26130258, 0.27577711], dtype=np.float32)


def test_image(w, h, seed):
    """An 8-bit RGB image with detail: smooth gradients in each channel, a few sharp bars and
    uniform noise."""
    rng = np.random.RandomState(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    r = 255 * x / max(w - 1, 1)
    g = 255 * y / max(h - 1, 1)
    b = 127.5 + 100 * np.sin(x / 3.0) * np.cos(y / 5.0)
    img = np.stack([r, g, b], axis=-1)
    img[:, (w // 3):(w // 3) + 2, :] = [250, 10, 10]  # a vertical red bar
    img[(h // 2):(h // 2) + 1, :, 1] = 0              # a horizontal line without green
    img += rng.uniform(-40, 40, size=img.shape)
    return Image.fromarray(np.clip(np.rint(img), 0, 255).astype(np.uint8), "RGB")


def preprocess(img, size):
    """CLIP's transform without CenterCrop: torchvision Resize(size, BICUBIC) on a PIL image
    (short side -> size, long side int(size * long / short)), ToTensor, Normalize."""
    w, h = img.size
    if w <= h:
        new_w, new_h = size, int(size * h / w)
    else:
        new_w, new_h = int(size * w / h), size
    img = img.resize((new_w, new_h), Image.BICUBIC)
    x = np.asarray(img, dtype=np.uint8).astype(np.float32) / np.float32(255)  # [h, w, 3]
    x = (x - MEAN) / STD
    return np.ascontiguousarray(x.transpose(2, 0, 1), dtype=np.float32)


def default_vocab():
    shared = os.environ.get("FG_SHARED_DATA")
    if not shared:
        shared = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..",
                              "shared", "data")
    return os.path.join(shared, "clip", "bpe_simple_vocab_16e6.txt.gz")


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gen-clip", required=True, help="the built gen_clip executable")
    ap.add_argument("--vocab", default=default_vocab(), help="bpe_simple_vocab_16e6.txt.gz")
    ap.add_argument("--out", default=os.path.join(here, "data"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    torch.manual_seed(0)
    torch.set_num_threads(1)  # the same sums in the same order on every machine

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "tiny.safetensors")
        res = subprocess.run([args.gen_clip, path] + GEN_ARGS, check=True, capture_output=True,
                             text=True)
        m = re.search(r"fnv1a64 ([0-9a-f]{16})", res.stdout)
        if not m:
            sys.exit(f"unexpected gen_clip output: {res.stdout!r}")
        fnv = clip_ref.fnv1a64_file(path)
        if int(m.group(1), 16) != fnv:
            sys.exit(f"gen_clip says fnv1a64 {m.group(1)}, this script computes {fnv:016x}")
        size = os.path.getsize(path)
        state, meta = clip_ref.read_safetensors(path, mmap=False)
        model = clip_ref.build_model(state, meta)

    rng = np.random.RandomState(20240)
    outputs = {}
    with torch.no_grad():
        x = rng.standard_normal((1, 3, 40, 60)).astype(np.float32)
        outputs["golden_dense_input"] = x
        outputs["golden_dense"] = model.encode_dense(torch.from_numpy(x))[0].numpy()
        x = rng.standard_normal((1, 3, 32, 32)).astype(np.float32)
        outputs["golden_dense_square_input"] = x
        outputs["golden_dense_square"] = model.encode_dense(torch.from_numpy(x))[0].numpy()
        x = rng.standard_normal((2, 3, 32, 32)).astype(np.float32)
        outputs["golden_pooled_input"] = x
        outputs["golden_pooled"] = model.encode_image(torch.from_numpy(x)).numpy()
        tok = clip_ref.Tokenizer(args.vocab)
        ids = tok.tokenize(TEXTS)
        outputs["golden_text_ids"] = ids
        outputs["golden_text"] = model.encode_text(ids).numpy()

    img = test_image(90, 60, seed=1)
    small = test_image(20, 14, seed=2)
    img.save(os.path.join(args.out, "preprocess_in.png"))
    small.save(os.path.join(args.out, "preprocess_in_20x14.png"))
    # preprocess what was saved, read back, as the C side will
    outputs["preprocess_golden"] = preprocess(
        Image.open(os.path.join(args.out, "preprocess_in.png")).convert("RGB"), 32)
    outputs["preprocess_golden_20x14"] = preprocess(
        Image.open(os.path.join(args.out, "preprocess_in_20x14.png")).convert("RGB"), 32)

    for name, arr in outputs.items():
        if arr.dtype not in (np.float32, np.int32):
            raise TypeError(f"{name}: {arr.dtype}")
        np.save(os.path.join(args.out, name + ".npy"), np.ascontiguousarray(arr))

    with open(os.path.join(args.out, "golden_model.txt"), "w") as f:
        f.write("# The tiny CLIP the golden_*.npy outputs were computed from (OpenAI names, F32,\n"
                "# float32 PyTorch reference of tests/clip/clip_ref.py). Written by\n"
                "# tests/clip/gen_clip_golden.py; test_clip_gen checks that gen_clip still\n"
                "# writes exactly these bytes.\n")
        f.write("command=gen_clip OUT " + " ".join(GEN_ARGS) + "\n")
        f.write(f"size={size}\n")
        f.write(f"fnv1a64={fnv:016x}\n")
        f.write(f"texts={len(TEXTS)}\n")
        for i, t in enumerate(TEXTS):
            n = int((ids[i] != 0).sum())
            f.write(f"text{i}={n} ids with start and end: {t}\n")

    for name, arr in outputs.items():
        print(f"{name}: {arr.dtype} {list(arr.shape)}")
    print(f"tiny model: {size} bytes, fnv1a64 {fnv:016x}")


if __name__ == "__main__":
    main()
