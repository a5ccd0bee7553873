"""Reference CLIP in plain PyTorch, for golden outputs and the benchmark peer.

REFERENCE ONLY. Nothing in the product or in `meson test` imports this; it is shared by
tests/clip/gen_clip_golden.py (golden outputs of the tiny model) and tests/bench/peer_clip.py
(the PyTorch side of the CLIP benchmark). It needs Debian's python3-torch (1.13), python3-numpy
and python3-regex: run the scripts with /usr/bin/python3.

What is here, each written after its public reference:
  read_safetensors  a safetensors reader on json + numpy (F32, F16, BF16, I64, ...)
  Tokenizer         OpenAI's simple_tokenizer.py (byte-level BPE over
                    bpe_simple_vocab_16e6.txt.gz) and clip.tokenize; ftfy's text repair is
                    left out (it changes nothing in plain text)
  CLIP              OpenAI's ViT CLIP (clip/model.py): LayerNorm in float32, QuickGELU,
                    residual attention blocks on nn.MultiheadAttention, the causal text mask,
                    encode_image, encode_text (the row of the end-of-text token, the largest
                    id), and F3RM's MaskCLIP dense output (f3rm/features/clip/model.py):
                    all blocks but the last, then the last block's value path
                    out_proj(v_proj(ln_1 x)) without attention mixing, residual or MLP, the
                    patch tokens, ln_post, @ proj; with F3RM's bicubic interpolation of the
                    positional embedding for inputs of another size
                    (f3rm/features/clip/interpolate.py)
  build_model       a CLIP from an OpenAI-named state dict; head counts from the file's
                    __metadata__ (vision_heads, text_heads) when present, else width / 64
"""
import gzip
import html
import json
from collections import OrderedDict
from functools import lru_cache

import numpy as np
import regex
import torch
import torch.nn as nn
import torch.nn.functional as F

# ---- safetensors -------------------------------------------------------------------------

_ST_DTYPES = {
    "F64": np.float64, "F32": np.float32, "F16": np.float16, "I64": np.int64, "I32": np.int32,
    "I16": np.int16, "I8": np.int8, "U8": np.uint8, "BOOL": np.bool_,
}


def read_safetensors(path, mmap=True):
    """Returns ({name: np.ndarray}, {metadata}). Arrays are read-only views of a memory map
    (mmap=True) or copies; BF16 is widened to float32 (exact)."""
    with open(path, "rb") as f:
        n = int.from_bytes(f.read(8), "little")
        header = json.loads(f.read(n).decode("utf-8"))
    meta = header.pop("__metadata__", {}) or {}
    raw = np.memmap(path, dtype=np.uint8, mode="r") if mmap else np.fromfile(path, np.uint8)
    base = 8 + n
    out = OrderedDict()
    for name, info in header.items():
        b, e = info["data_offsets"]
        shape = tuple(info["shape"])
        buf = raw[base + b: base + e]
        if info["dtype"] == "BF16":
            bits = buf.view("<u2").astype(np.uint32) << 16
            arr = bits.view(np.float32).reshape(shape)
        else:
            arr = buf.view(np.dtype(_ST_DTYPES[info["dtype"]]).newbyteorder("<")).reshape(shape)
        out[name] = arr
    return out, meta


def fnv1a64_file(path):
    """FNV-1a 64 of a file's bytes (what clipgen_file_fnv1a64 computes), as an int."""
    h = 0xcbf29ce484222325
    with open(path, "rb") as f:
        data = f.read()
    for byte in data:
        h = ((h ^ byte) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
    return h


# ---- tokenizer ---------------------------------------------------------------------------

@lru_cache()
def _byte_symbols():
    """The 256 byte symbols of GPT-2/CLIP BPE: printable Latin-1 bytes map to themselves, the
    others to code points 256, 257, ... in byte order."""
    keep = (list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1))
            + list(range(ord("®"), ord("ÿ") + 1)))
    table, extra = {}, 0
    for b in range(256):
        if b in keep:
            table[b] = chr(b)
        else:
            table[b] = chr(256 + extra)
            extra += 1
    # the vocabulary lists them in this order: kept bytes first, then the remapped ones
    order = keep + [b for b in range(256) if b not in keep]
    return table, [table[b] for b in order]


class Tokenizer:
    """OpenAI's CLIP tokenizer: 49152 - 256 - 2 merges of the vocab file, ids 0-255 byte
    symbols, 256-511 the same with </w>, then one per merge, then <|startoftext|> 49406 and
    <|endoftext|> 49407."""

    SOT, EOT = 49406, 49407
    PATTERN = (r"""<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|"""
               r"""[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+""")

    def __init__(self, vocab_path):
        lines = gzip.open(vocab_path).read().decode("utf-8").split("\n")
        merges = [tuple(line.split()) for line in lines[1:49152 - 256 - 2 + 1]]
        self.byte_sym, symbols = _byte_symbols()
        vocab = symbols + [s + "</w>" for s in symbols] + ["".join(m) for m in merges]
        vocab += ["<|startoftext|>", "<|endoftext|>"]
        self.ids = {tok: i for i, tok in enumerate(vocab)}
        self.rank = {m: i for i, m in enumerate(merges)}
        self.pat = regex.compile(self.PATTERN, regex.IGNORECASE)
        # the special tokens stand for themselves (no </w>, no merging)
        self.cache = {t: [t] for t in ("<|startoftext|>", "<|endoftext|>")}

    def _bpe(self, piece):
        """Merges the symbols of one pre-token (its last symbol marked </w>) by rank."""
        if piece in self.cache:
            return self.cache[piece]
        word = list(piece[:-1]) + [piece[-1] + "</w>"]
        while len(word) > 1:
            pairs = {(word[i], word[i + 1]) for i in range(len(word) - 1)}
            best = min(pairs, key=lambda p: self.rank.get(p, float("inf")))
            if best not in self.rank:
                break
            merged, i = [], 0
            while i < len(word):
                if i < len(word) - 1 and (word[i], word[i + 1]) == best:
                    merged.append(word[i] + word[i + 1])
                    i += 2
                else:
                    merged.append(word[i])
                    i += 1
            word = merged
        self.cache[piece] = word
        return word

    def encode(self, text):
        """BPE ids without start/end tokens."""
        text = html.unescape(html.unescape(text)).strip()
        text = regex.sub(r"\s+", " ", text).strip().lower()
        out = []
        for piece in self.pat.findall(text):
            sym = "".join(self.byte_sym[b] for b in piece.encode("utf-8"))
            out.extend(self.ids[t] for t in self._bpe(sym))
        return out

    def tokenize(self, texts, context=77):
        """clip.tokenize without truncation: int32 [n, context] = start, ids, end, zeros."""
        result = np.zeros((len(texts), context), dtype=np.int32)
        for i, t in enumerate(texts):
            ids = [self.SOT] + self.encode(t) + [self.EOT]
            if len(ids) > context:
                raise ValueError(f"{t!r} is {len(ids) - 2} tokens, the limit is {context - 2}")
            result[i, :len(ids)] = ids
        return result


# ---- the model ---------------------------------------------------------------------------

class LayerNorm(nn.LayerNorm):
    """torch's LayerNorm computed in float32 whatever the input type (eps 1e-5)."""

    def forward(self, x):
        return super().forward(x.float()).to(x.dtype)


class QuickGELU(nn.Module):
    def forward(self, x):
        return x * torch.sigmoid(1.702 * x)


class ResidualAttentionBlock(nn.Module):
    def __init__(self, width, heads, attn_mask=None):
        super().__init__()
        self.attn = nn.MultiheadAttention(width, heads)
        self.ln_1 = LayerNorm(width)
        self.mlp = nn.Sequential(OrderedDict([
            ("c_fc", nn.Linear(width, 4 * width)),
            ("gelu", QuickGELU()),
            ("c_proj", nn.Linear(4 * width, width)),
        ]))
        self.ln_2 = LayerNorm(width)
        self.attn_mask = attn_mask

    def forward(self, x):  # x [L, N, D]
        mask = None if self.attn_mask is None else self.attn_mask.to(x.dtype)
        y = self.ln_1(x)
        x = x + self.attn(y, y, y, need_weights=False, attn_mask=mask)[0]
        return x + self.mlp(self.ln_2(x))

    def forward_v(self, x):
        """MaskCLIP: the value projection and the output projection of ln_1 x, per token."""
        d = self.attn.embed_dim
        v = F.linear(self.ln_1(x), self.attn.in_proj_weight[2 * d:], self.attn.in_proj_bias[2 * d:])
        return F.linear(v, self.attn.out_proj.weight, self.attn.out_proj.bias)


class Transformer(nn.Module):
    def __init__(self, width, layers, heads, attn_mask=None):
        super().__init__()
        self.resblocks = nn.Sequential(*[ResidualAttentionBlock(width, heads, attn_mask)
                                         for _ in range(layers)])

    def forward(self, x):
        return self.resblocks(x)


def interpolate_positional_embedding(pos, rows, cols):
    """F3RM's interpolation: pos [N*N + 1, D] for a rows x cols grid -> [rows*cols + 1, D].
    The patch part is resized bicubically (align_corners False) with scale factors
    ((rows + 0.1) / N, (cols + 0.1) / N) used as given (recompute_scale_factor False), so the
    output is floor(N * scale) = rows x cols; the class row is kept. An N x N grid is
    returned as it is."""
    n_og = pos.shape[0] - 1
    side = int(np.sqrt(n_og))
    if rows == side and cols == side:
        return pos
    dim = pos.shape[1]
    grid = pos[1:].reshape(1, side, side, dim).permute(0, 3, 1, 2)  # [1, D, N, N]
    grid = F.interpolate(grid, scale_factor=((rows + 0.1) / side, (cols + 0.1) / side),
                         mode="bicubic", align_corners=False, recompute_scale_factor=False)
    assert grid.shape[-2:] == (rows, cols), grid.shape
    grid = grid.permute(0, 2, 3, 1).reshape(rows * cols, dim)
    return torch.cat([pos[:1], grid], dim=0)


class VisionTransformer(nn.Module):
    def __init__(self, image_size, patch, width, layers, heads, embed_dim):
        super().__init__()
        self.patch = patch
        self.conv1 = nn.Conv2d(3, width, kernel_size=patch, stride=patch, bias=False)
        self.class_embedding = nn.Parameter(torch.zeros(width))
        self.positional_embedding = nn.Parameter(torch.zeros((image_size // patch) ** 2 + 1, width))
        self.ln_pre = LayerNorm(width)
        self.transformer = Transformer(width, layers, heads)
        self.ln_post = LayerNorm(width)
        self.proj = nn.Parameter(torch.zeros(width, embed_dim))

    def tokens(self, x):
        """x [B, 3, H, W] -> ln_pre of [class; patches] + positions, as [L, B, D]."""
        rows, cols = x.shape[2] // self.patch, x.shape[3] // self.patch
        x = self.conv1(x)  # [B, D, rows, cols]; a remainder of H or W is dropped
        x = x.reshape(x.shape[0], x.shape[1], -1).permute(0, 2, 1)  # [B, rows*cols, D]
        cls = self.class_embedding.to(x.dtype) + torch.zeros(x.shape[0], 1, x.shape[-1],
                                                             dtype=x.dtype)
        x = torch.cat([cls, x], dim=1)
        x = x + interpolate_positional_embedding(self.positional_embedding, rows, cols).to(x.dtype)
        return self.ln_pre(x).permute(1, 0, 2)

    def forward(self, x):
        """encode_image: [B, 3, S, S] -> [B, E]."""
        x = self.transformer(self.tokens(x)).permute(1, 0, 2)
        return self.ln_post(x[:, 0, :]) @ self.proj

    def dense(self, x):
        """MaskCLIP patch features: [B, 3, H, W] -> [B, H/p, W/p, E]."""
        rows, cols = x.shape[2] // self.patch, x.shape[3] // self.patch
        *first, last = self.transformer.resblocks
        h = self.tokens(x)
        for blk in first:
            h = blk(h)
        h = last.forward_v(h).permute(1, 0, 2)[:, 1:, :]  # patch tokens [B, rows*cols, D]
        h = self.ln_post(h) @ self.proj
        return h.reshape(x.shape[0], rows, cols, -1)


class CLIP(nn.Module):
    def __init__(self, embed_dim, image_size, patch, vision_width, vision_layers, vision_heads,
                 context, vocab, text_width, text_layers, text_heads):
        super().__init__()
        self.visual = VisionTransformer(image_size, patch, vision_width, vision_layers,
                                        vision_heads, embed_dim)
        mask = torch.full((context, context), float("-inf")).triu_(1)  # causal, additive
        self.transformer = Transformer(text_width, text_layers, text_heads, attn_mask=mask)
        self.token_embedding = nn.Embedding(vocab, text_width)
        self.positional_embedding = nn.Parameter(torch.zeros(context, text_width))
        self.ln_final = LayerNorm(text_width)
        self.text_projection = nn.Parameter(torch.zeros(text_width, embed_dim))
        self.logit_scale = nn.Parameter(torch.zeros([]))

    def encode_image(self, x):
        return self.visual(x)

    def encode_dense(self, x):
        return self.visual.dense(x)

    def encode_text(self, ids):
        """ids [B, context] (int) -> [B, E], from the row of each sequence's largest id."""
        ids = torch.as_tensor(ids).long()
        x = self.token_embedding(ids) + self.positional_embedding
        x = self.transformer(x.permute(1, 0, 2)).permute(1, 0, 2)
        x = self.ln_final(x)
        return x[torch.arange(x.shape[0]), ids.argmax(dim=-1)] @ self.text_projection


def model_for_shapes(shapes, meta=None):
    """An uninitialised float32 CLIP for an OpenAI-named {name: shape}: sizes from the shapes,
    head counts from meta (vision_heads, text_heads) or width / 64."""
    meta = meta or {}
    conv = shapes["visual.conv1.weight"]
    vw, patch = conv[0], conv[-1]
    grid = int(round((shapes["visual.positional_embedding"][0] - 1) ** 0.5))
    tw = shapes["ln_final.weight"][0]

    def count(prefix):
        depth = len(prefix.split("."))
        return len({k.split(".")[depth] for k in shapes if k.startswith(prefix + ".")})

    return CLIP(
        embed_dim=shapes["text_projection"][1], image_size=grid * patch, patch=patch,
        vision_width=vw, vision_layers=count("visual.transformer.resblocks"),
        vision_heads=int(meta.get("vision_heads", vw // 64)),
        context=shapes["positional_embedding"][0],
        vocab=shapes["token_embedding.weight"][0], text_width=tw,
        text_layers=count("transformer.resblocks"),
        text_heads=int(meta.get("text_heads", tw // 64)))


def build_model(state, meta=None):
    """A float32 CLIP in eval mode from an OpenAI-named state dict {name: array}."""
    model = model_for_shapes({k: tuple(v.shape) for k, v in state.items()}, meta)
    tensors = {k: torch.from_numpy(np.array(v, dtype=np.float32)) for k, v in state.items()}
    model.load_state_dict(tensors, strict=True)
    return model.eval()


def load_model(path):
    """build_model from an OpenAI-named safetensors file, read one tensor at a time so that
    the peak memory is the model plus its largest tensor (no mapping of the whole file)."""
    with open(path, "rb") as f:
        n = int.from_bytes(f.read(8), "little")
        header = json.loads(f.read(n).decode("utf-8"))
        meta = header.pop("__metadata__", {}) or {}
        if "visual.conv1.weight" not in header:
            raise ValueError(f"{path}: not an OpenAI-named CLIP (no visual.conv1.weight); "
                             "write one with gen_clip --naming openai")
        model = model_for_shapes({k: tuple(v["shape"]) for k, v in header.items()}, meta)
        params = model.state_dict(keep_vars=True)
        if set(params) != set(header):
            raise ValueError(f"{path}: tensors differ from OpenAI's CLIP: "
                             f"{sorted(set(params) ^ set(header))[:5]}")
        with torch.no_grad():
            for name, info in header.items():
                b, e = info["data_offsets"]
                f.seek(8 + n + b)
                buf = np.frombuffer(f.read(e - b), dtype=np.uint8)
                if info["dtype"] == "BF16":
                    arr = (buf.view("<u2").astype(np.uint32) << 16).view(np.float32)
                else:
                    arr = buf.view(np.dtype(_ST_DTYPES[info["dtype"]]).newbyteorder("<"))
                arr = arr.astype(np.float32).reshape(info["shape"])
                params[name].copy_(torch.from_numpy(arr))
    return model.eval()
