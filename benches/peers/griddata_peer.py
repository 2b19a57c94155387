#!/usr/bin/env python3
"""Peer timing for errmap's interpolation bench: scipy griddata on the same probe points.

Reads a probe CSV (x_mm,y_mm,z_mm with nominal z = 30 mm, default plate_144.csv beside this
file), interpolates E = (z - 30) * 1000 um onto the 600 x 300 mm plate at 0.5 mm (1201 x 601
nodes), the same work as the `interp/resample_plate_0.5mm` group of benches/interp_bench.rs
(triangulation included), and prints the best and median wall time of several runs.

    pip install scipy
    python3 benches/peers/griddata_peer.py [PROBES.csv] [--repeats N]
"""
import argparse
import csv
import os
import statistics
import time

import numpy as np
from scipy.interpolate import griddata


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser()
    ap.add_argument("probes", nargs="?", default=os.path.join(here, "plate_144.csv"))
    ap.add_argument("--repeats", type=int, default=10)
    ap.add_argument("--nominal", type=float, default=30.0)
    args = ap.parse_args()
    with open(args.probes, newline="") as f:
        rows = list(csv.DictReader(f))
    pts = np.array([[float(r["x_mm"]), float(r["y_mm"])] for r in rows])
    e_um = np.array([(float(r["z_mm"]) - args.nominal) * 1000.0 for r in rows])
    gu, gv = np.meshgrid(np.linspace(0.0, 600.0, 1201), np.linspace(0.0, 300.0, 601))
    for method in ("cubic", "linear"):
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            out = griddata(pts, e_um, (gu, gv), method=method)
            times.append(time.perf_counter() - t0)
        inside = int(np.isfinite(out).sum())
        print(
            f"scipy griddata {method}: {len(pts)} points -> {gu.size} nodes ({inside} inside), "
            f"best {min(times) * 1e3:.1f} ms, median {statistics.median(times) * 1e3:.1f} ms"
        )


if __name__ == "__main__":
    main()
