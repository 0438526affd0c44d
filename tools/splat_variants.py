#!/usr/bin/env python3
"""Writes the kernel variants of tools/splat-variants: SRC/ copied to OUT/<variant>/ with one
edit each to splat_raster's post-shaded path. Each edit must match exactly once, so a variant
that no longer applies to the committed kernels fails here instead of measuring the base.
Usage: tools/splat_variants.py SRC-GLSL-DIR OUT-DIR"""
import shutil
import sys
from pathlib import Path

RASTER = "splat/splat_raster.comp"
POST = "splat/raster_post.glsl"

# variant -> [(file, old, new)]
EDITS = {
    "base": [],
    # The midpoint rule's ring: a kernel adds only at the seeds (sheets 4 and 12, ring 4: 2),
    # every step between them is gone. Tells what the steps cost.
    "noring": [(RASTER, "#define STEP(d, r) \\\n    g *= rho; \\\n    rho *= c; \\\n    MID(d, r)",
                "#define STEP(d, r)")],
    # No interval is looked up or composited. Tells what compositing costs.
    "nocomp": [(POST, "float s_f, float s_b) {\n", "float s_f, float s_b) {\n    return;\n")],
}


def main() -> None:
    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    for name, edits in EDITS.items():
        dst = out / name
        if dst.exists():
            shutil.rmtree(dst)
        shutil.copytree(src, dst)
        for rel, old, new in edits:
            path = dst / rel
            text = path.read_text()
            if text.count(old) != 1:
                sys.exit(f"splat_variants: {name}: the edit of {rel} matches "
                         f"{text.count(old)} times, not once")
            path.write_text(text.replace(old, new))


if __name__ == "__main__":
    main()
