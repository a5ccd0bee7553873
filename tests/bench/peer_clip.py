#!/usr/bin/python3
"""Benchmark peer: CLIP ViT image and text encoders in plain PyTorch, on the CPU.

BENCHMARK PEER ONLY. Nothing in the product or the tests imports or runs this; the clip
benchmark (tests/bench/run.sh clip) runs it beside bench_clip so that the C figures can be
reported as ratios to PyTorch on the same machine, threads and weights in the same run. It
needs Debian's python3-torch (1.13), python3-numpy and python3-regex: run it with
/usr/bin/python3.

The model is tests/clip/clip_ref.py (OpenAI's CLIP architecture with F3RM's MaskCLIP dense
path), float32, eval mode, under torch.no_grad, loaded from an OpenAI-named safetensors file
such as the one `gen_clip OUT --preset vit-b-16 --dtype f32` writes (F16/BF16 files are
widened to float32). Inputs are random preprocessed images (torch.manual_seed(0)) and, for
text, 8 phrases tokenized as clip.tokenize does (77-token contexts; with the vocabulary
missing, synthetic ids of the same shape: the encoder's cost does not depend on them).

Cases, each after one untimed warm-up call, repeated for at least --seconds:
  dense224       MaskCLIP dense features of one 224 x 224 image (14 x 14 patches)
  dense640x360   the same for a 640 x 360 frame resized to short side 224: 224 x 398
                 (14 x 24 patches, the positional embedding interpolated)
  text77         encode_text of a batch of 8 phrases
Output, one line per case and one for memory:
  peer=torch case=dense224 input=224x224 batch=1 images_per_s=1.93 iters=20 seconds=10.37 threads=2
  peer=torch case=text77 batch=8 texts_per_s=... threads=2
  peer=torch case=memory peak_rss_mb=... load_s=... threads=2 torch=1.13.0
peak_rss_mb is ru_maxrss of the process (the float32 weights included).

Usage:
  /usr/bin/python3 tests/bench/peer_clip.py WEIGHTS.safetensors [--threads 2] [--seconds 10]
                                           [--vocab bpe_simple_vocab_16e6.txt.gz]
"""
import argparse
import os
import resource
import sys
import time

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "clip"))
import clip_ref  # noqa: E402

PHRASES = [
    "a photo of a mug",
    "a blue ceramic mug on the kitchen table",
    "the handle of the screwdriver",
    "a metal bowl",
    "object",
    "things",
    "a cardboard box full of tennis balls next to a pair of scissors",
    "pick up the red mug by its handle and put it on the drying rack",
]


def default_vocab():
    shared = os.environ.get("FG_SHARED_DATA") or os.path.join(HERE, "..", "..", "..", "shared",
                                                              "data")
    return os.path.join(shared, "clip", "bpe_simple_vocab_16e6.txt.gz")


def text_ids(vocab, context, vocab_size):
    """[8, context] int64 ids and whether they come from the real tokenizer."""
    if os.path.exists(vocab):
        return torch.from_numpy(clip_ref.Tokenizer(vocab).tokenize(PHRASES, context)).long(), True
    g = torch.Generator().manual_seed(0)
    ids = torch.zeros(len(PHRASES), context, dtype=torch.long)
    for i in range(len(PHRASES)):
        n = 4 + 8 * i
        ids[i, 0] = vocab_size - 2
        ids[i, 1:n] = torch.randint(0, vocab_size - 2, (n - 1,), generator=g)
        ids[i, n] = vocab_size - 1
    return ids, False


def timed(fn, seconds):
    """One warm-up call, then calls until at least `seconds` have passed: (iters, elapsed)."""
    fn()
    n, t0 = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n, dt


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("weights",
                    help="OpenAI-named CLIP safetensors file (gen_clip --preset vit-b-16)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--vocab", default=default_vocab())
    args = ap.parse_args()
    if args.threads < 1 or args.seconds <= 0:
        sys.exit("peer_clip: --threads must be >= 1 and --seconds > 0")
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    t = args.threads

    t0 = time.perf_counter()
    try:
        model = clip_ref.load_model(args.weights)
    except (OSError, ValueError) as e:
        sys.exit(f"peer_clip: {e}")
    load_s = time.perf_counter() - t0
    size = model.visual.positional_embedding.shape[0]
    size = int(round((size - 1) ** 0.5)) * model.visual.patch  # 224 for ViT-B/16
    short, long_ = size, int(size * 640 / 360)  # torchvision Resize(224) of a 640 x 360 frame

    with torch.no_grad():
        for case, h, w in (("dense224", size, size), ("dense640x360", short, long_)):
            x = torch.randn(1, 3, h, w)
            n, dt = timed(lambda: model.encode_dense(x), args.seconds)
            print(f"peer=torch case={case} input={h}x{w} batch=1 images_per_s={n / dt:.3f} "
                  f"iters={n} seconds={dt:.2f} threads={t}", flush=True)
        context = model.positional_embedding.shape[0]
        ids, real = text_ids(args.vocab, context, model.token_embedding.weight.shape[0])
        n, dt = timed(lambda: model.encode_text(ids), args.seconds)
        print(f"peer=torch case=text{context} batch={ids.shape[0]} "
              f"texts_per_s={n * ids.shape[0] / dt:.2f} iters={n} seconds={dt:.2f} "
              f"tokenizer={'bpe' if real else 'synthetic'} threads={t}", flush=True)

    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peer=torch case=memory peak_rss_mb={peak_mb:.1f} load_s={load_s:.2f} threads={t} "
          f"torch={torch.__version__}")


if __name__ == "__main__":
    main()
