#!/usr/bin/python3
"""Benchmark peer: our field model written in plain PyTorch, trained on the CPU.

BENCHMARK PEER ONLY. Nothing in the product or the tests imports or runs this; benchmarks run
it beside the C implementation so that the C figure can be reported as a ratio to PyTorch on
the same machine in the same run. It needs Debian's python3-torch (1.13) and python3-numpy:
run it with /usr/bin/python3 (a pyenv python3 earlier on PATH has no torch).

The model is the one of lib/field/model.h, written the way a plain PyTorch NeRF is (autograd,
no custom kernels, no C extensions, no torch.compile):
  density: hash grid 16 levels x 2 features, 2^18 entries, N_min 16, N_max 2048
           (hashgrid.h conventions) -> MLP 32->64->ReLU->16, no biases;
           sigma = trunc_exp(out[:,0]) (exp of the value clamped to [-15, 15], gradient exp of
           the clamped value), geo = out (16)
  colour:  [SH4(d) (16), geo (16)] -> 32->64->ReLU->64->ReLU->3, sigmoid
  feature (--feature-dim D > 0): hash grid 12 x 4, 2^18, 16..128 -> 48->64->ReLU->64->ReLU
           -> h (64), then a 64->D linear layer per sample (as F3RM does; our C code instead
           composites h per ray and applies the D-wide layer once per ray)
  render:  samples in rays of K (32) samples, alpha = 1-exp(-sigma dt), T by cumprod,
           w = T alpha, rgb = sum w c + T_n (white background), feat = sum w f
  loss:    MSE(rgb) + MSE(feat) when D > 0; backward; torch.optim.Adam(eps=1e-15) step.
Inputs are random (torch.manual_seed(0)): positions uniform in the unit cube, one random unit
direction per ray, dt = sqrt(3)/1024, random targets; a pool of 4 batches is made before the
clock starts and cycled through.

Usage:
  /usr/bin/python3 tests/bench/peer_field.py [--threads N] [--samples S] [--feature-dim D]
                                             [--seconds T] [--json]
  /usr/bin/python3 tests/bench/peer_field.py --selftest
It runs 2 warm-up steps, then steps for about --seconds seconds, and prints one line (JSON
with --json): {"peer":"pytorch","torch":...,"threads":N,"feature_dim":D,"samples_per_step":S,
"steps":n,"seconds":t,"samples_per_s":x,"peak_rss_mb":m}. --selftest prints the level
geometry of a 2-level config and of the default grids and checks the encoding of a few points
against a scalar transcription of hashgrid.h's formulas; exit status 0 when all agree.
"""
import argparse
import json
import math
import resource
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

PRIME_Y = 2654435761
PRIME_Z = 805459861
MASK32 = 0xFFFFFFFF


def level_geometry(n_levels, log2_t, n_min, n_max):
    """hashgrid.h: b = exp((ln N_max - ln N_min)/(L-1)); scale_l = N_min b^l - 1 in double,
    rounded to float; res_l = ceil(scale_l) + 1; dense when res^3 <= T (entries = res^3
    rounded up to a multiple of 8), else hashed with T entries."""
    ln_b = (math.log(n_max) - math.log(n_min)) / (n_levels - 1) if n_levels > 1 else 0.0
    t = 1 << log2_t
    levels, offset = [], 0
    for l in range(n_levels):
        scale = torch.tensor(n_min * math.exp(l * ln_b) - 1.0, dtype=torch.float32).item()
        res = int(math.ceil(scale)) + 1
        dense = res ** 3 <= t
        n_entries = (res ** 3 + 7) & ~7 if dense else t
        levels.append(dict(scale=scale, res=res, dense=dense, n_entries=n_entries, offset=offset))
        offset += n_entries
    return levels, offset


class HashGrid(nn.Module):
    """Multiresolution hash encoding over one concatenated table (entries of all levels, in
    level order), gathered with advanced indexing; autograd does the scatter-add."""

    def __init__(self, n_levels, n_features, log2_t, n_min, n_max):
        super().__init__()
        self.L, self.F = n_levels, n_features
        self.levels, n_total = level_geometry(n_levels, log2_t, n_min, n_max)
        self.table = nn.Parameter(torch.empty(n_total, n_features).uniform_(-1e-4, 1e-4))
        lv = self.levels
        self.register_buffer("scale", torch.tensor([v["scale"] for v in lv], dtype=torch.float32))
        self.register_buffer("res", torch.tensor([v["res"] for v in lv], dtype=torch.int64))
        self.register_buffer("dense", torch.tensor([v["dense"] for v in lv]))
        self.register_buffer("n_entries", torch.tensor([v["n_entries"] for v in lv]))
        self.register_buffer("offset", torch.tensor([v["offset"] for v in lv]))
        self.hash_mask = (1 << log2_t) - 1
        # corner c takes +1 on axis d when bit d of c is set
        bits = torch.tensor([[(c >> d) & 1 for d in range(3)] for c in range(8)])
        self.register_buffer("bits", bits)  # (8, 3) int64

    def corners(self, x):
        """Table rows (B, L, 8) and trilinear weights (B, L, 8) of the 8 corners per level."""
        x = x.clamp(0.0, 1.0)
        pos = x[:, None, :] * self.scale[None, :, None] + 0.5  # (B, L, 3) float32
        g = torch.floor(pos)
        frac = pos - g
        c = g.long()[:, :, None, :] + self.bits[None, None]  # (B, L, 8, 3)
        b = self.bits.bool()[None, None]
        wd = torch.where(b, frac[:, :, None, :], 1.0 - frac[:, :, None, :])  # (B, L, 8, 3)
        w = wd[..., 0] * wd[..., 1] * wd[..., 2]  # axis order x, y, z
        cx, cy, cz = c[..., 0], c[..., 1], c[..., 2]
        r = self.res[None, :, None]
        dense_idx = (cx + cy * r + cz * r * r) % self.n_entries[None, :, None]
        hash_idx = (cx ^ ((cy * PRIME_Y) & MASK32) ^ ((cz * PRIME_Z) & MASK32)) & self.hash_mask
        idx = torch.where(self.dense[None, :, None], dense_idx, hash_idx)
        return idx + self.offset[None, :, None], w

    def forward(self, x):
        idx, w = self.corners(x)
        feats = self.table[idx]  # (B, L, 8, F)
        out = (feats * w[..., None]).sum(dim=2)  # (B, L, F)
        return out.reshape(x.shape[0], self.L * self.F)


def mlp(n_in, n_hidden, n_hidden_layers, n_out):
    """tiny-cuda-nn's FullyFusedMLP shape: no biases, ReLU hidden, linear output,
    Glorot-uniform weights."""
    dims = [n_in] + [n_hidden] * n_hidden_layers + [n_out]
    layers = []
    for i in range(len(dims) - 1):
        lin = nn.Linear(dims[i], dims[i + 1], bias=False)
        nn.init.xavier_uniform_(lin.weight)
        layers.append(lin)
        if i < len(dims) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


def sh4(d):
    """Degree-4 real SH of unit directions (B,3) -> (B,16), tiny-cuda-nn's constants (sh.c)."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    xy, xz, yz, x2, y2, z2 = x * y, x * z, y * z, x * x, y * y, z * z
    return torch.stack([
        torch.full_like(x, 0.28209479177387814),
        -0.48860251190291987 * y,
        0.48860251190291987 * z,
        -0.48860251190291987 * x,
        1.0925484305920792 * xy,
        -1.0925484305920792 * yz,
        0.94617469575755997 * z2 - 0.31539156525251999,
        -1.0925484305920792 * xz,
        0.54627421529603959 * x2 - 0.54627421529603959 * y2,
        0.59004358992664352 * y * (-3.0 * x2 + y2),
        2.8906114426405538 * xy * z,
        0.45704579946446572 * y * (1.0 - 5.0 * z2),
        0.3731763325901154 * z * (5.0 * z2 - 3.0),
        0.45704579946446572 * x * (1.0 - 5.0 * z2),
        1.4453057213202769 * z * (x2 - y2),
        0.59004358992664352 * x * (-x2 + 3.0 * y2),
    ], dim=1)


class TruncExp(torch.autograd.Function):
    """exp(clamp(x, -15, 15)) with gradient dout * out (Instant-NGP's truncated exp)."""

    @staticmethod
    def forward(ctx, x):
        out = torch.exp(x.clamp(-15.0, 15.0))
        ctx.save_for_backward(out)
        return out

    @staticmethod
    def backward(ctx, dout):
        (out,) = ctx.saved_tensors
        return dout * out


class Field(nn.Module):
    def __init__(self, feature_dim):
        super().__init__()
        self.grid = HashGrid(16, 2, 18, 16, 2048)
        self.density = mlp(32, 64, 1, 16)
        self.colour = mlp(32, 64, 2, 3)
        self.D = feature_dim
        if feature_dim > 0:
            self.feat_grid = HashGrid(12, 4, 18, 16, 128)
            self.feat_mlp = nn.Sequential(mlp(48, 64, 1, 64), nn.ReLU())
            self.feat_out = nn.Linear(64, feature_dim, bias=False)
            nn.init.xavier_uniform_(self.feat_out.weight)

    def forward(self, x, d):
        geo = self.density(self.grid(x))
        sigma = TruncExp.apply(geo[:, 0])
        rgb = torch.sigmoid(self.colour(torch.cat([sh4(d), geo], dim=1)))
        feat = self.feat_out(self.feat_mlp(self.feat_grid(x))) if self.D > 0 else None
        return sigma, rgb, feat


def composite(sigma, rgb, feat, dt, K):
    """Fixed-length rays of K samples: (S,) -> (R, K). White background for rgb."""
    R = sigma.shape[0] // K
    alpha = 1.0 - torch.exp(-sigma.view(R, K) * dt)
    trans = torch.cumprod(1.0 - alpha, dim=1)  # T after each sample
    T = torch.cat([torch.ones(R, 1), trans[:, :-1]], dim=1)  # T before each sample
    w = T * alpha
    out_rgb = (w[..., None] * rgb.view(R, K, 3)).sum(dim=1) + trans[:, -1:]
    out_feat = None
    if feat is not None:
        out_feat = (w[..., None] * feat.view(R, K, -1)).sum(dim=1)
    return out_rgb, out_feat


def make_batch(S, K, D):
    R = S // K
    x = torch.rand(S, 3)
    d = F.normalize(torch.randn(R, 3), dim=1).repeat_interleave(K, dim=0)
    rgb_gt = torch.rand(R, 3)
    feat_gt = torch.randn(R, D) if D > 0 else None
    return x, d, rgb_gt, feat_gt


def train_step(model, opt, batch, dt, K):
    x, d, rgb_gt, feat_gt = batch
    opt.zero_grad(set_to_none=True)
    sigma, rgb, feat = model(x, d)
    out_rgb, out_feat = composite(sigma, rgb, feat, dt, K)
    loss = F.mse_loss(out_rgb, rgb_gt)
    if out_feat is not None:
        loss = loss + F.mse_loss(out_feat, feat_gt)
    loss.backward()
    opt.step()
    return loss.item()


# ---- selftest: the encoding against a scalar transcription of hashgrid.h ---------------------

def ref_encode(levels, table, F_, xi, log2_t):
    """One point, plain Python integers (uint32 arithmetic by masking) and float32 tensors."""
    f32 = lambda v: torch.tensor(v, dtype=torch.float32)
    out = []
    for lv in levels:
        acc = torch.zeros(F_)
        for corner in range(8):
            c, w = [], f32(1.0)
            for dim in range(3):
                pos = f32(min(max(xi[dim], 0.0), 1.0)) * f32(lv["scale"]) + f32(0.5)
                g = torch.floor(pos)
                frac = pos - g
                bit = (corner >> dim) & 1
                w = w * (frac if bit else f32(1.0) - frac)
                c.append(int(g.item()) + bit)
            if lv["dense"]:
                r = lv["res"]
                idx = ((c[0] + c[1] * r + c[2] * r * r) & MASK32) % lv["n_entries"]
            else:
                h = (c[0] ^ ((c[1] * PRIME_Y) & MASK32) ^ ((c[2] * PRIME_Z) & MASK32)) & MASK32
                idx = h & ((1 << log2_t) - 1)
            acc = acc + w * table[lv["offset"] + idx]
        out.append(acc)
    return torch.cat(out)


def print_levels(name, levels):
    print(f"{name}:")
    for l, v in enumerate(levels):
        print(f"  level {l:2d}: scale {v['scale']:10.4f}  res {v['res']:5d}  "
              f"{'dense ' if v['dense'] else 'hashed'}  entries {v['n_entries']:7d}  "
              f"offset {v['offset']}")


def selftest():
    ok = True
    # 2 levels, T = 2^10, N_min 4, N_max 16: b = 4, scale = 4*4^l - 1 = 3, 15;
    # res = 4 (64 <= 1024: dense, 64 entries), 16 (4096 > 1024: hashed, 1024 entries).
    g = HashGrid(2, 2, 10, 4, 16)
    print_levels("2-level config (L=2, F=2, T=2^10, N_min=4, N_max=16)", g.levels)
    want = [(3.0, 4, True, 64, 0), (15.0, 16, False, 1024, 64)]
    got = [(v["scale"], v["res"], v["dense"], v["n_entries"], v["offset"]) for v in g.levels]
    print(f"  expected (scale, res, dense, entries, offset): {want}  "
          f"{'OK' if got == want else 'MISMATCH'}")
    ok &= got == want
    with torch.no_grad():
        g.table.copy_(torch.randn_like(g.table))
    # hand-picked points: a corner of the cube, the centre, an interior point, the upper face
    # (where level 0's upper corner reaches coordinate res = 4 and wraps modulo 64), and points
    # outside the cube (clamped).
    pts = [[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [0.1, 0.7, 0.3], [1.0, 1.0, 1.0],
           [0.99, 0.2, 0.98], [-0.3, 1.7, 0.5]]
    x = torch.tensor(pts, dtype=torch.float32)
    idx, w = g.corners(x)
    with torch.no_grad():
        enc = g(x)
    for i, p in enumerate(pts):
        ref = ref_encode(g.levels, g.table.detach(), 2, p, 10)
        err = (enc[i] - ref).abs().max().item()
        print(f"  x = {p}: level-0 corners {idx[i, 0].tolist()}, level-1 corners "
              f"{(idx[i, 1] - 64).tolist()}, weight sums "
              f"{[round(s, 6) for s in w[i].sum(1).tolist()]}, |peer - ref| = {err:.2e}")
        ok &= err <= 1e-5 and bool(((w[i].sum(1) - 1).abs() < 1e-5).all())
    # the spatial hash by hand for one vertex: (1, 2, 3) -> 1 ^ 2*2654435761 ^ 3*805459861
    h = (1 ^ ((2 * PRIME_Y) & MASK32) ^ ((3 * PRIME_Z) & MASK32)) & 1023
    print(f"  hash(1, 2, 3) mod 2^10 = {h} (expected 1 ^ 1013904226 ^ 2416379583 = "
          f"{(1 ^ 1013904226 ^ 2416379583) & 1023})")
    ok &= h == ((1 ^ 1013904226 ^ 2416379583) & 1023)
    print_levels("density grid (16 x 2, T=2^18, 16..2048)", level_geometry(16, 18, 16, 2048)[0])
    print_levels("feature grid (12 x 4, T=2^18, 16..128)", level_geometry(12, 18, 16, 128)[0])
    print("selftest", "OK" if ok else "FAILED")
    return 0 if ok else 1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--samples", type=int, default=65536)
    ap.add_argument("--feature-dim", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rays-of", type=int, default=32, help="samples per ray K (32)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--selftest", action="store_true")
    a = ap.parse_args()
    if a.selftest:
        return selftest()
    K = a.rays_of
    if a.samples < K or a.samples % K:
        ap.error(f"--samples must be a positive multiple of {K}")
    torch.set_num_threads(a.threads)
    torch.set_num_interop_threads(a.threads)
    torch.manual_seed(0)
    model = Field(a.feature_dim)
    opt = torch.optim.Adam(model.parameters(), lr=1e-2, betas=(0.9, 0.99), eps=1e-15)
    dt = math.sqrt(3.0) / 1024.0
    pool = [make_batch(a.samples, K, a.feature_dim) for _ in range(4)]
    for i in range(2):
        train_step(model, opt, pool[i % len(pool)], dt, K)
    steps, t0 = 0, time.perf_counter()
    while True:
        train_step(model, opt, pool[(steps + 2) % len(pool)], dt, K)
        steps += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= a.seconds:
            break
    res = {"peer": "pytorch", "torch": torch.__version__, "threads": a.threads,
           "feature_dim": a.feature_dim, "samples_per_step": a.samples, "steps": steps,
           "seconds": round(elapsed, 3), "samples_per_s": round(steps * a.samples / elapsed, 1),
           "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)}
    if a.json:
        print(json.dumps(res))
    else:
        print(f"pytorch {res['torch']} peer: {res['samples_per_s']:.0f} samples/s "
              f"({steps} steps of {a.samples} samples in {elapsed:.1f} s, {a.threads} threads, "
              f"D={a.feature_dim}, peak RSS {res['peak_rss_mb']:.0f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
