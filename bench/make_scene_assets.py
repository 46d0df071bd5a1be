"""Make the small assets of the gallery scenes in scenes/assets/ from ../shared/assets
(downsized copies of CC0 / MIT data; scenes/assets/LICENSE.md names the sources).

    python -m bench.make_scene_assets [../shared]
"""
import os
import shutil
import sys

import numpy as np

from pathtracer.film import linear_to_srgb, write_image
from pathtracer.scene.geometry import uv_sphere
from pathtracer.scene.images import read_image, srgb_to_linear

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def box_down(img, k):
    h, w = img.shape[0] // k * k, img.shape[1] // k * k
    return img[:h, :w].reshape(h // k, k, w // k, k, -1).mean(axis=(1, 3))


def main():
    shared = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "..", "shared")
    a = os.path.join(shared, "assets")
    out = os.path.join(ROOT, "scenes", "assets")
    os.makedirs(out, exist_ok=True)
    import imageio.v3 as iio
    # HDRI: 1024x512 -> 256x128 (box filter preserves the light's integral)
    img, _ = read_image(os.path.join(a, "hdri", "studio_small_03_1k.hdr"))
    write_image(os.path.join(out, "studio_small_03_256.hdr"), box_down(img, 4).astype(np.float32))
    # factory_wall PBR set: 1024^2 -> 256^2
    base = os.path.join(a, "textures", "factory_wall", "factory_wall_")
    diff, _ = read_image(base + "diff_1k.png")
    iio.imwrite(os.path.join(out, "factory_wall_diff_256.png"), np.round(
        linear_to_srgb(box_down(srgb_to_linear(diff), 4)) * 255).astype(np.uint8))
    nor, _ = read_image(base + "nor_gl_1k.png")
    n = box_down(nor * 2 - 1, 4)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    iio.imwrite(os.path.join(out, "factory_wall_nor_gl_256.png"),
                np.round((n * 0.5 + 0.5) * 255).astype(np.uint8))
    rough, _ = read_image(base + "rough_1k.png")
    iio.imwrite(os.path.join(out, "factory_wall_rough_256.png"),
                np.round(box_down(rough, 4)[:, :, 0] * 255).astype(np.uint8))
    shutil.copy(os.path.join(a, "textures", "checker", "kenney_prototype_light_texture_06_rgb.png"),
                os.path.join(out, "checker.png"))
    # Suzanne with UVs, without its flat per-face normals (so that smooth shading computes
    # vertex normals)
    src = open(os.path.join(a, "models", "suzanne_uv.obj")).read().splitlines()
    keep = ["# Blender's Suzanne with UVs (ekzhang/graphics-workshop, MIT); vn removed"]
    for line in src:
        if line.startswith("vn "):
            continue
        if line.startswith("f "):
            line = "f " + " ".join("/".join(c.split("/")[:2]) for c in line.split()[1:])
        keep.append(line)
    open(os.path.join(out, "suzanne_uv.obj"), "w").write("\n".join(keep) + "\n")
    sphere(os.path.join(out, "sphere.obj"))
    plane(os.path.join(out, "plane.obj"))


def sphere(path, n_theta=24, n_phi=48):
    """UV sphere of radius 1 with normals and texture coordinates."""
    verts, faces, uvs = uv_sphere(n_theta, n_phi, seam=True)
    lines = ["# UV sphere, radius 1 (bench/make_scene_assets.py)"]
    for (x, y, z), (u, v) in zip(verts, uvs):
        lines.append(f"v {x:.6f} {y:.6f} {z:.6f}")
        lines.append(f"vn {x:.6f} {y:.6f} {z:.6f}")
        lines.append(f"vt {u:.6f} {v:.6f}")
    lines += ["f {0}/{0}/{0} {1}/{1}/{1} {2}/{2}/{2}".format(*(f + 1)) for f in faces]
    open(path, "w").write("\n".join(lines) + "\n")


def plane(path):
    open(path, "w").write("# unit plane y = 0, [-1, 1]^2, uv [0, 1]^2\n"
                          "v -1 0 1\nv 1 0 1\nv 1 0 -1\nv -1 0 -1\n"
                          "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 1 0\n"
                          "f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")


if __name__ == "__main__":
    main()
