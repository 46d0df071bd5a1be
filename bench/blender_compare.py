"""glTF models through pt-render and through Blender (its glTF importer and Cycles, CPU) at
equal settings: the same camera (pt-render's framing camera, or the file's), a uniform
white sky of radiance 1 (pt-render's lighting rule for glTF models), the same bounces and
samples, linear float images; the report is each model's channel means, ours / Blender's.

    python3 -m venv BPY && BPY/bin/pip install bpy OpenEXR     # Blender as a module (~400 MB)
    python -m bench.blender_compare MODEL.gltf ... --blender BPY/bin/python [--json OUT]

Blender's Python (bpy 5.0 wants Python 3.11) runs in its own environment, one process per
model. An independent reference for glTF: another importer and another path tracer (its
Principled BSDF is not Mitsuba's principled, which ours follows: a few per cent apart on
rough dielectrics is the material model, not the reader).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from bench.common import write_record

# Runs in Blender's Python: argv[1] is the job (JSON), argv[2] the EXR to write.
WORKER = r"""
import json, math, sys
import bpy
from mathutils import Vector
job = json.load(open(sys.argv[1]))
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=job["model"])
scene = bpy.context.scene
# glTF (and pt-render) is Y up; Blender's importer turns it Z up: (x, y, z) -> (x, -z, y)
def blender(p):
    return Vector((p[0], -p[2], p[1]))
cam_data = bpy.data.cameras.new("cam")
cam_data.sensor_fit = "HORIZONTAL"
cam_data.angle = math.radians(job["fov"])
cam = bpy.data.objects.new("cam", cam_data)
scene.collection.objects.link(cam)
cam.location = blender(job["position"])
direction = blender(job["look_at"]) - cam.location
cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
scene.camera = cam
world = bpy.data.worlds.new("white")
world.use_nodes = True
bg = world.node_tree.nodes["Background"]
bg.inputs[0].default_value = (1.0, 1.0, 1.0, 1.0)
bg.inputs[1].default_value = 1.0
scene.world = world
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = job["spp"]
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = job["bounces"]
for key in ("diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces",
            "transparent_max_bounces"):
    setattr(scene.cycles, key, job["bounces"])
scene.cycles.sample_clamp_direct = 0.0
scene.cycles.sample_clamp_indirect = 0.0
scene.cycles.pixel_filter_type = "BOX"
scene.cycles.filter_width = 1.0
scene.render.resolution_x, scene.render.resolution_y = job["resolution"]
scene.render.resolution_percentage = 100
scene.view_settings.view_transform = "Standard"
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = sys.argv[2]
bpy.ops.render.render(write_still=True)
"""


def ours(model, width, spp, bounces):
    """pt-render's image of ``model`` and the camera it used."""
    import pathtracer as pt
    scene = pt.load_scene(model)
    cam = scene.description.camera
    w, h = cam.resolution
    res = (width, max(1, round(width * h / w)))
    scene.set("/camera/resolution", list(res))
    image = pt.render(scene, spp=spp, backend="cpu", max_bounces=bounces, seed=1).image
    job = {"model": os.path.abspath(model), "position": list(cam.position),
           "look_at": list(cam.look_at), "fov": float(cam.fov), "resolution": list(res),
           "spp": spp, "bounces": bounces}
    return image, job


def blender(job, python):
    """Cycles' linear image for ``job`` (a subprocess in Blender's Python)."""
    from pathtracer.film import read_raw
    with tempfile.TemporaryDirectory() as tmp:
        job_path = os.path.join(tmp, "job.json")
        out = os.path.join(tmp, "cycles.exr")
        with open(job_path, "w") as f:
            json.dump(job, f)
        r = subprocess.run([python, "-c", WORKER, job_path, out], capture_output=True,
                           text=True, timeout=1800)
        if r.returncode != 0 or not os.path.exists(out):
            raise RuntimeError((r.stderr or r.stdout)[-800:])
        return read_raw(out)[0][..., :3].astype(np.float64)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("models", nargs="+")
    p.add_argument("--blender", required=True, help="a Python with bpy (Blender as a module)")
    p.add_argument("--width", type=int, default=96)
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--bounces", type=int, default=8)
    p.add_argument("--json")
    args = p.parse_args(argv)
    rows = []
    for model in args.models:
        name = os.path.basename(model)
        try:
            img, job = ours(model, args.width, args.spp, args.bounces)
            ref = blender(job, args.blender)
        except Exception as e:           # one model's failure is a row, not the end
            print(f"{name}: failed: {str(e).splitlines()[-1] if str(e) else e!r}", flush=True)
            rows.append({"model": name, "error": str(e)[-400:]})
            continue
        ours_mean = img.reshape(-1, 3).mean(0)
        ref_mean = ref.reshape(-1, 3).mean(0)
        ratio = ours_mean / np.maximum(ref_mean, 1e-9)
        # the model's own pixels: where either image is not the white sky seen directly
        fg = (np.abs(ref - 1.0).max(-1) > 1e-3) | (np.abs(img - 1.0).max(-1) > 1e-3)
        fg_ratio = (img[fg].mean(0) / np.maximum(ref[fg].mean(0), 1e-9)) if fg.any() else \
            np.full(3, np.nan)
        print(f"{name}: means ours {np.round(ours_mean, 4).tolist()} Blender "
              f"{np.round(ref_mean, 4).tolist()} ratio {np.round(ratio, 3).tolist()}; "
              f"the model's pixels ({100 * fg.mean():.0f} %) {np.round(fg_ratio, 3).tolist()}",
              flush=True)
        rows.append({"model": name, "ours": ours_mean.tolist(), "blender": ref_mean.tolist(),
                     "ratio": ratio.tolist(), "model_pixels": float(fg.mean()),
                     "model_ratio": fg_ratio.tolist(), "camera": job})
    if args.json:
        write_record(args.json, rows=rows, spp=args.spp, width=args.width)
    return 0


if __name__ == "__main__":
    sys.exit(main())
