#!/usr/bin/env python3
"""The VTK peer of `vmls bench --peer vtk`: renders a vmls scene file with VTK's GPU ray caster
(vtkGPUVolumeRayCastMapper, OpenGL; EGL offscreen on llvmpipe here) and writes its images and a
results.csv in the bench's columns (source = vtk; error columns empty: vmls bench measures them
against its own reference).

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


def load_volume(scene, base):
    vol = scene.get("volume", {})
    if "file" in vol:
        path = os.path.join(base, vol["file"])
        reader = vtk.vtkXMLImageDataReader() if path.endswith(".vti") else vtk.vtkStructuredPointsReader()
        reader.SetFileName(path)
        reader.Update()
        img = reader.GetOutput()
        if "scalars" in vol:
            img.GetPointData().SetActiveScalars(vol["scalars"])
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
    img, spacing = load_volume(scene, os.path.dirname(os.path.abspath(a.scene)))
    cam = scene.get("camera", {})
    width, height = int(cam.get("width", 256)), int(cam.get("height", 256))
    points = scene["transfer"]["points"]
    s_lo, s_hi = points[0][0], points[-1][0]
    unit = spacing
    color, opacity = vtk.vtkColorTransferFunction(), vtk.vtkPiecewiseFunction()
    for i in range(1024):
        s = s_lo + (s_hi - s_lo) * i / 1023
        r, g, b, tau = tf_lookup(points, s)
        color.AddRGBPoint(s, r, g, b)
        opacity.AddPoint(s, 1.0 - math.exp(-tau * unit))
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(unit)
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOff()
    mapper = vtk.vtkGPUVolumeRayCastMapper()
    mapper.SetInputData(img)
    mapper.AutoAdjustSampleDistancesOff()
    mapper.SetBlendModeToComposite()
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
    camera = ren.GetActiveCamera()
    # vmls's defaults (src/scene/mod.rs) where the scene leaves a key out.
    camera.SetPosition(*cam.get("eye", [3.0, 2.0, 2.5]))
    camera.SetFocalPoint(*cam.get("target", [0.0, 0.0, 0.0]))
    camera.SetViewUp(*cam.get("up", [0.0, 0.0, 1.0]))
    if cam.get("projection", "perspective") == "orthographic":
        camera.ParallelProjectionOn()
        camera.SetParallelScale(cam.get("view_height", 2.0) / 2)
    else:
        camera.SetViewAngle(cam.get("fov_y", 30.0))
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

    rows = []
    device, version = "", ""
    for i, step in enumerate(float(x) for x in a.steps.split(",")):
        mapper.SetSampleDistance(step * spacing)
        # Near and far planes around the volume, as vmls clips rays to its box.
        ren.ResetCameraClippingRange()
        first = frame()
        if not device:  # the GL context exists after the first frame
            info = win.ReportCapabilities().splitlines()
            device = next((l for l in info if "OpenGL renderer string" in l), ":OpenGL").split(":", 1)[1].strip()
            version = next((l for l in info if "OpenGL version string" in l), ":").split(":", 1)[1].strip()
        times = [frame() for _ in range(a.repeat)]
        writer = vtk.vtkPNGWriter()
        image_path = os.path.join(a.out, f"{i:03}.png")
        writer.SetFileName(image_path)
        # vtkPNGWriter writes VTK's bottom-up rows top row first, as vmls's images are.
        writer.SetInputConnection(grab.GetOutputPort())
        writer.Write()
        rows.append({
            "source": "vtk", "method": "vtk-gpu",
            "settings": f"sample_distance={step}",
            "device": device, "driver": f"VTK {vtk.vtkVersion.GetVTKVersion()}, OpenGL {version}",
            "vmls_version": "", "commit": "", "width": width, "height": height,
            "frames": a.repeat, "gpu_ms": "", "gpu_ms_min": "", "gpu_ms_max": "", "kernel_ms": "",
            "wall_ms": statistics.median(times), "first_frame_wall_ms": first,
            "first_frame_gpu_ms": "", "prepare_ms": 0.0, "evaluations": "",
            "evaluations_per_s": "", "bytes_uploaded_first": "", "bytes_uploaded_next": "",
            "rmse": "", "max_abs": "", "max_x": "", "max_y": "", "psnr": "", "non_finite": "",
            "fma_share": "", "memory_share": "", "bound_by": "", "reference": "", "variant": f"image={image_path}",
        })
    with open(os.path.join(a.out, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
