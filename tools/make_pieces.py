#!/usr/bin/env python3
"""Cuts a tetrahedral mesh (.vtu) or a point cloud (.csv x,y,z,f) into PIECES spatially
coherent pieces and writes them as a parallel VTK XML file (.pvtu or .pvtp) with its pieces in
OUT_pieces/: what a simulation's ranks write, for issue 30's per-rank reading
(tools/mpi-check's mesh-pvtu and points-pvtp cases).

- A mesh's cells are sorted by their centroids' x (ties by index) and cut into PIECES runs of
  equal count; each piece holds its cells and the points they use (points on a cut are
  written by both pieces, as VTK's writers do), with every point and cell array of the input
  (Float64). No ghost cells (tests/parallel_files.rs covers pieces with them).
- A point cloud's points are sorted by x and cut the same way; each piece is a PolyData of
  points with point array "f" (Float64).
Pieces are ASCII (exact: Python's repr of each double). The same arguments give the same files.
Reading a .vtu needs meshio: run it with tools/make-tet-mesh's environment
(${VMLS_MESH_VENV:-${TMPDIR:-/tmp}/vmls-mesh-venv}/bin/python3); a .csv needs only Python.

Usage: make_pieces.py INPUT (.vtu or .csv) OUT (.pvtu or .pvtp) PIECES
"""

import os
import sys


def join(values):
    return " ".join(repr(float(v)) for v in values)


def write_summary(out, kind, arrays, sources):
    """The parallel file: its arrays (point arrays, then cell arrays) and its pieces."""
    point = "".join(
        f'<PDataArray type="Float64" Name="{n}"/>' for n, where in arrays if where == "point"
    )
    cell = "".join(
        f'<PDataArray type="Float64" Name="{n}"/>' for n, where in arrays if where == "cell"
    )
    pieces = "".join(f'<Piece Source="{s}"/>' for s in sources)
    with open(out, "w") as f:
        f.write(
            f'<?xml version="1.0"?>\n<VTKFile type="P{kind}" version="1.0">'
            f'<P{kind} GhostLevel="0"><PPointData>{point}</PPointData>'
            f"<PCellData>{cell}</PCellData>"
            '<PPoints><PDataArray type="Float64" NumberOfComponents="3"/></PPoints>'
            f"{pieces}</P{kind}></VTKFile>\n"
        )


def runs(order, pieces):
    n = len(order)
    return [order[n * k // pieces : n * (k + 1) // pieces] for k in range(pieces)]


def mesh_pieces(path, out, pieces):
    import meshio

    mesh = meshio.read(path)
    tets = mesh.cells_dict["tetra"]
    points = mesh.points
    centroid_x = [sum(points[i][0] for i in t) / 4.0 for t in tets]
    order = sorted(range(len(tets)), key=lambda c: (centroid_x[c], c))
    point_arrays = sorted(mesh.point_data)
    cell_arrays = sorted(mesh.cell_data)
    stem, directory = piece_dir(out)
    sources = []
    for k, cells in enumerate(runs(order, pieces)):
        used = sorted({int(i) for c in cells for i in tets[c]})
        local = {p: j for j, p in enumerate(used)}
        conn = " ".join(str(local[int(i)]) for c in cells for i in tets[c])
        pdata = "".join(
            f'<DataArray type="Float64" Name="{n}" format="ascii">'
            f"{join(mesh.point_data[n][i] for i in used)}</DataArray>"
            for n in point_arrays
        )
        cdata = "".join(
            f'<DataArray type="Float64" Name="{n}" format="ascii">'
            f"{join(mesh.cell_data[n][0][c] for c in cells)}</DataArray>"
            for n in cell_arrays
        )
        name = f"{stem}_pieces/p{k}.vtu"
        with open(os.path.join(directory, name), "w") as f:
            f.write(
                '<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0">'
                f'<UnstructuredGrid><Piece NumberOfPoints="{len(used)}" '
                f'NumberOfCells="{len(cells)}"><PointData>{pdata}</PointData>'
                f"<CellData>{cdata}</CellData><Points>"
                '<DataArray type="Float64" NumberOfComponents="3" format="ascii">'
                f"{join(x for i in used for x in points[i])}</DataArray></Points><Cells>"
                f'<DataArray type="Int64" Name="connectivity" format="ascii">{conn}</DataArray>'
                '<DataArray type="Int64" Name="offsets" format="ascii">'
                f'{" ".join(str(4 * (j + 1)) for j in range(len(cells)))}</DataArray>'
                '<DataArray type="UInt8" Name="types" format="ascii">'
                f'{" ".join("10" for _ in cells)}</DataArray>'
                "</Cells></Piece></UnstructuredGrid></VTKFile>\n"
            )
        sources.append(name)
    arrays = [(n, "point") for n in point_arrays] + [(n, "cell") for n in cell_arrays]
    write_summary(out, "UnstructuredGrid", arrays, sources)


def point_pieces(path, out, pieces):
    rows = []
    with open(path) as f:
        next(f)
        for line in f:
            x, y, z, v = (float(t) for t in line.split(","))
            rows.append((x, y, z, v))
    order = sorted(range(len(rows)), key=lambda i: (rows[i][0], i))
    stem, directory = piece_dir(out)
    sources = []
    for k, run in enumerate(runs(order, pieces)):
        name = f"{stem}_pieces/q{k}.vtp"
        with open(os.path.join(directory, name), "w") as f:
            f.write(
                '<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0"><PolyData>'
                f'<Piece NumberOfPoints="{len(run)}"><PointData>'
                '<DataArray type="Float64" Name="f" format="ascii">'
                f"{join(rows[i][3] for i in run)}</DataArray></PointData><Points>"
                '<DataArray type="Float64" NumberOfComponents="3" format="ascii">'
                f"{join(x for i in run for x in rows[i][:3])}</DataArray></Points>"
                "</Piece></PolyData></VTKFile>\n"
            )
        sources.append(name)
    write_summary(out, "PolyData", [("f", "point")], sources)


def piece_dir(out):
    directory = os.path.dirname(os.path.abspath(out))
    stem = os.path.splitext(os.path.basename(out))[0]
    os.makedirs(os.path.join(directory, f"{stem}_pieces"), exist_ok=True)
    return stem, directory


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    path, out, pieces = sys.argv[1], sys.argv[2], int(sys.argv[3])
    if path.endswith(".vtu") and out.endswith(".pvtu"):
        mesh_pieces(path, out, pieces)
    elif path.endswith(".csv") and out.endswith(".pvtp"):
        point_pieces(path, out, pieces)
    else:
        sys.exit("make_pieces.py: INPUT .vtu with OUT .pvtu, or INPUT .csv with OUT .pvtp")
    print(out)


if __name__ == "__main__":
    main()
