#!/usr/bin/env python3
"""Writes a CT-like 16-bit volume for the capacity benchmark of issue 25 §4: the 3D Shepp-Logan
head phantom (Kak & Slaney's ellipsoids) in Hounsfield units stored as uint16 (HU + 1024, as CT
scanners store them), with a faint smooth texture so that no region is exactly flat.

No 512³ CT ships in a package of the registries this project reaches (PyPI wheels stop near
100 MB; pydicom's and scikit-image's samples are single slices or 256² MRIs), so the benchmark
volume is generated. Needs numpy. Writes slice by slice (host memory: a few slices).

Usage: tools/make_ct_phantom.py OUT.nrrd [SIZE] [--type=uint16|uint8|float]
(float: the same uint16 values as float32, the twin the benchmark compares against.)
"""

import sys

import numpy as np

# (HU added, semi-axes a b c, centre x y z, rotation about z in degrees), in the unit cube
# [-1, 1]³: the skull, the brain inside it, two ventricles, and small lesions.
ELLIPSOIDS = [
    (2000.0, (0.69, 0.92, 0.81), (0.0, 0.0, 0.0), 0.0),
    (-960.0, (0.6624, 0.874, 0.78), (0.0, -0.0184, 0.0), 0.0),
    (-40.0, (0.11, 0.31, 0.22), (0.22, 0.0, 0.0), -18.0),
    (-40.0, (0.16, 0.41, 0.28), (-0.22, 0.0, 0.0), 18.0),
    (30.0, (0.21, 0.25, 0.41), (0.0, 0.35, -0.15), 0.0),
    (60.0, (0.046, 0.046, 0.05), (0.0, 0.1, 0.25), 0.0),
    (60.0, (0.046, 0.046, 0.05), (0.0, -0.1, 0.25), 0.0),
    (60.0, (0.046, 0.023, 0.05), (-0.08, -0.605, 0.0), 0.0),
    (60.0, (0.023, 0.023, 0.02), (0.0, -0.606, 0.0), 0.0),
    (60.0, (0.023, 0.046, 0.02), (0.06, -0.605, 0.0), 0.0),
]


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--type")]
    ty = "uint16"
    for a in sys.argv[1:]:
        if a.startswith("--type="):
            ty = a.split("=", 1)[1]
    if ty not in ("uint16", "uint8", "float"):
        sys.exit(f"unknown --type={ty}")
    if not args:
        sys.exit(__doc__)
    out = args[0]
    n = int(args[1]) if len(args) > 1 else 512
    spacing = 0.5  # mm: a 256 mm field of view at 512³
    axis = np.linspace(-1.0, 1.0, n)
    x, y = np.meshgrid(axis, axis, indexing="xy")  # x fastest in memory
    header = (
        "NRRD0004\n"
        "# 3D Shepp-Logan head phantom in HU + 1024 (tools/make_ct_phantom.py)\n"
        f"type: {ty}\ndimension: 3\nsizes: {n} {n} {n}\n"
        "space: left-posterior-superior\n"
        f"space directions: ({spacing},0,0) (0,{spacing},0) (0,0,{spacing})\n"
        f"space origin: ({-spacing * (n - 1) / 2},{-spacing * (n - 1) / 2},{-spacing * (n - 1) / 2})\n"
        "endian: little\nencoding: raw\n\n"
    )
    with open(out, "wb") as f:
        f.write(header.encode())
        for k in range(n):
            z = axis[k]
            hu = np.full((n, n), -1000.0)
            for add, (a, b, c), (cx, cy, cz), phi in ELLIPSOIDS:
                t = np.radians(phi)
                dx, dy = x - cx, y - cy
                u = dx * np.cos(t) + dy * np.sin(t)
                v = -dx * np.sin(t) + dy * np.cos(t)
                inside = (u / a) ** 2 + (v / b) ** 2 + ((z - cz) / c) ** 2 <= 1.0
                hu[inside] += add
            hu += 8.0 * np.sin(9.0 * x) * np.cos(7.0 * y) * np.cos(5.0 * z)
            stored = np.clip(np.rint(hu + 1024.0), 0, 65535)
            if ty == "uint8":
                # Window [-1024, 1526] HU into 0..255 (a coarse CT export).
                stored = np.clip(np.rint((hu + 1024.0) / 10.0), 0, 255)
                f.write(stored.astype("<u1").tobytes())
            elif ty == "float":
                f.write(stored.astype("<f4").tobytes())
            else:
                f.write(stored.astype("<u2").tobytes())
    print(out)


if __name__ == "__main__":
    main()
