#!/usr/bin/env python3
"""Writes N points uniform in [-1, 1]³ with the Marschner–Lobb field as a CSV (x,y,z,f) that
`vmls` reads as scattered data: the splatting benchmark's point cloud (issue 26). The field is
src/data/marschner_lobb.rs's (f_M = 6, alpha = 0.25); the points come from Python's Mersenne
Twister seeded with SEED, so the same command writes the same file on any machine. Standard
library only.

Usage: tools/make_ml_points.py OUT.csv [N] [SEED]      (default N = 68921 = 41³, SEED = 1)
"""

import math
import random
import sys

F_M = 6.0
ALPHA = 0.25


def rho(x, y, z):
    r = math.sqrt(x * x + y * y)
    rho_r = math.cos(2.0 * math.pi * F_M * math.cos(math.pi * r / 2.0))
    return (1.0 - math.sin(math.pi * z / 2.0) + ALPHA * (1.0 + rho_r)) / (2.0 * (1.0 + ALPHA))


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 41**3
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    rng = random.Random(seed)
    with open(out, "w") as f:
        f.write("x,y,z,f\n")
        for _ in range(n):
            x, y, z = (rng.uniform(-1.0, 1.0) for _ in range(3))
            f.write(f"{x!r},{y!r},{z!r},{rho(x, y, z)!r}\n")
    print(out)


if __name__ == "__main__":
    main()
