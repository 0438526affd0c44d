#!/usr/bin/env python3
"""Writes a scene of the built-in Marschner-Lobb volume at 32² with a transfer function of N
points (colour and extinction varying at every point), for BENCHMARKS.md's preintegration-table
rows and the allowed maximum of 1024 points:
    python3 tools/make_tf_scene.py 1024 > tf1024.toml
    vmls render tf1024.toml -o x.png --stats s.json    # table_build_ms_cpu
"""

import math
import sys

n = int(sys.argv[1]) if len(sys.argv) > 1 else 1024
points = []
for i in range(n):
    s = i / (n - 1)
    r = 0.5 + 0.5 * math.sin(7 * s)
    g = 0.5 + 0.5 * math.cos(5 * s)
    tau = 20 * (0.5 + 0.5 * math.sin(31 * s))
    points.append(f"[{s:.6f}, {r:.4f}, {g:.4f}, {s:.4f}, {tau:.4f}]")
print("[camera]\nwidth = 32\nheight = 32\n[transfer]\npoints = [")
print(",\n".join(points))
print("]")
