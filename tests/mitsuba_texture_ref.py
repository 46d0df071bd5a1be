"""The Mitsuba 3 reference of the textured sphere (tests/test_mitsuba.py,
``test_textures_agree_with_mitsuba``).

    python -m tests.mitsuba_texture_ref [SPP]     # needs mitsuba (pip install -e .[bench])

A UV sphere with texture coordinates and a principled material whose base colour (an sRGB
photograph, mirrored repeats) and roughness (a generated linear image, plain repeats) are image
textures with tiles and offsets that are not whole numbers, so that a texture turned,
flipped, shifted by half a texel or decoded with the wrong curve shows. Lit by the smooth
generated sky of tests/mitsuba_refs.py and seen by the same 40x40 camera as the other
references. Mitsuba's scene is the translation that the benchmark uses
(pathtracer.mitsuba.mitsuba_dict of our scene), so the test checks that translation too:
the textures' orientation, tiling and wrapping, sRGB decoding and bilinear lookups. The
image goes to tests/references/textured.npy and its settings to textured.json.
"""
import json
import os
import sys

import numpy as np

from tests.mitsuba_refs import (CAMERA, FOV, GRADIENT, MAX_BOUNCES, REF_DIR, RES,
                                render_in_passes, save_reference, smooth_sky)

NAME = "textured"
ASSETS = os.path.join(os.path.dirname(REF_DIR), "..", "scenes", "assets")
ALBEDO = os.path.abspath(os.path.join(ASSETS, "factory_wall_diff_256.png"))
SPHERE_RES = (64, 128)
MATERIAL = {
    "albedo": {"texture": ALBEDO, "tile": [1.5, 0.75], "offset": [0.2, 0.1],
               "wrap": "mirror", "filter": "bilinear"},
    "roughness": {"texture": "roughness.png", "tile": [2, 1.25], "offset": [0.0, 0.3],
                  "filter": "bilinear"},
    "metallic": 0.7,
}


def roughness_map(path, w=64, h=32):
    """An 8-bit linear roughness image from 0.1 to 0.9 with no symmetry (a ramp along u,
    bands of two heights along v): a turned, flipped or shifted lookup changes the
    highlights."""
    import imageio.v3 as iio
    x = (np.arange(w) + 0.5) / w
    band = np.where((np.arange(h) // 4) % 3 == 0, 1.0, 0.35)
    r = 0.1 + 0.8 * x[None, :] * band[:, None]
    iio.imwrite(path, np.round(r * 255).astype(np.uint8))
    return path


def our_scene(obj, roughness, spp=64, seed=0, sampler="independent"):
    """Our scene file; ``roughness``: the path of roughness_map's image."""
    material = dict(MATERIAL, name="m")
    material["roughness"] = dict(MATERIAL["roughness"], texture=roughness)
    return {"camera": {"resolution": [RES, RES], "position": list(CAMERA),
                       "lookAt": [0, 0, 0], "fov": FOV},
            "render": {"spp": spp, "maxBounces": MAX_BOUNCES, "seed": seed,
                       "sampler": sampler},
            "materials": [material],
            "objects": [{"name": "sphere", "file": obj, "material": "m", "smooth": True}],
            # the plain density, as Mitsuba's (see tests/mitsuba_refs.our_scene)
            "environment": {"file": GRADIENT, "misCompensation": False}}


def render_mitsuba(scene_path, spp, variant="llvm_ad_rgb"):
    """Mitsuba's image of our scene file, through pathtracer.mitsuba; with its version."""
    import mitsuba as mi

    from pathtracer.mitsuba import mitsuba_dict
    from pathtracer.scene import load_scene_description
    mi.set_variant(variant)
    return render_in_passes(mi.load_dict(mitsuba_dict(load_scene_description(scene_path))),
                            spp)


def main():
    import tempfile

    from tests.test_normal_map import write_sphere_obj
    spp = int(sys.argv[1]) if len(sys.argv) > 1 else 16384
    smooth_sky()
    with tempfile.TemporaryDirectory() as tmp:
        obj = os.path.join(tmp, "sphere.obj")
        write_sphere_obj(obj, *SPHERE_RES)
        rough = roughness_map(os.path.join(tmp, "roughness.png"))
        path = os.path.join(tmp, "scene.json")
        with open(path, "w") as f:
            json.dump(our_scene(obj, rough, spp), f)
        img, version = render_mitsuba(path, spp)
    save_reference(NAME, img, version, spp, f"python -m tests.mitsuba_texture_ref {spp}",
                   material={k: (dict(v, texture=os.path.basename(v["texture"]))
                                 if isinstance(v, dict) else v) for k, v in MATERIAL.items()},
                   sphere=SPHERE_RES)


if __name__ == "__main__":
    main()
