#!/usr/bin/env python3
"""training_ratio.py: errmap's trainers against PyTorch CPU on the same training work, in one run, with ratios.

For each family size, rounds alternate: PyTorch batched (bmm), PyTorch loop, then
`errmap bench training --json` for each backend asked. Same work on both sides (peers.py's
`family` and `torch_*`: per part 1536 samples of the web-plate field, MLP 2-32-32-1 tanh,
full-batch Adam). errmap's figure is its own sample_epochs_per_s (training only, pipeline
build excluded); PyTorch's is timed around its training loop after a warm-up. Medians of the
rounds are printed, and each ratio errmap / PyTorch (> 1: errmap faster).

Wall-clock rates move with whatever else runs on the machine, so every round also records the
load average before it, each side's work per CPU second of its whole process (errmap's
`sample_epochs_per_cpu_s`; PyTorch's `time.process_time()` around the same loop) and the best
round. On a busy machine compare the ratios of one run, and prefer the per-CPU-second and
best-round figures; PyTorch's OpenMP threads spin while waiting, so its CPU time can exceed its
useful work when cores are contended.

Usage: python3 benches/peers/training_ratio.py --errmap target/release/errmap \
           [--parts 1,8,32] [--epochs 200] [--rounds 3] [--backends cpu,gpu] [--json FILE]
           [--torch-threads N] [--no-loop]
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import peers


def torch_rate(torch, fn, sets, epochs):
    """(sample·epochs per wall second, per CPU second of the process)."""
    fn(torch, sets, 2, "cpu")  # warm-up
    cpu, start = time.process_time(), time.perf_counter()
    fn(torch, sets, epochs, "cpu")
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    work = len(sets) * len(sets[0][1]) * epochs
    return work / wall, work / max(cpu, 1e-9)


def errmap_rate(binary, backend, parts, epochs):
    out = subprocess.run(
        [binary, "bench", "training", "--json", "--backend", backend,
         "--parts", str(parts), "--samples", str(peers.GRID_U * peers.GRID_V), "--epochs", str(epochs)],
        check=True, capture_output=True, text=True).stdout
    report = json.loads(out)
    per_cpu = report.get("sample_epochs_per_cpu_s") or float("nan")
    return (report["sample_epochs_per_s"], per_cpu), report["device"], report["pipeline_build_s"]


def load():
    return os.getloadavg()[0]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--errmap", required=True, help="the errmap binary (release build)")
    ap.add_argument("--parts", default="1,8,32")
    ap.add_argument("--epochs", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--backends", default="cpu,gpu")
    ap.add_argument("--json", help="also write every round's figures to this file")
    ap.add_argument("--no-loop", action="store_true",
                    help="skip PyTorch's per-part loop (slow; the ratios are against batched)")
    ap.add_argument("--torch-threads", type=int,
                    help="PyTorch's intra-op threads (default: its own choice, the cores); 1 "
                         "avoids OpenMP's waits on a machine whose cores are contended")
    args = ap.parse_args()
    try:
        import torch
    except ImportError:
        sys.exit("PyTorch is not installed: pip install -r benches/peers/requirements.txt")
    torch.manual_seed(1)
    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads; epochs {args.epochs}, rounds {args.rounds}")
    backends = [b for b in args.backends.split(",") if b]
    print(f"load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    results = []
    for parts in [int(p) for p in args.parts.split(",")]:
        sets = peers.family(parts)
        torch_sides = [("torch batched", peers.torch_batched)]
        if not args.no_loop:
            torch_sides.append(("torch loop", peers.torch_loop))
        sides = [name for name, _ in torch_sides] + [f"errmap {b}" for b in backends]
        rates = {k: [] for k in sides}
        per_cpu = {k: [] for k in sides}
        loads = []
        devices = {}
        for _ in range(args.rounds):
            loads.append(load())
            for side, fn in torch_sides:
                wall, cpu = torch_rate(torch, fn, sets, args.epochs)
                rates[side].append(wall)
                per_cpu[side].append(cpu)
            for b in backends:
                (wall, cpu), device, build = errmap_rate(args.errmap, b, parts, args.epochs)
                rates[f"errmap {b}"].append(wall)
                per_cpu[f"errmap {b}"].append(cpu)
                devices[b] = f"{device}, pipeline build {build:.2f} s"
        loads.append(load())
        med = {k: statistics.median(v) for k, v in rates.items()}
        best = {k: max(v) for k, v in rates.items()}
        med_cpu = {k: statistics.median(v) for k, v in per_cpu.items()}
        print(f"\n{parts} parts, load average {min(loads):.1f}–{max(loads):.1f} "
              f"(sample·epochs/s: median, best of {args.rounds}; per CPU second: median):")
        for k in sides:
            print(f"  {k:<16} {med[k]:10.3e} {best[k]:10.3e}   per CPU s {med_cpu[k]:10.3e}   "
                  f"rounds: {', '.join(f'{x:.3e}' for x in rates[k])}")
        for b in backends:
            e = f"errmap {b}"
            print(f"  {e} ({devices[b]}): {med[e] / med['torch batched']:.2f}x torch batched "
                  f"(best {best[e] / best['torch batched']:.2f}x, per CPU s "
                  f"{med_cpu[e] / med_cpu['torch batched']:.2f}x)"
                  + ("" if args.no_loop else f", {med[e] / med['torch loop']:.2f}x torch loop"))
        results.append({"parts": parts, "epochs": args.epochs, "load_average": loads,
                        "sample_epochs_per_s": rates, "sample_epochs_per_cpu_s": per_cpu,
                        "devices": devices})
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"torch": torch.__version__, "threads": torch.get_num_threads(),
                       "runs": results}, f, indent=1)


if __name__ == "__main__":
    main()
