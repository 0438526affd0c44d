#!/usr/bin/env python3
"""The VTK peer of `vmls bench --peer vtk`: renders a vmls scene file with VTK's GPU ray caster
(vtkGPUVolumeRayCastMapper, OpenGL; EGL offscreen on llvmpipe here), or a scattered-point scene
with vtkPointGaussianMapper (below), and writes its images and a results.csv in the bench's
columns (source = vtk; error columns empty: vmls bench measures them against its own reference).

How the scene is matched (see BENCHMARKS.md, "Peers"):
- Volume: `generator = "marschner-lobb"` is sampled with the same formula on the same grid
  (n³ over [-1, 1]³); `volume.file` is read with VTK's reader for .vti/.vtk image data.
- Camera: eye, target, up and fov_y (VTK's view angle is the vertical angle, as vmls's), or
  an orthographic view height; the image size of the scene.
- Transfer function: vmls's points are (s, r, g, b, τ) with τ an extinction per world unit and
  emission c·τ. VTK interpolates opacity α linearly and corrects it per sample to its scalar
  opacity unit distance u; we tabulate 1024 points of α(s) = 1 − exp(−τ(s)·u) and c(s), so the
  per-sample opacity is 1 − exp(−τ(s)·Δ) as in vmls's midpoint rule, to table precision.
- Integration: trilinear interpolation, sample distance = step × spacing with automatic
  adjustment off, no shading, background as in the scene. Isosurfaces are not rendered (the
  peer refuses scenes with them).
- Output is 8-bit RGBA read back from the framebuffer: quantization alone gives an RMSE of about
  1/(255·√12) ≈ 1.1e-3 against a float image.
- Time is wall time of Render() followed by a framebuffer read (which waits for the GPU): median
  of `--repeat` frames after a first frame (which compiles shaders and uploads the volume).

Unstructured meshes (`volume.file` a .vtu or a legacy .vtk unstructured grid) are split into
tetrahedra (vtkDataSetTriangleFilter: VTK's unstructured volume mappers draw tetrahedra only)
and drawn with VTK's two unstructured volume mappers: rows `vtk-unstructured-raycast`
(vtkUnstructuredGridVolumeRayCastMapper: Bunyk's cell-by-cell ray caster on the CPU threads,
one ray per pixel, piecewise-linear ray integration) and `vtk-projected-tetrahedra`
(vtkProjectedTetrahedraMapper, OpenGL: cells sorted by visibility and drawn as projected
triangles), whatever `--steps` says. Their field is the mesh's piecewise-linear interpolant, not
vmls's MLS reconstruction, so the image differs by the reconstruction, which the error columns
(against vmls's reference) include. Transfer function: VTK's unstructured integrators read the
opacity function as an attenuation per `ScalarOpacityUnitDistance` (attenuation = value / unit),
so the opacity points hold τ(s)·u with u = 1 / max τ, which is vmls's extinction τ per world
unit; colours as for grids (1024 points, RGB, linear). Time: as for grids, wall time of Render()
and the framebuffer read, median of `--repeat` frames after a first one (which sorts, builds
the cell connectivity and its tables); prepare_ms is the read and the split into tetrahedra.

Scattered points (`volume.file` a .csv: columns x, y, z or Points:0..2 and the scalar column
`volume.scalars`, else the first other numeric one) are drawn with vtkPointGaussianMapper, one
Gaussian per sample as vmls's pre-shaded splatting (`render.method = "splat"`, src/splat/) draws
it: rows `vtk-point-gaussian` (below), whatever `--steps` says. VTK 9.7's mapper is an EWA
splatter: each point's world covariance (scale·ScaleFactor)²·I goes through the affine Jacobian
of the projection, gets a 2D low-pass added, and is drawn as a quad from a geometry shader with
a per-fragment Gaussian (standard deviation = scale·ScaleFactor). How the kernels are matched:
- Kernel size: vmls's isotropic kNN supports for scattered data (src/samples/supports.rs):
  h_i = support × the distance to the knn-th nearest other point (`reconstruction.support`,
  1.5 when left out; `reconstruction.knn`, 8), exact kNN by vtkStaticPointLocator. The Gaussian
  (src/recon/gaussian.rs) has covariance σ²·h_i²·I with σ = `reconstruction.sigma` (0.25), so
  the scale array holds the standard deviation σ·h_i in world units and ScaleFactor is 1: the
  same Gaussian, not an approximation of it. Anisotropic supports
  (`reconstruction.anisotropic = true`) and duplicate points (vmls merges them) are refused.
- Weight: the kernel's volume v_i is the same SPH estimate, 1 / Σ_j G_j(x_i − x_j) over the
  kernels truncated at ρ = 1, computed with numpy. Pre-shaded splatting lays down extinction
  τ(f_i)·v_i·G_i and emission c(f_i) times that, so along a ray at distance d from the centre a
  kernel's optical depth is D_i(d) = τ(f_i)·v_i/(2π·σ_i²)·exp(−d²/(2σ_i²)).
- Opacity: the peak D_i depends on v_i and σ_i, not only on f_i, so it is computed per point
  in numpy and passed as the opacity array with no ScalarOpacityFunction (the mapper's function
  maps one array, so τ(f) could not carry v_i/σ_i²). The mapper stores opacity in the colour's
  alpha byte (truncating), so D_i/D_max is rounded to 8 bits first; points whose byte is 0, and
  those with τ(f_i) = 0 (vmls culls them too), are not drawn. A splat shader
  (SetSplatShaderCode) makes each fragment's opacity 1 − exp(−D_max·byte/255·g), g the
  footprint's Gaussian: exact Beer–Lambert per kernel, where the mapper's default would be the
  linear byte/255·g.
- Footprint filter: `splat.antialias = "ewa"` adds `splat.lowpass` px² to the footprint as
  vmls does, through SetLowpassMatrix (in NDC units). vmls rescales the filtered footprint to
  keep its integral, the mapper keeps its peak, so each point's peak D_i is scaled by
  s²/(s² + L) with s = f·σ_i/depth its footprint's standard deviation in pixels on the optical
  axis (f = H / (2 tan(fov_y/2))), recomputed whenever the points are sorted. "swan" (scale the
  footprint until its variance reaches L) is applied to the radius and peak in numpy; "auto"
  (vmls's default: each footprint axis narrower than L widened to L) is the same for the
  isotropic footprints drawn here; "none" adds nothing.
- Cutoff: footprints end at `splat.cutoff` (3.5) standard deviations (SetBoundScale and a
  discard in the shader), as vmls's do.
- Colour: vtkColorTransferFunction through the transfer points (RGB space, linear, so c(f) as
  vmls interpolates it; colours above 1 clamp; 8-bit).
- Compositing: the mapper sorts nothing, so the points are sorted back to front by distance
  from the eye with numpy (vmls's sheets are cut at that distance, t) and drawn in that order
  with the over operator (Emissive off, the actor forced translucent, depth peeling and OIT
  off, so the blending order is the draw order). VTK composites whole kernels in the order of
  their centres; vmls cuts every kernel into sheets of splat.slab spacings and composites sheet
  by sheet, so where kernels overlap in depth the emission order differs (the total optical
  depth, Σ D_i, is the same).
- Projection: the mapper's footprint is the affine (EWA) one; vmls's default
  `splat.footprint = "exact"` integrates each pixel's own ray, which differs for large kernels
  far off the optical axis (on the benchmark scene at 256², VTK against vmls's exact and
  affine footprints: RMSE 0.00125 and 0.00123, both at the 8-bit quantization level).
- Not matched: early termination (vmls stops compositing a pixel beyond
  `render.early_termination` opacity; VTK draws everything), vmls's culling of kernels
  reaching the near plane (none do in a view from outside the volume), and the mapper's own
  culling of points whose centre lies beyond 1.3× the view frustum (vmls keeps kernels whose
  footprint reaches the image).
- Framebuffer: with VTK's default 8-bit target every one of the hundreds of blends a pixel
  receives is rounded to 1/255, and with opacities of a few per cent per kernel the rounding
  does not average out: on tools/scenes/ml-points-68921.toml it raises the green channel's
  mean by 11% (RMSE 0.020 against vmls's splatting, against 0.0012 in float). The matched
  configuration therefore renders VTK's standard render steps (vtkRenderStepsPass) into the
  RGBA32F target of a vtkToneMappingPass whose mapping is Clamp (identity on [0, 1]); the
  8-bit default is measured too. The image read back is 8-bit either way (quantization alone
  is an RMSE of about 1.1e-3).
- Rows, one per (framebuffer, sorting): `framebuffer=float32;sort=once` (the matched one),
  `framebuffer=float32;sort=per-frame` and `framebuffer=rgba8;sort=once`. `sort=once` sorts
  before the timed frames (a still camera); `sort=per-frame` sorts, rewrites the point arrays
  (which the mapper re-uploads) and renders in every timed frame, the cost of a moving camera.
  Time = wall time of the frame (sorting if any, Render(), the framebuffer read), median of
  `--repeat` frames after a first frame in that pipeline; prepare_ms is the CPU kernel
  derivation (CSV read, kNN, SPH volumes, transfer function), once for all rows.
"""
import argparse, csv, math, os, statistics, sys, time, tomllib

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
import numpy as np  # noqa: E402
import vtk  # noqa: E402
from vtk.util import numpy_support  # noqa: E402

COLUMNS = ["source", "method", "settings", "device", "driver", "vmls_version", "commit", "width",
           "height", "frames", "gpu_ms", "gpu_ms_min", "gpu_ms_max", "kernel_ms", "wall_ms",
           "first_frame_wall_ms", "first_frame_gpu_ms", "prepare_ms", "evaluations",
           "evaluations_per_s", "bytes_uploaded_first", "bytes_uploaded_next", "rmse", "max_abs",
           "max_x", "max_y", "psnr", "non_finite", "fma_share", "memory_share", "bound_by",
           "reference", "variant"]


def apply_set(scene, arg):
    path, raw = arg.split("=", 1)
    section, key = path.strip().split(".", 1)
    try:
        value = tomllib.loads("v = " + raw)["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    scene.setdefault(section, {})[key] = value


def ml_volume(n):
    f_m, alpha = 6.0, 0.25
    c = np.linspace(-1.0, 1.0, n)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt(x * x + y * y)
    rho_r = np.cos(2 * math.pi * f_m * np.cos(math.pi * r / 2))
    v = (1 - np.sin(math.pi * z / 2) + alpha * (1 + rho_r)) / (2 * (1 + alpha))
    img = vtk.vtkImageData()
    img.SetDimensions(n, n, n)
    img.SetOrigin(-1.0, -1.0, -1.0)
    h = 2.0 / (n - 1)
    img.SetSpacing(h, h, h)
    arr = numpy_support.numpy_to_vtk(v.astype(np.float32).ravel(), deep=True)
    arr.SetName("scalars")
    img.GetPointData().SetScalars(arr)
    return img, h


def read_with(reader, path, scalars):
    """The dataset `reader` reads from `path`, with point array `scalars` (if given) active."""
    reader.SetFileName(path)
    reader.Update()
    data = reader.GetOutput()
    if scalars is not None:
        if data.GetPointData().GetArray(scalars) is None:
            sys.exit(f"peer-vtk: {path} has no point array '{scalars}'")
        data.GetPointData().SetActiveScalars(scalars)
    return data


def load_volume(scene, base):
    vol = scene.get("volume", {})
    if "file" in vol:
        path = os.path.join(base, vol["file"])
        img = read_with(vtk.vtkXMLImageDataReader() if path.endswith(".vti") else vtk.vtkStructuredPointsReader(),
                        path, vol.get("scalars"))
        return img, min(img.GetSpacing())
    return ml_volume(int(vol.get("resolution", 41)))


def tf_lookup(points, s):
    if s <= points[0][0]:
        return points[0][1:]
    for a, b in zip(points, points[1:]):
        if s < b[0]:
            t = (s - a[0]) / (b[0] - a[0])
            return [a[k] + t * (b[k] - a[k]) for k in range(1, 5)]
    return points[-1][1:]


def point_columns(header, first_row, wanted):
    """Indices of the x, y, z columns and of the scalar column, by vmls's CSV rules
    (src/data/points.rs): x/y/z or Points:0/1/2, any case; the scalar is `wanted`, else the first
    other column whose first data row is a number. (Unquoted fields only.)"""
    names = [h.strip().strip('"') for h in header.split(",")]
    values = [v.strip() for v in first_row.split(",")]

    def numeric(c):
        try:
            float(values[c])
            return True
        except (IndexError, ValueError):
            return False

    axes = {"x": 0, "y": 1, "z": 2, "points:0": 0, "points:1": 1, "points:2": 2}
    cols = [None, None, None]
    for c, n in enumerate(names):
        a = axes.get(n.lower())
        if a is not None:
            cols[a] = c
    if None in cols:
        sys.exit(f"peer-vtk: the CSV names no x, y and z columns (header: {header.strip()})")
    others = [c for c in range(len(names)) if c not in cols and numeric(c)]
    if wanted is not None:
        if wanted not in names:
            sys.exit(f"peer-vtk: the CSV has no column '{wanted}'")
        scalar = names.index(wanted)
    elif others:
        scalar = others[0]
    else:
        sys.exit("peer-vtk: the CSV holds positions only")
    return cols + [scalar]


def load_points(path, wanted):
    with open(path, encoding="utf-8-sig") as f:
        header = f.readline()
        first_row = f.readline()
    cols = point_columns(header, first_row, wanted)
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=cols, ndmin=2, encoding="utf-8-sig")
    return data[:, :3].astype(np.float64), data[:, 3].astype(np.float64)


def knn_distances(x, k):
    """Distances from every point to its nearest and to its k-th nearest other point (exact,
    vtkStaticPointLocator)."""
    pd = vtk.vtkPolyData()
    pts = vtk.vtkPoints()
    pts.SetData(numpy_support.numpy_to_vtk(x, deep=True))
    pd.SetPoints(pts)
    loc = vtk.vtkStaticPointLocator()
    loc.SetDataSet(pd)
    loc.BuildLocator()
    ids = vtk.vtkIdList()
    k = min(k, len(x) - 1)
    near = np.empty(len(x), dtype=np.int64)
    far = np.empty(len(x), dtype=np.int64)
    for i in range(len(x)):
        # The list starts with the point itself (coincident points are refused by the caller).
        loc.FindClosestNPoints(k + 1, x[i], ids)
        near[i] = ids.GetId(1)
        far[i] = ids.GetId(ids.GetNumberOfIds() - 1)
    return tuple(np.sqrt(((x[j] - x) ** 2).sum(axis=1)) for j in (near, far))


def close_pairs(x, r):
    """Yields (i, j, |x_i − x_j|²) blocks for every ordered pair (self pairs included) closer
    than r: points binned in cells of side r, each cell against its 27 neighbours."""
    lo = x.min(axis=0)
    cell = np.floor((x - lo) / r).astype(np.int64)
    dims = cell.max(axis=0) + 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    keys, starts, counts = np.unique(key[order], return_index=True, return_counts=True)
    where = {int(k): (s, s + c) for k, s, c in zip(keys, starts, counts)}
    offsets = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    for k, (s, e) in where.items():
        i = order[s:e]
        cx, cy, cz = cell[i[0]]
        near = []
        for a, b, c in offsets:
            q = (cx + a, cy + b, cz + c)
            if min(q) < 0 or q[0] >= dims[0] or q[1] >= dims[1] or q[2] >= dims[2]:
                continue
            span = where.get(int((q[0] * dims[1] + q[1]) * dims[2] + q[2]))
            if span:
                near.append(order[span[0]:span[1]])
        j = np.concatenate(near)
        d2 = ((x[i][:, None, :] - x[j][None, :, :]) ** 2).sum(axis=2)
        ii, jj = np.nonzero(d2 < r * r)
        yield i[ii], j[jj], d2[ii, jj]


def point_kernels(scene, x):
    """vmls's isotropic Gaussian kernels of scattered samples: (σ_i in world units, v_i)."""
    rec = scene.get("reconstruction", {})
    if rec.get("anisotropic", False):
        sys.exit("peer-vtk: anisotropic supports of scattered points are not matched")
    support = float(rec.get("support", 1.5))
    k = int(rec.get("knn", 8))
    sigma = float(rec.get("sigma", 0.25))
    if len(x) < 2:
        sys.exit("peer-vtk: scattered data needs at least 2 points")
    nearest, kth = knn_distances(x, k)
    if nearest.min() <= 1e-9 * np.linalg.norm(x.max(axis=0) - x.min(axis=0)):
        sys.exit("peer-vtk: coincident points (vmls merges them; not matched)")
    h = support * kth
    s = sigma * h
    norm = 1.0 / ((2 * math.pi) ** 1.5 * s ** 3)
    density = np.zeros(len(x))
    for i, j, d2 in close_pairs(x, h.max()):
        inside = d2 < h[j] ** 2  # the kernel is cut at ρ = 1
        g = norm[j[inside]] * np.exp(-0.5 * d2[inside] / s[j[inside]] ** 2)
        density += np.bincount(i[inside], weights=g, minlength=len(x))
    return s, 1.0 / density


def run_points(scene, a, base):
    t0 = time.perf_counter()
    vol = scene["volume"]
    path = os.path.join(base, vol["file"])
    x, f = load_points(path, vol.get("scalars"))
    f = f.astype(np.float32).astype(np.float64)  # vmls keeps values as f32
    s, v = point_kernels(scene, x)
    points = np.array(scene["transfer"]["points"], dtype=np.float64)
    tau = np.interp(f, points[:, 0], points[:, 4])
    d_peak = tau * v / (2 * math.pi * s * s)
    keep = d_peak > 0
    if not keep.any():
        sys.exit("peer-vtk: the transfer function gives every point zero extinction")
    x, f, s, d_peak = x[keep], f[keep], s[keep], d_peak[keep]
    d_max = float(d_peak.max())
    prepare_ms = (time.perf_counter() - t0) * 1e3

    cam = scene.get("camera", {})
    width, height = int(cam.get("width", 256)), int(cam.get("height", 256))
    eye = np.array(cam.get("eye", [3.0, 2.0, 2.5]), dtype=np.float64)
    target = np.array(cam.get("target", [0.0, 0.0, 0.0]), dtype=np.float64)
    forward = (target - eye) / np.linalg.norm(target - eye)
    ortho = cam.get("projection", "perspective") == "orthographic"
    fov = float(cam.get("fov_y", 30.0))
    focal = height / (cam.get("view_height", 2.0) if ortho else 2 * math.tan(math.radians(fov) / 2))
    splat = scene.get("splat", {})
    cutoff = float(splat.get("cutoff", 3.5))
    lowpass = float(splat.get("lowpass", 1.0))
    antialias = splat.get("antialias", "auto")

    pd = vtk.vtkPolyData()

    def arrange():
        """Sorts the points back to front and writes the arrays the mapper reads."""
        u = x - eye
        dist = (u @ forward) if ortho else np.sqrt((u * u).sum(axis=1))
        order = np.argsort(-dist, kind="stable")
        depth = np.maximum(np.abs(u[order] @ forward), 1e-12)
        sd = s[order]
        peak = d_peak[order]
        # Footprint variance in px² (on the optical axis) and the low-pass's change of the peak.
        var = (focal * sd) ** 2 if ortho else (focal * sd / depth) ** 2
        if antialias == "ewa":
            peak = peak * var / (var + lowpass)
        elif antialias in ("swan", "auto"):
            grow = np.maximum(lowpass / var, 1.0)
            sd, peak = sd * np.sqrt(grow), peak / grow
        byte = np.rint(peak / d_max * 255.0)
        drawn = byte > 0
        # The mapper truncates opacity·255 to a byte: half a step up makes that the rounding.
        opacity = (byte[drawn] + 0.5) / 255.0
        pts = vtk.vtkPoints()
        pts.SetData(numpy_support.numpy_to_vtk(x[order][drawn], deep=True))
        pd.SetPoints(pts)
        for name, values in (("scalars", f[order][drawn]), ("opacity", opacity), ("radius", sd[drawn])):
            arr = numpy_support.numpy_to_vtk(values.astype(np.float32), deep=True)
            arr.SetName(name)
            pd.GetPointData().AddArray(arr)
        pd.Modified()
        return int(drawn.sum())

    drawn = arrange()
    color = vtk.vtkColorTransferFunction()
    color.SetColorSpaceToRGB()
    for q in points:
        color.AddRGBPoint(q[0], *(min(max(c, 0.0), 1.0) for c in q[1:4]))
    mapper = vtk.vtkPointGaussianMapper()
    mapper.SetInputData(pd)
    mapper.SetScaleArray("radius")
    mapper.SetScaleFactor(1.0)
    mapper.SetOpacityArray("opacity")
    mapper.SetLookupTable(color)
    mapper.SetScalarModeToUsePointFieldData()
    mapper.SelectColorArray("scalars")
    mapper.SetColorModeToMapScalars()
    mapper.UseLookupTableScalarRangeOn()
    mapper.ScalarVisibilityOn()
    mapper.EmissiveOff()
    mapper.SetBoundScale(cutoff)
    if antialias == "ewa":
        mapper.SetLowpassMatrix(lowpass * (2.0 / width) ** 2, 0.0, lowpass * (2.0 / height) ** 2)
    else:
        mapper.SetLowpassMatrix(0.0, 0.0, 0.0)
    mapper.SetSplatShaderCode(
        "//VTK::Color::Impl\n"
        "  float dist2 = dot(offsetVCVSOutput.xy, offsetVCVSOutput.xy);\n"
        f"  if (dist2 > {cutoff * cutoff!r}) {{ discard; }}\n"
        f"  opacity = 1.0 - exp(-{d_max!r} * opacity * exp(-0.5 * dist2));\n")
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)
    actor.ForceTranslucentOn()
    ren = vtk.vtkRenderer()
    ren.AddActor(actor)
    ren.SetUseDepthPeeling(0)
    ren.SetUseOIT(False)
    ren.SetBackground(*scene.get("render", {}).get("background", [0.0, 0.0, 0.0]))
    # A float framebuffer: VTK's standard render steps drawn into the RGBA32F target of a tone
    # mapping pass that only clamps to [0, 1] (see the module docs, "Framebuffer").
    float_target = vtk.vtkToneMappingPass()
    float_target.SetToneMappingType(vtk.vtkToneMappingPass.Clamp)
    float_target.SetDelegatePass(vtk.vtkRenderStepsPass())
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetMultiSamples(0)
    win.SetSize(width, height)
    win.AddRenderer(ren)
    camera = ren.GetActiveCamera()
    camera.SetPosition(*eye)
    camera.SetFocalPoint(*target)
    camera.SetViewUp(*cam.get("up", [0.0, 0.0, 1.0]))
    if ortho:
        camera.ParallelProjectionOn()
        camera.SetParallelScale(cam.get("view_height", 2.0) / 2)
    else:
        camera.SetViewAngle(fov)
    # Near and far planes around every kernel's cutoff (the depth test never rejects a splat:
    # translucent geometry writes no depth).
    dist = np.sqrt(((x - eye) ** 2).sum(axis=1))
    reach = cutoff * float(s.max()) * 2
    camera.SetClippingRange(max(float(dist.min()) - reach, 1e-3 * float(dist.max())), float(dist.max()) + reach)
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.SetInputBufferTypeToRGBA()
    grab.ReadFrontBufferOff()

    def frame(sort):
        t = time.perf_counter()
        if sort:
            arrange()
        win.Render()
        grab.Modified()
        grab.Update()
        return (time.perf_counter() - t) * 1e3

    rows = []
    device, version = "", ""
    # (framebuffer, sort every frame): the matched configuration first.
    for i, (fb, sort) in enumerate((("float32", False), ("float32", True), ("rgba8", False))):
        ren.SetPass(float_target if fb == "float32" else None)
        first = frame(False)  # shaders for this pipeline
        if not device:  # the GL context exists after the first frame
            device, version = gl_strings(win)
        times = [frame(sort) for _ in range(a.repeat)]
        image_path = os.path.join(a.out, f"{i:03}.png")
        write_png(grab, image_path)
        rows.append(peer_row(
            "vtk-point-gaussian", f"framebuffer={fb};sort={'per-frame' if sort else 'once'};splats={drawn}",
            device, version, width, height, times, first, prepare_ms, image_path))
    # The pass owns GL objects, which it must free while the context exists.
    ren.SetPass(None)
    float_target.ReleaseGraphicsResources(win)
    return rows


def gl_strings(win):
    """(renderer, version) of the window's OpenGL context, which exists after a first frame."""
    info = win.ReportCapabilities().splitlines()
    device = next((l for l in info if "OpenGL renderer string" in l), ":OpenGL").split(":", 1)[1].strip()
    version = next((l for l in info if "OpenGL version string" in l), ":").split(":", 1)[1].strip()
    return device, version


def write_png(grab, path):
    # vtkPNGWriter writes VTK's bottom-up rows top row first, as vmls's images are.
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(path)
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()


def peer_row(method, settings, device, version, width, height, times, first, prepare_ms, image_path):
    """A row in results.csv's columns: wall times only, the error columns left to vmls bench."""
    return {
        "source": "vtk", "method": method, "settings": settings,
        "device": device, "driver": f"VTK {vtk.vtkVersion.GetVTKVersion()}, OpenGL {version}",
        "vmls_version": "", "commit": "", "width": width, "height": height,
        "frames": len(times), "gpu_ms": "", "gpu_ms_min": "", "gpu_ms_max": "", "kernel_ms": "",
        "wall_ms": statistics.median(times), "first_frame_wall_ms": first,
        "first_frame_gpu_ms": "", "prepare_ms": prepare_ms, "evaluations": "",
        "evaluations_per_s": "", "bytes_uploaded_first": "", "bytes_uploaded_next": "",
        "rmse": "", "max_abs": "", "max_x": "", "max_y": "", "psnr": "", "non_finite": "",
        "fma_share": "", "memory_share": "", "bound_by": "", "reference": "", "variant": f"image={image_path}",
    }


def write_rows(out, rows):
    with open(os.path.join(out, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)


def run_unstructured(scene, a, base):
    t0 = time.perf_counter()
    vol = scene["volume"]
    path = os.path.join(base, vol["file"])
    grid = read_with(vtk.vtkXMLUnstructuredGridReader() if path.endswith(".vtu") else vtk.vtkUnstructuredGridReader(),
                     path, vol.get("scalars"))
    tets = vtk.vtkDataSetTriangleFilter()
    tets.SetInputData(grid)
    tets.TetrahedraOnlyOn()
    tets.Update()
    mesh = tets.GetOutput()
    prepare_ms = (time.perf_counter() - t0) * 1e3
    points = scene["transfer"]["points"]
    unit = 1.0 / max(max(q[4] for q in points), 1e-30)
    prop = volume_property(points, unit, lambda tau: tau * unit)
    cam = scene.get("camera", {})
    width, height = int(cam.get("width", 256)), int(cam.get("height", 256))
    rows = []
    device, version = "", ""
    for i, (name, mapper) in enumerate((
            ("vtk-unstructured-raycast", vtk.vtkUnstructuredGridVolumeRayCastMapper()),
            ("vtk-projected-tetrahedra", vtk.vtkProjectedTetrahedraMapper()))):
        mapper.SetInputData(mesh)
        settings = f"tetrahedra={mesh.GetNumberOfCells()}"
        if name == "vtk-unstructured-raycast":
            mapper.AutoAdjustSampleDistancesOff()
            mapper.SetImageSampleDistance(1.0)
            settings += f";threads={mapper.GetNumberOfThreads()}"
        ren, win, grab, frame = volume_window(scene, mapper, prop, width, height)
        ren.ResetCameraClippingRange()
        first = frame()
        if not device:
            device, version = gl_strings(win)
        times = [frame() for _ in range(a.repeat)]
        image_path = os.path.join(a.out, f"{i:03}.png")
        write_png(grab, image_path)
        rows.append(peer_row(name, settings, device, version, width, height, times, first,
                             prepare_ms, image_path))
        win.Finalize()
    return rows


def volume_property(points, unit, opacity_of):
    """vmls's transfer points tabulated at 1024 values (colour in RGB, linear) with opacity
    opacity_of(τ) per `unit` of ScalarOpacityUnitDistance; linear interpolation, no shading."""
    s_lo, s_hi = points[0][0], points[-1][0]
    color, opacity = vtk.vtkColorTransferFunction(), vtk.vtkPiecewiseFunction()
    color.SetColorSpaceToRGB()
    for i in range(1024):
        s = s_lo + (s_hi - s_lo) * i / 1023
        r, g, b, tau = tf_lookup(points, s)
        color.AddRGBPoint(s, r, g, b)
        opacity.AddPoint(s, opacity_of(tau))
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(unit)
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOff()
    return prop


def volume_window(scene, mapper, prop, width, height):
    """An offscreen window drawing `mapper` with `prop` through the scene's camera: (renderer,
    window, framebuffer grab, frame), frame() rendering once and returning its wall ms."""
    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    ren = vtk.vtkRenderer()
    ren.AddVolume(volume)
    ren.SetBackground(*scene.get("render", {}).get("background", [0.0, 0.0, 0.0]))
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetSize(width, height)
    win.AddRenderer(ren)
    set_camera(ren.GetActiveCamera(), scene.get("camera", {}))
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.SetInputBufferTypeToRGBA()
    grab.ReadFrontBufferOff()

    def frame():
        t = time.perf_counter()
        win.Render()
        grab.Modified()
        grab.Update()
        return (time.perf_counter() - t) * 1e3

    return ren, win, grab, frame


def set_camera(camera, cam):
    """vmls's camera keys, with vmls's defaults (src/scene/mod.rs) where the scene leaves one out."""
    camera.SetPosition(*cam.get("eye", [3.0, 2.0, 2.5]))
    camera.SetFocalPoint(*cam.get("target", [0.0, 0.0, 0.0]))
    camera.SetViewUp(*cam.get("up", [0.0, 0.0, 1.0]))
    if cam.get("projection", "perspective") == "orthographic":
        camera.ParallelProjectionOn()
        camera.SetParallelScale(cam.get("view_height", 2.0) / 2)
    else:
        camera.SetViewAngle(cam.get("fov_y", 30.0))


def is_unstructured(scene, base):
    name = str(scene.get("volume", {}).get("file", ""))
    if name.lower().endswith(".vtu"):
        return True
    if name.lower().endswith(".vtk"):
        with open(os.path.join(base, name), "rb") as f:
            return b"UNSTRUCTURED_GRID" in f.read(4096)
    return False


def is_points(scene):
    return str(scene.get("volume", {}).get("file", "")).lower().endswith(".csv")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("scene")
    p.add_argument("--set", action="append", default=[])
    p.add_argument("--steps", default="1,0.5,0.25", help="sample distances in spacings")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--out", required=True)
    a = p.parse_args()
    with open(a.scene, "rb") as f:
        scene = tomllib.load(f)
    for s in a.set:
        apply_set(scene, s)
    if scene.get("transfer", {}).get("isosurfaces"):
        sys.exit("peer-vtk: scenes with isosurfaces are not matched (VTK's volume mapper has none)")
    os.makedirs(a.out, exist_ok=True)
    base = os.path.dirname(os.path.abspath(a.scene))
    if is_points(scene):
        write_rows(a.out, run_points(scene, a, base))
        return
    if is_unstructured(scene, base):
        write_rows(a.out, run_unstructured(scene, a, base))
        return
    img, spacing = load_volume(scene, base)
    cam = scene.get("camera", {})
    width, height = int(cam.get("width", 256)), int(cam.get("height", 256))
    points = scene["transfer"]["points"]
    unit = spacing
    prop = volume_property(points, unit, lambda tau: 1.0 - math.exp(-tau * unit))
    mapper = vtk.vtkGPUVolumeRayCastMapper()
    mapper.SetInputData(img)
    mapper.AutoAdjustSampleDistancesOff()
    mapper.SetBlendModeToComposite()
    ren, win, grab, frame = volume_window(scene, mapper, prop, width, height)
    rows = []
    device, version = "", ""
    for i, step in enumerate(float(x) for x in a.steps.split(",")):
        mapper.SetSampleDistance(step * spacing)
        # Near and far planes around the volume, as vmls clips rays to its box.
        ren.ResetCameraClippingRange()
        first = frame()
        if not device:  # the GL context exists after the first frame
            device, version = gl_strings(win)
        times = [frame() for _ in range(a.repeat)]
        image_path = os.path.join(a.out, f"{i:03}.png")
        write_png(grab, image_path)
        rows.append(peer_row("vtk-gpu", f"sample_distance={step}", device, version, width, height,
                             times, first, 0.0, image_path))
    with open(os.path.join(a.out, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
