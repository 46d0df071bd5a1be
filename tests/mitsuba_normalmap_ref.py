"""The Mitsuba 3 reference of the normal-mapped sphere (tests/test_normal_map.py).

    python -m tests.mitsuba_normalmap_ref [SPP]     # needs mitsuba (pip install -e .[bench])

A fine UV sphere (146,688 triangles, texture coordinates, exact normals) with a mild
normal map (smooth bumps leaning up to about 20 degrees, tiled), a principled material,
lit by the generated smooth sky of tests/mitsuba_refs.py, seen by the same 40x40 camera as
the other references. Mitsuba's side: ``normalmap`` around ``principled``, the map a raw
(linear) bilinear ``bitmap``; its OBJ loader flips v (flip_tex_coords), so that v = 0 is the
bottom of the image in both renderers. The image goes to tests/references/normalmap.npy
and its settings to normalmap.json.
"""
import os
import sys

import numpy as np

from tests.mitsuba_refs import (CAMERA, FOV, GRADIENT, MAX_BOUNCES, RES, save_reference,
                                smooth_sky)

NAME = "normalmap"
MATERIAL = {"albedo": [0.8, 0.45, 0.2], "roughness": 0.5}
TILE = [3, 2]
SPHERE_RES = (192, 384)


def bump_normal_map(path, w=128, h=64, tilt_deg=20.0, flip_green=False):
    """A smooth, tileable tangent-space normal map (OpenGL convention, +Y green up): the
    slopes of sin(2 pi u) sin(2 pi v)-like bumps, leaning at most tilt_deg; 8-bit PNG.
    ``flip_green``: the same map in the DirectX convention (the wrong one for us)."""
    import imageio.v3 as iio
    u = (np.arange(w) + 0.5) / w
    v = 1 - (np.arange(h) + 0.5) / h          # row 0 is the top of the image, v = 1
    uu, vv = np.meshgrid(u, v)
    k = np.tan(np.radians(tilt_deg))
    dx = k * np.cos(2 * np.pi * uu) * np.sin(2 * np.pi * vv)
    dy = k * 0.6 * np.sin(2 * np.pi * uu) * np.cos(4 * np.pi * vv)
    n = np.stack([-dx, -dy, np.ones_like(dx)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    if flip_green:
        n[..., 1] = -n[..., 1]
    iio.imwrite(path, np.round((n * 0.5 + 0.5) * 255).astype(np.uint8))
    return path


def our_scene(obj, png, spp=64, seed=0):
    m = dict(MATERIAL, name="m", normalMap={"texture": png, "tile": TILE})
    return {"camera": {"resolution": [RES, RES], "position": list(CAMERA),
                       "lookAt": [0, 0, 0], "fov": FOV},
            "render": {"spp": spp, "maxBounces": MAX_BOUNCES, "seed": seed},
            "materials": [m],
            "objects": [{"name": "sphere", "file": obj, "material": "m", "smooth": True}],
            # the plain density, as Mitsuba's (see tests/mitsuba_refs.our_scene)
            "environment": {"file": GRADIENT, "misCompensation": False}}


def render_mitsuba(obj, png, spp, variant="llvm_ad_rgb"):
    import mitsuba as mi
    from pathtracer.mitsuba import mitsuba_bsdf
    from tests.mitsuba_refs import render_mitsuba as render_sphere
    mi.set_variant(variant)
    bsdf = {"type": "normalmap",
            "normalmap": {"type": "bitmap", "filename": png, "raw": True,
                          "filter_type": "bilinear",
                          "to_uv": mi.ScalarTransform4f().scale([TILE[0], TILE[1], 1])},
            "bsdf": mitsuba_bsdf(MATERIAL)}
    return render_sphere(MATERIAL, GRADIENT, spp, variant, obj=obj, bsdf=bsdf)


def main():
    import tempfile
    from tests.test_normal_map import write_sphere_obj
    spp = int(sys.argv[1]) if len(sys.argv) > 1 else 16384
    smooth_sky()
    with tempfile.TemporaryDirectory() as tmp:
        obj = os.path.join(tmp, "sphere.obj")
        write_sphere_obj(obj, *SPHERE_RES)
        png = bump_normal_map(os.path.join(tmp, "n.png"))
        img, version = render_mitsuba(obj, png, spp)
    save_reference(NAME, img, version, spp, f"python -m tests.mitsuba_normalmap_ref {spp}",
                   material=MATERIAL, tile=TILE, sphere=SPHERE_RES)


if __name__ == "__main__":
    main()
