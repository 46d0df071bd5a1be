"""Render the Mitsuba 3 references that tests/test_mitsuba.py compares against.

    python -m tests.mitsuba_refs            # needs `pip install -e .[bench]` and ../shared

Each case is a smooth sphere lit by ../shared/assets/hdri/studio_small_03_1k.hdr (Mitsuba's
`envmap` turned 180 degrees about +Y, which matches the scene format's mapping), seen by a
40x40 perspective camera, path traced with max_depth = maxBounces + 1. The principled
parameters are written in the scene format's names; pathtracer.mitsuba translates them. The
images go to tests/references/<case>.npy with their settings in references.json.
"""
import datetime
import json
import os
import platform
import sys

import numpy as np

from pathtracer.mitsuba import mitsuba_bsdf
from pathtracer.scene.geometry import uv_sphere

HERE = os.path.dirname(os.path.abspath(__file__))
REF_DIR = os.path.join(HERE, "references")
SPHERE = os.path.join(REF_DIR, "sphere.obj")
RES = 40
FOV = 30.0
CAMERA = (0.0, 0.3, 4.0)
MAX_BOUNCES = 8
HDRI = "studio_small_03_1k.hdr"
# Transmissive and near-mirror cases are lit by a smooth synthetic sky instead. Through
# near-specular glass the studio's small bright lamps make both renderers' estimates
# heavy-tailed; and a near-mirror resolves the map texel by texel, where Mitsuba's
# envmap places its texels half a texel away from the scene format's texel centres (the
# mean of the smooth-metal sphere then differs by 1.4%). Under the smooth sky they agree
# to 0.03%. The sky file is generated, not kept in git.
GRADIENT = os.path.join(REF_DIR, "gradient_sky.hdr")   # made by gradient_sky(), not kept
SMOOTH_SKY_CASES = ("principled_glass_rough", "principled_mixed", "glass_smooth_vs_dielectric",
                    "principled_metal_smooth")


def gradient_sky(path=GRADIENT, w=2048, h=1024):
    """A low-frequency equirectangular sky: blue above, warm below, one soft bright lobe
    and an azimuthal ramp (so that rotations and flips show). Fine enough (texels of 0.18
    degrees) that Mitsuba's envmap, which places texels about half a texel off the scene
    format's texel centres, reads the same values within the noise of 8192 samples per pixel
    even in a mirror (at 512 x 256 the smooth-metal case showed the offset on the GPU)."""
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    theta = np.pi * v[:, None]
    phi = 2 * np.pi * (u[None, :] - 0.5)
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta) + 0 * phi,
                  -np.sin(theta) * np.cos(phi)], -1)
    up = np.clip(d[..., 1], 0, 1)[..., None]
    img = (up * np.array([0.3, 0.5, 1.0]) + (1 - up) * np.array([0.8, 0.5, 0.3]) *
           (0.5 + 0.5 * u[None, :, None]))
    lobe = np.exp(8 * (d @ np.array([0.6, 0.6, 0.53]) - 1))[..., None] * np.array([4, 3.5, 3])
    img = (img + lobe).astype(np.float32)
    from pathtracer.film import write_image
    write_image(path, img)
    return path


def smooth_sky():
    """The path of the generated smooth sky, made first if it is missing (not kept in git)."""
    if not os.path.isfile(GRADIENT):
        gradient_sky()
    return GRADIENT


def save_reference(name, img, version, spp, command, **settings):
    """Write a reference image to tests/references/<name>.npy and its settings, with the
    Mitsuba version, date, machine and command that made it, to <name>.json."""
    np.save(os.path.join(REF_DIR, name + ".npy"), img)
    meta = {"spp": spp, "mitsuba": version, "date": datetime.date.today().isoformat(),
            "machine": platform.processor() or platform.machine(), "command": command,
            **settings}
    with open(os.path.join(REF_DIR, name + ".json"), "w") as f:
        json.dump(meta, f, indent=1)
    print(name, img.mean(axis=(0, 1)))


def env_for(case, shared):
    if case in SMOOTH_SKY_CASES:
        return smooth_sky()
    return os.path.join(shared, "assets", "hdri", HDRI)

BASE = [0.8, 0.45, 0.2]
DARK = [0.04, 0.03, 0.02]
CASES = {
    # each principled lobe alone, then mixed
    "diffuse_only": {"type": "diffuse", "albedo": BASE},
    "principled_default": {"albedo": BASE},
    "principled_rough_dielectric": {"albedo": BASE, "roughness": 0.9},
    "principled_subsurface": {"albedo": BASE, "subsurface": 1.0, "roughness": 0.7},
    "principled_metal_smooth": {"albedo": BASE, "metallic": 1.0, "roughness": 0.15},
    "principled_metal_rough": {"albedo": BASE, "metallic": 1.0, "roughness": 0.6},
    "principled_anisotropic": {"albedo": BASE, "metallic": 1.0, "roughness": 0.4,
                               "anisotropic": 0.8},
    "principled_spec_tint": {"albedo": BASE, "specularTint": 1.0, "specular": 1.0,
                             "roughness": 0.3},
    # sheen and clearcoat are weak lobes: on a dark base they decide the image
    "principled_sheen": {"albedo": DARK, "sheen": 1.0, "sheenTint": 0.5, "roughness": 0.8,
                         "specular": 0.0},
    "principled_clearcoat": {"albedo": DARK, "clearcoat": 1.0, "clearcoatGloss": 0.6,
                             "roughness": 0.8, "specular": 0.0},
    "principled_glass_rough": {"albedo": [1, 1, 1], "transmission": 1.0, "roughness": 0.3,
                               "eta": 1.5},
    "principled_mixed": {"albedo": BASE, "metallic": 0.3, "roughness": 0.45,
                         "transmission": 0.4, "clearcoat": 0.5, "sheen": 0.5,
                         "anisotropic": 0.3, "specularTint": 0.4},
    # smooth glass against Mitsuba's dielectric
    "glass_smooth_vs_dielectric": {"albedo": [1, 1, 1], "transmission": 1.0,
                                   "roughness": 0.0, "eta": 1.5},
    # conductors: Mitsuba's gold (its RGB eta and k) on GGX, and copper's on anisotropic
    # Beckmann with a tint
    "conductor_gold_ggx": {"type": "conductor", "eta": [0.1431, 0.3749, 1.4425],
                           "k": [3.9831, 2.3857, 1.6032], "alphaU": 0.15},
    "conductor_copper_beckmann_aniso": {"type": "conductor", "eta": [0.2004, 0.9240, 1.1022],
                                        "k": [3.9129, 2.4528, 2.1421], "alphaU": 0.3,
                                        "alphaV": 0.06, "distribution": "beckmann",
                                        "albedo": [0.9, 0.85, 0.8]},
}


def sphere_obj(path=SPHERE, n_theta=32, n_phi=64):
    """A UV sphere of radius 1 with exact vertex normals (no texture coordinates)."""
    verts, faces = uv_sphere(n_theta, n_phi)
    lines = ["# UV sphere, radius 1, generated by tests/mitsuba_refs.py"]
    lines += ["v %.9f %.9f %.9f" % tuple(v) for v in verts]
    lines += ["vn %.9f %.9f %.9f" % tuple(v) for v in verts]
    lines += ["f {0}//{0} {1}//{1} {2}//{2}".format(*(f + 1)) for f in faces]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return path


def our_scene(material, env_path, spp=64, seed=0):
    """The same setup in the scene format."""
    m = dict(material)
    m.setdefault("type", "principled")
    m["name"] = "m"
    return {
        "camera": {"resolution": [RES, RES], "position": list(CAMERA), "lookAt": [0, 0, 0],
                   "fov": FOV},
        "render": {"spp": spp, "maxBounces": MAX_BOUNCES, "seed": seed},
        "materials": [m],
        "objects": [{"name": "sphere", "file": SPHERE, "material": "m", "smooth": True}],
        # Mitsuba samples the plain density: the agreement tests model the reference's
        # noise as ours scaled by the sample counts, true only of the same estimator
        # (compensation's unbiasedness: tests/test_environment.py)
        "environment": {"file": env_path, "misCompensation": False},
    }


def render_mitsuba(material, hdri_path, spp, variant="llvm_ad_rgb", obj=SPHERE, bsdf=None):
    """Mitsuba's image of ``obj`` (default: the smooth sphere) with ``material``'s BSDF, or
    the Mitsuba BSDF dict ``bsdf``, under the environment ``hdri_path``; with its version."""
    import mitsuba as mi
    mi.set_variant(variant)
    T = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_BOUNCES + 1},
        "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "x",
                   "to_world": T().look_at(origin=list(CAMERA), target=[0, 0, 0],
                                           up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": RES, "height": RES,
                            "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "env": {"type": "envmap", "filename": hdri_path,
                "to_world": T().rotate([0, 1, 0], 180)},
        "sphere": {"type": "obj", "filename": obj, "face_normals": False,
                   "bsdf": bsdf if bsdf is not None else mitsuba_bsdf(material)},
    })
    return render_in_passes(scene, spp)


def render_in_passes(scene, spp):
    """Mitsuba's RES x RES image of a loaded scene at ``spp``, rendered in passes of at most
    1,024 spp (seeds 0, 1, ...); with Mitsuba's version."""
    import mitsuba as mi
    img = np.zeros((RES, RES, 3))
    passes = max(1, spp // 1024)
    for k in range(passes):
        img += np.array(mi.render(scene, spp=spp // passes, seed=k))
    return (img / passes).astype(np.float32), mi.__version__


def main():
    shared = os.environ.get("PT_RENDER_SHARED", os.path.join(HERE, "..", "..", "shared"))
    sphere_obj()
    gradient_sky()
    spp = int(sys.argv[1]) if len(sys.argv) > 1 else 16384
    # cases named after the spp: only those are rendered (the others' images are kept)
    only = sys.argv[2:] or list(CASES)
    meta = {"hdri": HDRI, "resolution": RES, "spp": spp, "max_bounces": MAX_BOUNCES,
            "date": datetime.date.today().isoformat(), "machine": platform.processor() or
            platform.machine(), "command": "python -m tests.mitsuba_refs " + str(spp),
            "cases": CASES}
    old_path = os.path.join(REF_DIR, "references.json")
    if sys.argv[2:] and os.path.isfile(old_path):
        old = json.load(open(old_path))
        if old["spp"] != spp:
            raise SystemExit(f"the kept references have {old['spp']} spp: render with that")
        meta["dates"] = {**old.get("dates", {n: old["date"] for n in old["cases"]}),
                         **{n: meta["date"] for n in only}}
        meta["date"] = old["date"]
    for name in only:
        material = CASES[name]
        img, version = render_mitsuba(material, env_for(name, shared), spp)
        meta["mitsuba"] = version
        np.save(os.path.join(REF_DIR, name + ".npy"), img)
        print(name, img.mean(axis=(0, 1)), flush=True)
    with open(os.path.join(REF_DIR, "references.json"), "w") as f:
        json.dump(meta, f, indent=1)


if __name__ == "__main__":
    main()
