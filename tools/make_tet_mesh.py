#!/usr/bin/env python3
"""Meshes a solid torus into tetrahedra with Gmsh and writes it as a VTK XML .vtu file.

Run through tools/make-tet-mesh, which makes the Python environment (gmsh, meshio, numpy).

The solid: the torus of major radius R = 1 and minor radius r = 0.4 about the z axis, centred
at the origin (OpenCASCADE's torus in Gmsh). It is not convex: a ray along the z axis passes
through the hole (radius 0.6) and meets no cell, so a renderer must show only background there.

The mesh: Gmsh's 3D mesher with one uniform target edge length h everywhere (no refinement
from curvature or from the boundary; or, with --grade G, an edge length that grows
geometrically across the torus in x, from h at x = -1.4 to G h at x = 1.4: a multi-scale mesh), Gmsh's default tetrahedral optimisation, linear
tetrahedra (VTK_TETRA = 10). The default algorithm is HXT on one thread: several times faster
than Gmsh's classic Delaunay and, on one thread, deterministic (on several threads its cell
count varies from run to run, which would make the output differ between runs). h is first
predicted from the target cell count with an empirical number of cells per unit volume and, if
the count misses the target by more than --tolerance, corrected by the cube root of the miss
and meshed again (at most three passes). The same arguments give the same file.

The data, sampled on the mesh:
    f(x, y, z) = 0.5 + 0.5 * sin(4x) * cos(4y) * cos(4z)          (values in [0, 1])
- point array "f" (Float64): f at every mesh point;
- cell array "f_cell" (Float64): f at every cell's centroid (the mean of its four points).

The output: an UnstructuredGrid .vtu from meshio's writer, binary, zlib-compressed, points
Float64, connectivity Int64, with only the points that some cell uses, and every cell oriented
as VTK expects (positive volume: (p1-p0, p2-p0, p3-p0) right-handed). It is written to a
temporary file beside OUTPUT and renamed, so an interrupted run leaves no half-written file.
"""

import argparse
import math
import os
import sys
import time

R_MAJOR = 1.0
R_MINOR = 0.4
VOLUME = 2.0 * math.pi**2 * R_MAJOR * R_MINOR**2

# Cells per unit volume is about 1 / (K * h^3), K measured on this torus with Gmsh 4.15 near
# 2e5 cells (HXT: 0.256 at 1e6, 0.29 at 2e3, where the boundary weighs more). Only the first
# guess depends on it; a corrected pass absorbs the rest.
CELL_VOLUME_FACTOR = {"hxt": 0.249, "delaunay": 0.219}
ALGORITHM_3D = {"delaunay": 1, "hxt": 10}


def field(p):
    """f(x, y, z) = 0.5 + 0.5 sin(4x) cos(4y) cos(4z) for an (n, 3) array of points."""
    import numpy as np

    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    return 0.5 + 0.5 * np.sin(4.0 * x) * np.cos(4.0 * y) * np.cos(4.0 * z)


def parse_args(argv):
    ap = argparse.ArgumentParser(
        prog="tools/make-tet-mesh",
        description="Mesh the torus (R=1, r=0.4) into tetrahedra with Gmsh, sample "
        "f = 0.5 + 0.5 sin(4x) cos(4y) cos(4z) at the points ('f') and the cell "
        "centroids ('f_cell'), and write a zlib-compressed binary .vtu.",
    )
    ap.add_argument("output", help="the .vtu file to write")
    ap.add_argument(
        "--cells",
        type=int,
        default=200_000,
        help="target number of tetrahedra (default 200000)",
    )
    ap.add_argument(
        "--tolerance",
        type=float,
        default=0.1,
        help="relative miss of the target that triggers a corrected pass (default 0.1)",
    )
    ap.add_argument(
        "--grade",
        type=float,
        default=1.0,
        help="ratio of the largest to the smallest target edge length, graded "
        "geometrically along x (default 1: uniform)",
    )
    ap.add_argument(
        "--algorithm",
        choices=sorted(ALGORITHM_3D),
        default="hxt",
        help="Gmsh 3D algorithm (default hxt)",
    )
    args = ap.parse_args(argv)
    if not 100 <= args.cells <= 50_000_000:
        ap.error("--cells must be between 100 and 50000000")
    if not 1.0 <= args.grade <= 1000.0:
        ap.error("--grade must be between 1 and 1000")
    if not 0.0 < args.tolerance < 1.0:
        ap.error("--tolerance must be in (0, 1)")
    if not args.output.endswith(".vtu"):
        ap.error("the output must end in .vtu (vmls picks its reader by the extension)")
    return args


def mesh_torus(gmsh, h, grade=1.0):
    """Meshes the torus with edge length h (graded up to grade * h along x); returns (points,
    tets) as numpy arrays."""
    import numpy as np

    gmsh.model.mesh.clear()
    gmsh.option.setNumber("Mesh.MeshSizeMin", h)
    gmsh.option.setNumber("Mesh.MeshSizeMax", h * grade)
    if grade > 1.0:
        if 1 in list(gmsh.model.mesh.field.list()):
            gmsh.model.mesh.field.remove(1)
        gmsh.model.mesh.field.add("MathEval", 1)
        gmsh.model.mesh.field.setString(1, "F", f"{h!r} * {grade!r}^((x + 1.4) / 2.8)")
        gmsh.model.mesh.field.setAsBackgroundMesh(1)
    gmsh.model.mesh.generate(3)
    _, tet_nodes = gmsh.model.mesh.getElementsByType(4)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    tets = np.asarray(tet_nodes, dtype=np.int64).reshape(-1, 4)
    tags = np.asarray(tags, dtype=np.int64)
    coords = np.asarray(coords, dtype=np.float64).reshape(-1, 3)
    # Gmsh numbers nodes by tag, not 0..n-1, and also lists nodes no tetrahedron uses (none
    # for this solid, but a .vtu with unused points would give a renderer stray samples).
    used = np.unique(tets)
    order = np.argsort(tags)
    where = order[np.searchsorted(tags, used, sorter=order)]
    if not np.array_equal(tags[where], used):
        raise SystemExit("make_tet_mesh: a tetrahedron names a node Gmsh did not list")
    points = coords[where]
    tets = np.searchsorted(used, tets)
    return points, tets


def orient(points, tets):
    """Makes every tetrahedron positively oriented; returns (tets, volumes)."""
    import numpy as np

    p = points[tets]
    vol = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))
    flip = vol < 0
    tets = tets.copy()
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return tets, np.abs(vol) / 6.0


def main(argv):
    args = parse_args(argv)
    try:
        import gmsh
    except OSError as e:
        # The wheel's libgmsh links libGLU, libXft, libXinerama, libXcursor and friends.
        raise SystemExit(
            f"make_tet_mesh: cannot load the Gmsh library ({e}); install the X11 "
            "and OpenGL client libraries that tools/make-tet-mesh lists"
        ) from e
    import meshio
    import numpy as np

    t0 = time.perf_counter()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("torus")
        gmsh.model.occ.addTorus(0, 0, 0, R_MAJOR, R_MINOR)
        gmsh.model.occ.synchronize()
        for name in ("MeshSizeFromCurvature", "MeshSizeExtendFromBoundary", "MeshSizeFromPoints"):
            gmsh.option.setNumber("Mesh." + name, 0)
        gmsh.option.setNumber("Mesh.Algorithm3D", ALGORITHM_3D[args.algorithm])
        h = (VOLUME / (CELL_VOLUME_FACTOR[args.algorithm] * args.cells)) ** (1.0 / 3.0)
        if args.grade > 1.0:
            # The mean of 1/h^3 over x in [-1.4, 1.4] for h = h0 G^((x+1.4)/2.8): the first
            # guess of h0 that gives the target count (a corrected pass absorbs the rest).
            mean = (1.0 - args.grade ** -3.0) / (3.0 * math.log(args.grade))
            h *= mean ** (1.0 / 3.0)
        for attempt in range(3):
            points, tets = mesh_torus(gmsh, h, args.grade)
            print(f"pass {attempt + 1}: h = {h:.5f}, {len(tets)} tetrahedra")
            miss = len(tets) / args.cells
            if abs(miss - 1.0) <= args.tolerance or attempt == 2:
                break
            h *= miss ** (1.0 / 3.0)
        version = gmsh.option.getString("General.Version")
    finally:
        gmsh.finalize()
    t_mesh = time.perf_counter() - t0

    tets, volumes = orient(points, tets)
    if len(tets) == 0 or not np.all(np.isfinite(points)):
        raise SystemExit("make_tet_mesh: Gmsh returned no tetrahedra or non-finite points")
    if volumes.min() <= 1e-6 * volumes.mean():
        raise SystemExit(f"make_tet_mesh: a degenerate tetrahedron (volume {volumes.min():.3e})")
    f_point = field(points)
    f_cell = field(points[tets].mean(axis=1))

    t1 = time.perf_counter()
    out = os.path.abspath(args.output)
    os.makedirs(os.path.dirname(out), exist_ok=True)
    tmp = os.path.join(os.path.dirname(out), f".{os.path.basename(out)}.{os.getpid()}.vtu")
    mesh = meshio.Mesh(
        points,
        [("tetra", tets)],
        point_data={"f": f_point},
        cell_data={"f_cell": [f_cell]},
    )
    try:
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression="zlib")
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    t_write = time.perf_counter() - t1

    rho = np.hypot(points[:, 0], points[:, 1])
    tube = np.hypot(rho - R_MAJOR, points[:, 2])
    print(
        f"mesher: Gmsh {version} ({args.algorithm}, 1 thread), writer: meshio {meshio.__version__}"
    )
    print(f"points: {len(points)}")
    print(f"cells: {len(tets)} tetrahedra (target {args.cells}, h = {h:.5f})")
    print(
        f"volume: {volumes.sum():.5f} (torus {VOLUME:.5f}), "
        f"cell volume min/mean/max {volumes.min():.3e}/{volumes.mean():.3e}/{volumes.max():.3e}"
    )
    print(
        f"points: distance from the z axis >= {rho.min():.4f}, "
        f"from the tube's core <= {tube.max():.4f}"
    )
    print(
        f"f: [{f_point.min():.4f}, {f_point.max():.4f}], "
        f"f_cell: [{f_cell.min():.4f}, {f_cell.max():.4f}]"
    )
    print(f"time: mesh {t_mesh:.1f} s, write {t_write:.1f} s")
    print(f"wrote {out} ({os.path.getsize(out)} bytes)")


if __name__ == "__main__":
    main(sys.argv[1:])
