#!/usr/bin/env python3
"""Writes issue 29's sphere-shell volume: a distance field on an N³ grid (default 64³).

f(x) = |x| / 0.8 on the grid over [-1, 1]³, so that the sphere of radius 0.8 is f = 1 and a
transfer-function peak at f = 0.5 draws a spherical shell of radius 0.4 whose thickness is the
peak's half-width times 0.8. Written as NRRD (raw float32, little-endian, space directions of
2/(N-1)) with no dependency beyond the standard library.

    python3 tools/make_sphere_shell.py target/bench-data/sphere-distance-64.nrrd [--size N]
"""

import argparse
import math
import os
import struct


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("output")
    ap.add_argument("--size", type=int, default=64)
    args = ap.parse_args()
    n = args.size
    if not 4 <= n <= 512:
        ap.error("--size must be between 4 and 512")
    h = 2.0 / (n - 1)
    values = bytearray()
    for k in range(n):
        z = -1.0 + k * h
        for j in range(n):
            y = -1.0 + j * h
            row = [math.sqrt((-1.0 + i * h) ** 2 + y * y + z * z) / 0.8 for i in range(n)]
            values += struct.pack(f"<{n}f", *row)
    header = (
        "NRRD0004\n"
        "type: float\n"
        "dimension: 3\n"
        f"sizes: {n} {n} {n}\n"
        "space: right-anterior-superior\n"
        f"space directions: ({h!r},0,0) (0,{h!r},0) (0,0,{h!r})\n"
        "space origin: (-1,-1,-1)\n"
        "endian: little\n"
        "encoding: raw\n\n"
    )
    out = os.path.abspath(args.output)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    tmp = f"{out}.{os.getpid()}.tmp"
    with open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(values)
    os.replace(tmp, out)
    print(f"wrote {out}: {n}³ float32, f = |x| / 0.8 in [0, {math.sqrt(3) / 0.8:.3f}]")


if __name__ == "__main__":
    main()
