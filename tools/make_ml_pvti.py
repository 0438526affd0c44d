#!/usr/bin/env python3
"""Writes the Marschner–Lobb field on an N³ grid over [-1, 1]³ as a parallel VTK XML image:
OUT.pvti and CUTS³ pieces OUT_pieces/p<k>.vti (extents sharing their faces, ASCII Float32 point
data "f"), as ParaView's parallel writer lays them out. The values are
src/data/marschner_lobb.rs's (f_M = 6, alpha = 0.25), so `volume.file = "OUT.pvti"` renders
the image `volume.resolution = N` does, to f32 rounding of the printed values. Standard
library only; tools/mpi-check's parallel-file case (issue 30).

Usage: tools/make_ml_pvti.py OUT.pvti [N] [CUTS]      (default N = 41, CUTS = 3)
"""

import os
import struct
import sys

from make_ml_points import rho


def f32(v):
    """The value rounded to f32 and printed so that it reads back exactly."""
    return repr(struct.unpack("f", struct.pack("f", v))[0])


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 41
    cuts = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    h = 2.0 / (n - 1)
    stem = os.path.splitext(os.path.basename(out))[0]
    folder = os.path.join(os.path.dirname(out) or ".", stem + "_pieces")
    os.makedirs(folder, exist_ok=True)
    bounds = [(n - 1) * c // cuts for c in range(cuts + 1)]
    whole = f"0 {n - 1} 0 {n - 1} 0 {n - 1}"
    place = f'Origin="-1 -1 -1" Spacing="{h!r} {h!r} {h!r}"'
    pieces = []
    k = 0
    for cz in range(cuts):
        for cy in range(cuts):
            for cx in range(cuts):
                e = [bounds[cx], bounds[cx + 1], bounds[cy], bounds[cy + 1], bounds[cz], bounds[cz + 1]]
                extent = " ".join(map(str, e))
                values = []
                for z in range(e[4], e[5] + 1):
                    for y in range(e[2], e[3] + 1):
                        for x in range(e[0], e[1] + 1):
                            values.append(f32(rho(-1.0 + x * h, -1.0 + y * h, -1.0 + z * h)))
                name = f"p{k}.vti"
                with open(os.path.join(folder, name), "w") as fh:
                    fh.write(
                        '<?xml version="1.0"?>\n<VTKFile type="ImageData" version="1.0">\n'
                        f'<ImageData WholeExtent="{whole}" {place}>\n'
                        f'<Piece Extent="{extent}"><PointData Scalars="f">\n'
                        '<DataArray type="Float32" Name="f" format="ascii">\n'
                        + " ".join(values)
                        + "\n</DataArray></PointData><CellData/></Piece>\n</ImageData>\n</VTKFile>\n"
                    )
                pieces.append(f'<Piece Extent="{extent}" Source="{stem}_pieces/{name}"/>')
                k += 1
    with open(out, "w") as fh:
        fh.write(
            '<?xml version="1.0"?>\n<VTKFile type="PImageData" version="1.0">\n'
            f'<PImageData WholeExtent="{whole}" GhostLevel="0" {place}>\n'
            '<PPointData Scalars="f"><PDataArray type="Float32" Name="f"/></PPointData>\n'
            + "\n".join(pieces)
            + "\n</PImageData>\n</VTKFile>\n"
        )
    print(out)


if __name__ == "__main__":
    main()
