#!/usr/bin/env python3
"""Could post-shaded splatting skip kernels where the transfer function is transparent? (issue 26)

An oracle, not a renderer: it evaluates the Gaussian-sum field of a scattered-point CSV (the
kernels of vmls's Gaussian reconstruction: support r_i = 1.5 x the 8th-neighbour distance,
sigma_i = 0.25 r_i, truncated at r_i, SPH volumes v_i = 1 / sum_j G_j(x_i - x_j)) on a dense
lattice over [-1, 1]^3, marks the lattice points where the transfer function's extinction is
positive, and counts the kernels with no such point within their support plus a dilation (a
kernel whose whole support is transparent is the only kind a post-shaded splatter could drop
without changing what the visible sheets sum; gradients and neighbouring sheets need the
dilation). The count is an upper bound on what any culling rule could skip.

Usage (numpy and scipy, e.g. in a venv; benchmarks only, never CI):
  python3 tools/splat_cull_oracle.py target/bench-data/ml-points-68921.csv [lattice points per axis]
The transfer bands are those of tools/scenes/ml-points-68921.toml.
"""
import sys

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

BANDS = [(0.22, 0.38), (0.62, 0.78)]  # where the scene's extinction is positive

path = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 161
d = np.loadtxt(path, delimiter=",", skiprows=1)
p, f = d[:, :3], d[:, 3]
tree = cKDTree(p)
dist, _ = tree.query(p, k=9)
r = 1.5 * dist[:, 8]
s = 0.25 * r
norm = 1.0 / ((2 * np.pi) ** 1.5 * s ** 3)
# SPH volumes: 1 / sum_j G_j(x_i - x_j) over the kernels j that reach x_i.
density = np.zeros(len(p))
for j, near in enumerate(tree.query_ball_point(p, r)):
    dd = np.sum((p[near] - p[j]) ** 2, axis=1)
    density[near] += norm[j] * np.exp(-dd / (2 * s[j] ** 2))
v = 1.0 / density

g = np.linspace(-1, 1, n)
h = g[1] - g[0]
field = np.zeros((n, n, n))
idx = np.round((p + 1) / h).astype(int)
m = int(np.ceil(r.max() / h))
for a in range(-m, m + 1):
    for b in range(-m, m + 1):
        for c in range(-m, m + 1):
            q = idx + np.array([a, b, c])
            ok = np.all((q >= 0) & (q < n), axis=1)
            dd = np.sum((q * h - 1 - p) ** 2, axis=1)
            ok &= dd < r * r
            w = f * v * norm * np.exp(-dd / (2 * s * s))
            np.add.at(field, (q[ok, 0], q[ok, 1], q[ok, 2]), w[ok])

opaque = np.zeros(field.shape, dtype=bool)
for lo, hi in BANDS:
    opaque |= (field > lo) & (field < hi)
to_opaque = ndimage.distance_transform_edt(~opaque) * h
at = to_opaque[tuple(idx.clip(0, n - 1).T)]
print(f"kernels {len(p)}, lattice {n}^3 (spacing {h:.4f}), field range "
      f"[{field.min():.3f}, {field.max():.3f}], lattice points with extinction {opaque.mean():.3f}")
pre = np.zeros(len(p), dtype=bool)
for lo, hi in BANDS:
    pre |= (f > lo) & (f < hi)
print(f"pre-shaded: kernels whose own value is transparent {1 - pre.mean():.4f}")
for dil in [0.0, 0.02, 0.05]:
    cull = at > r + dil + h
    print(f"post-shaded: kernels with no extinction within support + {dil}: {cull.mean():.5f}")
