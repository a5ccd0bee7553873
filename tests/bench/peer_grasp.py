#!/usr/bin/python3
"""Benchmark peer: F3RM's grasp optimisation written in plain PyTorch, on the CPU.

BENCHMARK PEER ONLY. Nothing in the product or the tests imports or runs this; run.sh's
`grasp` benchmark runs it beside bench_grasp so that our grasp request can be reported as a
ratio to PyTorch on the same threads in the same run. It needs Debian's python3-torch (1.13)
and python3-numpy: run it with /usr/bin/python3.

Input: the folder bench_grasp --dump DIR wrote (see tests/bench/bench_grasp.c): the voxel
cache's alpha, the kept voxels' alpha*f with their flat indices, the grid, the query points,
each task's embedding Z, the candidate voxels, the SO(3) rotations and the search options.
Loading builds the dense alpha*f grid, channels last, (nz*ny*nx + 1, D) float32, with a last
row of zeros that every corner outside the grid reads; that is outside the clock.

The search (timed), the way F3RM does it, with full D-dimensional features and autograd:
  cost     J(T) = -cos(z_T, Z), z_T (N_q, D) the grid sampled trilinearly between voxel
           centres at x_i = R p_i + t (a hand-written gather of the 8 corners' rows, weights
           from the fractional position; 0 where the corner keeps no features or lies outside
           the grid): the same J as lib/grasp, whose 64-d factorisation this peer does not use
  scoring  every candidate pose (voxel centre x rotation), batched, without gradient
  keep     the n_keep lowest costs. NO COLLISION CHECK here (ours rejects colliding poses
           before and after optimising), so the peer's kept poses and best score may differ
           from ours; the work per pose is the same
  optimise torch.optim.Adam (betas 0.9/0.999, eps 1e-8; lr_translation_m on t, lr_rotation_rad
           on w) over a translation t and a rotation vector w with R = exp([w]) R_0 (so(3)
           exponential map by Rodrigues), gradients by autograd, `iterations` steps; after
           each step the worst prune_fraction (2.5 %) of the poses by the costs just computed
           are dropped (at least one) down to n_final; a last evaluation ranks the survivors
Evaluations are counted as ours are: scored poses + poses alive at each of the iterations + 1.

Usage:
  /usr/bin/python3 tests/bench/peer_grasp.py DUMP_DIR [--threads N] [--runs N] [--batch B]
It runs a short warm-up (the first task on a few candidates for 2 iterations), then --runs
(default 1) requests of each task, and prints one line:
  bench=grasp_peer threads=N torch=... seconds=P50 min_s=... max_s=... candidates=...
  rotations=... poses_scored=... poses_optimised=... iterations=... evaluations=...
  best_score=... best_score_mug=... best_score_box=... collision_check=none
  cost_check_max_abs=... peak_rss_mb=...
seconds is the p50 of one request over the timed ones. cost_check_max_abs is the largest
|J_peer - J_ours| at our best pose of each task (bench_grasp's results), a check that both
compute the same cost (float32 here, so about 1e-5 is agreement).
"""
import argparse
import json
import math
import os
import resource
import sys
import time

import numpy as np
import torch


def load(dump):
    with open(os.path.join(dump, "bench_grasp.json")) as f:
        meta = json.load(f)
    g = meta["grid"]
    nx, ny, nz, D = g["nx"], g["ny"], g["nz"], meta["dim"]
    n_vox = nx * ny * nz
    alpha = np.load(os.path.join(dump, "alpha.npy"))
    assert alpha.shape == (nz, ny, nx), alpha.shape
    idx = torch.from_numpy(np.load(os.path.join(dump, "kept_index.npy")))
    feat = torch.from_numpy(np.load(os.path.join(dump, "kept_feat.npy")))
    assert feat.shape == (idx.shape[0], D), feat.shape
    t0 = time.perf_counter()
    grid = torch.zeros(n_vox + 1, D, dtype=torch.float32)  # last row: outside / no features
    grid[idx] = feat
    del feat
    build_s = time.perf_counter() - t0
    tasks = {}
    for name in meta["tasks"]:
        tasks[name] = torch.from_numpy(np.load(os.path.join(dump, "Z_%s.npy" % name)))
    return {
        "meta": meta,
        "grid": grid,
        "build_s": build_s,
        "p": torch.from_numpy(np.load(os.path.join(dump, "query_points.npy"))),
        "tasks": tasks,
        "cand": torch.from_numpy(np.load(os.path.join(dump, "candidates.npy"))),
        "quat": torch.from_numpy(np.load(os.path.join(dump, "rotations.npy"))),
    }


def quat_to_rot(q):
    """(n, 4) [w, x, y, z] unit quaternions -> (n, 3, 3)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], -1).reshape(-1, 3, 3)


def so3_exp(w):
    """(n, 3) rotation vectors -> (n, 3, 3) = exp([w]) (Rodrigues; Taylor near 0, where the
    norm has no gradient)."""
    th2 = (w * w).sum(-1, keepdim=True)
    th = th2.clamp_min(1e-12).sqrt()
    small = th2 < 1e-6
    a = torch.where(small, 1 - th2 / 6, torch.sin(th) / th)
    half = torch.sin(th / 2) / th
    b = torch.where(small, 0.5 - th2 / 24, 2 * half * half)
    zero = torch.zeros_like(w[:, 0])
    K = torch.stack([zero, -w[:, 2], w[:, 1],
                     w[:, 2], zero, -w[:, 0],
                     -w[:, 1], w[:, 0], zero], -1).reshape(-1, 3, 3)
    eye = torch.eye(3, dtype=w.dtype).expand_as(K)
    return eye + a[..., None] * K + b[..., None] * (K @ K)


class Field:
    """The dense alpha*f grid and J over batches of poses."""

    def __init__(self, data):
        g = data["meta"]["grid"]
        self.grid = data["grid"]
        self.n_vox = self.grid.shape[0] - 1
        self.nx, self.ny, self.nz = g["nx"], g["ny"], g["nz"]
        self.min = torch.tensor(g["min"], dtype=torch.float32)
        self.vs = float(g["voxel_size"])
        self.p = data["p"]  # (N_q, 3)

    def sample(self, R, t):
        """z_T (B, N_q, D) at x = R p + t for R (B, 3, 3), t (B, 3)."""
        x = torch.einsum("bij,qj->bqi", R, self.p) + t[:, None, :]
        u = (x - self.min) / self.vs - 0.5
        i0 = torch.floor(u.detach())
        f = u - i0
        i0 = i0.long()
        n = (self.nx, self.ny, self.nz)
        z = None
        for k in range(8):
            d = (k & 1, (k >> 1) & 1, (k >> 2) & 1)
            ok = None
            w = None
            for a in range(3):
                ia = i0[..., a] + d[a]
                va = (ia >= 0) & (ia < n[a])
                ok = va if ok is None else ok & va
                wa = f[..., a] if d[a] else 1 - f[..., a]
                w = wa if w is None else w * wa
            flat = ((i0[..., 2] + d[2]) * self.ny + (i0[..., 1] + d[1])) * self.nx + (i0[..., 0] + d[0])
            flat = torch.where(ok, flat, torch.full_like(flat, self.n_vox))
            rows = self.grid.index_select(0, flat.reshape(-1)).reshape(*flat.shape, -1)
            term = w[..., None] * rows
            z = term if z is None else z + term
        return z

    def cost(self, R, t, Z, z_norm):
        """J (B,) = -cos(z_T, Z), 0 where z_T = 0; also cos (B,)."""
        z = self.sample(R, t)
        num = (z * Z).sum((1, 2))
        den2 = (z * z).sum((1, 2))
        cos = torch.where(den2 > 1e-30, num / (den2.clamp_min(1e-30).sqrt() * z_norm),
                          torch.zeros_like(num))
        return -cos, cos


def search(field, data, Z, opt, batch):
    """One request; returns (best score, counts)."""
    meta = data["meta"]
    g = meta["grid"]
    z_norm = Z.norm()
    cand, R_rot = data["cand"], quat_to_rot(data["quat"]).float()
    n_rot = R_rot.shape[0]
    n_poses = cand.shape[0] * n_rot
    nx, ny = g["nx"], g["ny"]
    ix, iy, iz = cand % nx, (cand // nx) % ny, cand // (nx * ny)
    centres = (torch.stack([ix, iy, iz], -1).float() + 0.5) * field.vs + field.min  # (n_cand, 3)
    evaluations = 0

    # score every candidate pose, id = candidate * n_rot + rotation
    costs = torch.empty(n_poses)
    with torch.no_grad():
        for s in range(0, n_poses, batch):
            ids = torch.arange(s, min(s + batch, n_poses))
            c, _ = field.cost(R_rot[ids % n_rot], centres[ids // n_rot], Z, z_norm)
            costs[s:s + ids.shape[0]] = c
    evaluations += n_poses
    order = torch.sort(costs, stable=True).indices[:opt["n_keep"]]
    n_keep = order.shape[0]
    R0 = R_rot[order % n_rot].clone()
    t = centres[order // n_rot].clone().requires_grad_()
    w = torch.zeros(n_keep, 3, requires_grad=True)

    def adam(t, w):
        return torch.optim.Adam([{"params": [t], "lr": opt["lr_translation_m"]},
                                 {"params": [w], "lr": opt["lr_rotation_rad"]}],
                                betas=(opt["adam_beta1"], opt["adam_beta2"]), eps=opt["adam_eps"])

    optim = adam(t, w)
    n = n_keep
    for it in range(opt["iterations"]):
        cur = torch.empty(n)
        optim.zero_grad(set_to_none=False)
        for s in range(0, n, batch):
            e = min(s + batch, n)
            J, _ = field.cost(so3_exp(w[s:e]) @ R0[s:e], t[s:e], Z, z_norm)
            J.sum().backward()  # poses are independent: the batch's sum gives each its own
            cur[s:e] = J.detach()
        optim.step()
        evaluations += n
        if n > opt["n_final"]:
            drop = max(1, int(opt["prune_fraction"] * n))
            drop = min(drop, n - opt["n_final"])
            keep = torch.sort(cur, stable=True).indices[:n - drop]
            t2 = t.detach()[keep].clone().requires_grad_()
            w2 = w.detach()[keep].clone().requires_grad_()
            optim2 = adam(t2, w2)
            for old, new in ((t, t2), (w, w2)):
                st = optim.state[old]
                optim2.state[new] = {"step": st["step"].clone(),
                                     "exp_avg": st["exp_avg"][keep].clone(),
                                     "exp_avg_sq": st["exp_avg_sq"][keep].clone()}
            t, w, R0, optim, n = t2, w2, R0[keep], optim2, n - drop
    with torch.no_grad():
        J, cos = field.cost(so3_exp(w) @ R0, t, Z, z_norm)
    evaluations += n
    best = int(torch.argmin(J))
    return float(cos[best]), {"candidates": int(cand.shape[0]), "rotations": n_rot,
                              "poses_scored": n_poses, "poses_optimised": n_keep,
                              "iterations": opt["iterations"], "evaluations": evaluations}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dump", help="the folder bench_grasp --dump wrote")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=1, help="timed requests per task")
    ap.add_argument("--batch", type=int, default=128, help="poses per batch")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.set_grad_enabled(True)
    data = load(a.dump)
    meta, opt = data["meta"], data["meta"]["options"]
    field = Field(data)

    # the same cost as ours at our best poses
    check = 0.0
    res = meta.get("results", {})
    with torch.no_grad():
        for name, Z in data["tasks"].items():
            if "top_pose_%s" % name not in res:
                continue
            T = torch.tensor(res["top_pose_%s" % name], dtype=torch.float64).reshape(4, 4)
            J, _ = field.cost(T[None, :3, :3].float(), T[None, :3, 3].float(), Z, Z.norm())
            check = max(check, abs(float(J[0]) - res["top_cost_%s" % name]))

    names = list(data["tasks"])
    # warm-up: the first task on a few candidates for 2 iterations (pages of the grid, thread
    # pool, allocator); a whole request would add minutes at D = 512
    n_rot = data["quat"].shape[0]
    few = dict(data, cand=data["cand"][:max(1, 2 * a.batch // n_rot)])
    search(field, few, data["tasks"][names[0]], dict(opt, iterations=2), a.batch)
    secs, best, counts = [], {}, None
    for _ in range(a.runs):
        for name in names:
            t0 = time.perf_counter()
            best[name], c = search(field, data, data["tasks"][name], opt, a.batch)
            secs.append(time.perf_counter() - t0)
            if counts is None or c["evaluations"] > counts["evaluations"]:
                counts = c
    secs.sort()
    k = len(secs)
    p50 = secs[k // 2] if k % 2 else 0.5 * (secs[k // 2 - 1] + secs[k // 2])
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print("bench=grasp_peer threads=%d torch=%s dim=%d seconds=%.4f min_s=%.4f max_s=%.4f "
          "requests=%d candidates=%d rotations=%d poses_scored=%d poses_optimised=%d "
          "iterations=%d evaluations=%d query_points=%d lookups=%d best_score=%.4f %s "
          "collision_check=none dense_grid_mb=%.1f cost_check_max_abs=%.2e peak_rss_mb=%.1f"
          % (a.threads, torch.__version__.split("+")[0], meta["dim"], p50, secs[0], secs[-1], k,
             counts["candidates"], counts["rotations"], counts["poses_scored"],
             counts["poses_optimised"], counts["iterations"], counts["evaluations"],
             data["p"].shape[0], counts["evaluations"] * data["p"].shape[0] * 8, best[names[0]],
             " ".join("best_score_%s=%.4f" % (n, best[n]) for n in names),
             data["grid"].numel() * 4 / 1048576.0, check, peak))
    return 0


if __name__ == "__main__":
    sys.exit(main())
