#!/usr/bin/env python3
"""Writes the Marschner–Lobb field on an N³ grid over [-1, 1]³ as a parallel VTK XML image:
OUT.pvti and CUTS³ pieces OUT_pieces/p<k>.vti (extents sharing their faces, ASCII Float32 point
data "f"), as ParaView's parallel writer lays them out. The values are
src/data/marschner_lobb.rs's (f_M = 6, alpha = 0.25), so `volume.file = "OUT.pvti"` renders
the image `volume.resolution = N` does, to f32 rounding of the printed values. With OUT.pvtr or
OUT.pvts the same grid is written as a rectilinear or curvilinear grid (its coordinates or
points given explicitly; vmls holds those as scattered samples with their own supports).
Standard library only; tools/mpi-check's parallel-file cases (issue 30).

Usage: tools/make_ml_pvti.py OUT.pvti|OUT.pvtr|OUT.pvts [N] [CUTS]   (default N = 41, CUTS = 3)
"""

import os
import struct
import sys

from make_ml_points import rho


def f32(v):
    """The value rounded to f32 and printed so that it reads back exactly."""
    return repr(struct.unpack("f", struct.pack("f", v))[0])


KINDS = {".pvti": ("ImageData", "vti"), ".pvtr": ("RectilinearGrid", "vtr"),
         ".pvts": ("StructuredGrid", "vts")}


def geometry(ext, e, h):
    """A piece's coordinates (rectilinear) or points (curvilinear): the grid's, explicitly."""
    axis = lambda a: " ".join(repr(-1.0 + i * h) for i in range(e[2 * a], e[2 * a + 1] + 1))
    if ext == "vtr":
        arrays = "".join(
            f'<DataArray type="Float64" format="ascii">{axis(a)}</DataArray>' for a in range(3)
        )
        return f"<Coordinates>{arrays}</Coordinates>"
    if ext == "vts":
        pts = " ".join(
            f"{-1.0 + x * h!r} {-1.0 + y * h!r} {-1.0 + z * h!r}"
            for z in range(e[4], e[5] + 1)
            for y in range(e[2], e[3] + 1)
            for x in range(e[0], e[1] + 1)
        )
        return (
            '<Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">'
            f"{pts}</DataArray></Points>"
        )
    return ""


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 41
    cuts = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    kind = KINDS.get(os.path.splitext(out)[1])
    if kind is None:
        sys.exit("make_ml_pvti.py: OUT must end in .pvti, .pvtr or .pvts")
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
                name = f"p{k}.{kind[1]}"
                with open(os.path.join(folder, name), "w") as fh:
                    fh.write(
                        f'<?xml version="1.0"?>\n<VTKFile type="{kind[0]}" version="1.0">\n'
                        f'<{kind[0]} WholeExtent="{whole}" {place if kind[1] == "vti" else ""}>\n'
                        f'<Piece Extent="{extent}"><PointData Scalars="f">\n'
                        '<DataArray type="Float32" Name="f" format="ascii">\n'
                        + " ".join(values)
                        + "\n</DataArray></PointData><CellData/>"
                        + geometry(kind[1], e, h)
                        + f"</Piece>\n</{kind[0]}>\n</VTKFile>\n"
                    )
                pieces.append(f'<Piece Extent="{extent}" Source="{stem}_pieces/{name}"/>')
                k += 1
    points = {
        "vti": "",
        "vtr": '<PCoordinates><PDataArray type="Float64"/><PDataArray type="Float64"/>'
        '<PDataArray type="Float64"/></PCoordinates>\n',
        "vts": '<PPoints><PDataArray type="Float64" NumberOfComponents="3"/></PPoints>\n',
    }[kind[1]]
    with open(out, "w") as fh:
        fh.write(
            f'<?xml version="1.0"?>\n<VTKFile type="P{kind[0]}" version="1.0">\n'
            f'<P{kind[0]} WholeExtent="{whole}" GhostLevel="0" '
            f'{place if kind[1] == "vti" else ""}>\n'
            '<PPointData Scalars="f"><PDataArray type="Float32" Name="f"/></PPointData>\n'
            + points
            + "\n".join(pieces)
            + f"\n</P{kind[0]}>\n</VTKFile>\n"
        )
    print(out)


if __name__ == "__main__":
    main()
