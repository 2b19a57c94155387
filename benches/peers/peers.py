#!/usr/bin/env python3
"""peers.py: PyTorch training of the same MLP family as errmap's `training` criterion bench, and errmap/peer ratios.

Same work as benches/training_bench.rs: per part a 48 x 32 grid (1536 samples) of the +-40 um
web-plate field over 600 x 300 mm, inputs scaled to [-1, 1], targets standardised; MLP
2-32-32-1 tanh, Glorot-uniform, full-batch Adam (beta 0.9/0.999, eps 1e-8, lr 0.01), EPOCHS
epochs; families of 1, 8 and 32 parts. float32, CPU threads = cores (CUDA too where present).

Two PyTorch variants: `loop` trains the parts one after another (what a user writes first);
`batched` trains all parts as one batched model with torch.bmm (the fastest plain-PyTorch way).

errmap figures come from criterion's output (target/criterion/training/*/new/estimates.json):
run `cargo bench --bench errmap_benches -- training` first. Ratio = errmap throughput /
peer throughput (> 1: errmap faster).

Usage: python3 benches/peers/peers.py [--epochs 10] [--repeats 5] [--criterion target/criterion]
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

GRID_U, GRID_V = 48, 32
HIDDEN = (32, 32)


def field_um(u, v, k):
    return (-40.0 * np.sin(math.pi * u / 600.0) * np.sin(math.pi * v / 300.0)
            + 6.0 * (u / 600.0 - 0.5) + 0.5 * k * (v / 300.0))


def family(parts):
    """List of (inputs [n,2] float32, targets [n] float32), as errmap's bench builds them."""
    i, j = np.meshgrid(np.arange(GRID_U), np.arange(GRID_V))  # row j, column i: u fastest
    u = 600.0 * i.ravel() / (GRID_U - 1)
    v = 300.0 * j.ravel() / (GRID_V - 1)
    out = []
    for k in range(parts):
        e = field_um(u, v, k)
        std = e.std() if e.std() > 1e-12 else 1.0
        x = np.stack([2.0 * u / 600.0 - 1.0, 2.0 * v / 300.0 - 1.0], axis=1).astype(np.float32)
        t = ((e - e.mean()) / std).astype(np.float32)
        out.append((x, t))
    return out


def torch_loop(torch, sets, epochs, device):
    """Parts one after another: nn.Sequential + torch.optim.Adam, full batch."""
    for x, t in sets:
        x = torch.from_numpy(x).to(device)
        t = torch.from_numpy(t).to(device).unsqueeze(1)
        layers = []
        sizes = (2,) + HIDDEN + (1,)
        for a, b in zip(sizes[:-1], sizes[1:]):
            lin = torch.nn.Linear(a, b)
            torch.nn.init.xavier_uniform_(lin.weight)
            torch.nn.init.zeros_(lin.bias)
            layers += [lin, torch.nn.Tanh()]
        model = torch.nn.Sequential(*layers[:-1]).to(device)
        opt = torch.optim.Adam(model.parameters(), lr=0.01, betas=(0.9, 0.999), eps=1e-8)
        for _ in range(epochs):
            opt.zero_grad(set_to_none=True)
            loss = torch.mean((model(x) - t) ** 2)
            loss.backward()
            opt.step()
    if device != "cpu":
        torch.cuda.synchronize()


def torch_batched(torch, sets, epochs, device):
    """All parts at once: weights [K, out, in] and torch.bmm (sets have equal sizes here)."""
    k = len(sets)
    x = torch.from_numpy(np.stack([s[0] for s in sets])).to(device)          # [K, n, 2]
    t = torch.from_numpy(np.stack([s[1] for s in sets])).to(device)[..., None]  # [K, n, 1]
    sizes = (2,) + HIDDEN + (1,)
    params = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        limit = math.sqrt(6.0 / (a + b))
        w = (torch.rand(k, a, b, device=device) * 2 - 1) * limit
        params += [w.requires_grad_(), torch.zeros(k, 1, b, device=device, requires_grad=True)]
    opt = torch.optim.Adam(params, lr=0.01, betas=(0.9, 0.999), eps=1e-8)
    n_layers = len(sizes) - 1
    for _ in range(epochs):
        opt.zero_grad(set_to_none=True)
        h = x
        for l in range(n_layers):
            h = torch.baddbmm(params[2 * l + 1], h, params[2 * l])
            if l + 1 < n_layers:
                h = torch.tanh(h)
        # Sum over parts of each part's mean squared error: the same gradients per part.
        loss = ((h - t) ** 2).mean(dim=(1, 2)).sum()
        loss.backward()
        opt.step()
    if device != "cpu":
        torch.cuda.synchronize()


def best_time(fn, repeats):
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times), sum(times) / len(times)


def errmap_throughput(criterion_dir, backend, parts):
    path = os.path.join(criterion_dir, "training", backend, str(parts), "new", "estimates.json")
    bench = os.path.join(criterion_dir, "training", backend, str(parts), "new", "benchmark.json")
    try:
        with open(path) as f:
            mean_ns = json.load(f)["mean"]["point_estimate"]
        with open(bench) as f:
            elements = json.load(f)["throughput"]["Elements"]
    except (OSError, KeyError, ValueError, TypeError):
        return None
    return elements / (mean_ns * 1e-9)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=10, help="epochs per run (errmap's bench: 10)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--criterion", default="target/criterion", help="criterion output folder")
    ap.add_argument("--parts", default="1,8,32")
    args = ap.parse_args()
    try:
        import torch
    except ImportError:
        sys.exit("PyTorch is not installed: pip install -r benches/peers/requirements.txt")
    torch.manual_seed(1)
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    print(f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads, devices {devices}")
    print(f"{'parts':>5} {'peer':>20} {'peer sample*ep/s':>17} {'errmap cpu':>12} {'errmap gpu':>12} "
          f"{'cpu/peer':>9} {'gpu/peer':>9}")
    for parts in [int(p) for p in args.parts.split(",")]:
        sets = family(parts)
        work = parts * GRID_U * GRID_V * args.epochs
        ours = {b: errmap_throughput(args.criterion, b, parts) for b in ("cpu", "gpu")}
        for device in devices:
            for name, fn in (("loop", torch_loop), ("batched", torch_batched)):
                best, _mean = best_time(lambda: fn(torch, sets, args.epochs, device), args.repeats)
                peer = work / best
                ratio = {b: (f"{ours[b] / peer:9.2f}" if ours[b] else f"{'-':>9}") for b in ours}
                fmt = {b: (f"{ours[b]:12.3e}" if ours[b] else f"{'-':>12}") for b in ours}
                print(f"{parts:>5} {'torch ' + device + ' ' + name:>20} {peer:17.3e} "
                      f"{fmt['cpu']} {fmt['gpu']} {ratio['cpu']} {ratio['gpu']}")


if __name__ == "__main__":
    main()
