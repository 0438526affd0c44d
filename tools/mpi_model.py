#!/usr/bin/env python3
"""Predicts strong and weak scaling of `vmls render --mpi` to 64 and 512 nodes (issue 30 §4)
from what tools/bench-mpi measured on one machine, and a stated network model.

Usage: tools/mpi_model.py VIRTUAL.csv BENCH.csv

Model, per frame of P pixels on N nodes (one rank and one device per node):
- render: the slowest brick. Strong scaling (fixed data): each brick's GPU time rendered alone
  on this device (`vmls render --bricks N`), measured up to the largest N in VIRTUAL.csv and
  extrapolated beyond as t(N) = t(N_max)·(N_max/N)^s, s the least-squares log-log slope of the
  measured counts from 8 on. Weak scaling (data grows with N, each node keeps one brick of the
  8-brick decomposition): the 8-brick slowest brick, constant.
- composite: IceT's binary swap / radix-k over each rank's active pixels (IceT skips the
  transparent ones), A(N) = P·N^(−2/3) (the volume fills the frame; a brick of 1/N of it covers
  N^(−2/3) of it), then the collection of the image on the display rank:
  t_c = log2(N)·α + 16·A(N)/β + A(N)·t_b + 16·P·(1 − 1/N)/β, with α = 2 µs and β = 12.5 GB/s
  (100 Gb/s InfiniBand) and t_b, the time per active pixel, from IceT's composite time at 2
  ranks on this machine (shared memory, so it holds the copies too: an upper bound).
- total = render + composite (rank 0 writing the image not counted).
Published figures beside it: Radix-k in IceT composited 64 Mpixel in 0.08 s at 32 768
processes (Kendall et al., EGPGV 2010); OSPRay's MPI module rendered 951 GB at 5 frames/s on
64 nodes (Usher et al. 2019, cited by issue 30).
"""

import csv
import math
import sys

ALPHA = 2e-6
BETA = 12.5e9


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def main():
    virtual, bench = rows(sys.argv[1]), rows(sys.argv[2])
    sizes = sorted({int(r["size"]) for r in virtual})
    for size in sizes:
        pixels = size * size
        v = {int(r["bricks"]): r for r in virtual if int(r["size"]) == size}
        b = [r for r in bench if int(r["size"]) == size and r["strategy"] == "radixk"]
        two = [r for r in b if int(r["ranks"]) == 2]
        if not two:
            print(f"{size}²: no 2-rank composite measured")
            continue
        t_blend = float(two[0]["composite_ms_max"]) * 1e-3 / (pixels * 2 ** (-2 / 3))
        counts = sorted(v)
        t = {n: float(v[n]["brick_gpu_ms_max"]) * 1e-3 for n in counts}
        # The slope from 8 bricks on, or from the last two counts measured.
        fit = [n for n in counts if n >= 8]
        if len(fit) < 2:
            fit = counts[-2:]
        xs = [math.log(n) for n in fit]
        ys = [math.log(t[n]) for n in fit]
        mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
        slope = -sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)
        n2 = counts[-1]
        one = float(v[counts[0]]["one_device_gpu_ms"]) * 1e-3
        print(f"## {size}²: one device {one * 1e3:.1f} ms; t_b {t_blend * 1e9:.2f} ns per active "
              f"pixel (IceT at 2 ranks); render beyond {n2} bricks ∝ N^-{slope:.2f}")
        print(f"{'nodes':>6} {'render ms':>10} {'composite ms':>13} {'total ms':>9} "
              f"{'speed-up':>9} {'efficiency':>10}   weak: {'render':>7} {'composite':>9} {'total':>7}")
        weak_render = t.get(8, t[counts[-1]])
        for n in [1, 2, 4, 8, 64, 512]:
            render = t[n] if n in t else t[n2] * (n2 / n) ** slope
            comp = composite(n, pixels, t_blend)
            total = render + comp
            measured = " (render measured)" if n in t else " (render extrapolated)"
            print(f"{n:>6} {render * 1e3:>10.2f} {comp * 1e3:>13.2f} {total * 1e3:>9.2f} "
                  f"{one / total:>9.1f} {one / total / n:>10.2f}   weak: {weak_render * 1e3:>7.2f} "
                  f"{comp * 1e3:>9.2f} {(weak_render + comp) * 1e3:>7.2f}{measured}")
        big = composite(32768, 64e6, t_blend)
        print(f"model for 64 Mpixel on 32 768 ranks: {big:.3f} s (published Radix-k in IceT: "
              f"0.08 s)\n")


def composite(n, pixels, t_blend):
    """The composite model of the module documentation, seconds."""
    if n == 1:
        return 0.0
    active = pixels * n ** (-2 / 3)
    return (math.log2(n) * ALPHA + 16 * active / BETA + active * t_blend
            + 16 * pixels * (1 - 1 / n) / BETA)


if __name__ == "__main__":
    main()
