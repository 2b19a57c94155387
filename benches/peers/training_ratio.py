#!/usr/bin/env python3
"""training_ratio.py: errmap's trainers against PyTorch CPU on the same training work, in one run, with ratios.

For each family size, rounds alternate: PyTorch batched (bmm), PyTorch loop, then
`errmap bench training --json` for each backend asked. Same work on both sides (peers.py's
`family` and `torch_*`: per part 1536 samples of the web-plate field, MLP 2-32-32-1 tanh,
full-batch Adam). errmap's figure is its own sample_epochs_per_s (training only, pipeline
build excluded); PyTorch's is timed around its training loop after a warm-up. Medians of the
rounds are printed, and each ratio errmap / PyTorch (> 1: errmap faster).

Usage: python3 benches/peers/training_ratio.py --errmap target/release/errmap \
           [--parts 1,8,32] [--epochs 200] [--rounds 3] [--backends cpu,gpu]
"""
import argparse
import json
import statistics
import subprocess
import sys
import time

import peers


def torch_rate(torch, fn, sets, epochs):
    fn(torch, sets, 2, "cpu")  # warm-up
    start = time.perf_counter()
    fn(torch, sets, epochs, "cpu")
    return len(sets) * len(sets[0][1]) * epochs / (time.perf_counter() - start)


def errmap_rate(binary, backend, parts, epochs):
    out = subprocess.run(
        [binary, "bench", "training", "--json", "--backend", backend,
         "--parts", str(parts), "--samples", str(peers.GRID_U * peers.GRID_V), "--epochs", str(epochs)],
        check=True, capture_output=True, text=True).stdout
    report = json.loads(out)
    return report["sample_epochs_per_s"], report["device"], report["pipeline_build_s"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--errmap", required=True, help="the errmap binary (release build)")
    ap.add_argument("--parts", default="1,8,32")
    ap.add_argument("--epochs", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--backends", default="cpu,gpu")
    args = ap.parse_args()
    try:
        import torch
    except ImportError:
        sys.exit("PyTorch is not installed: pip install -r benches/peers/requirements.txt")
    torch.manual_seed(1)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads; epochs {args.epochs}, rounds {args.rounds}")
    backends = [b for b in args.backends.split(",") if b]
    for parts in [int(p) for p in args.parts.split(",")]:
        sets = peers.family(parts)
        rates = {"torch batched": [], "torch loop": []}
        devices = {}
        for b in backends:
            rates[f"errmap {b}"] = []
        for _ in range(args.rounds):
            rates["torch batched"].append(torch_rate(torch, peers.torch_batched, sets, args.epochs))
            rates["torch loop"].append(torch_rate(torch, peers.torch_loop, sets, args.epochs))
            for b in backends:
                rate, device, build = errmap_rate(args.errmap, b, parts, args.epochs)
                rates[f"errmap {b}"].append(rate)
                devices[b] = f"{device}, pipeline build {build:.2f} s"
        med = {k: statistics.median(v) for k, v in rates.items()}
        print(f"\n{parts} parts (sample·epochs/s, median of {args.rounds}):")
        for k, v in med.items():
            print(f"  {k:<16} {v:10.3e}   rounds: {', '.join(f'{x:.3e}' for x in rates[k])}")
        for b in backends:
            e = med[f"errmap {b}"]
            print(f"  errmap {b} ({devices[b]}): {e / med['torch batched']:.2f}x torch batched, "
                  f"{e / med['torch loop']:.2f}x torch loop")


if __name__ == "__main__":
    main()
