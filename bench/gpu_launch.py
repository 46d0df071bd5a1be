"""GPU kernel variants measured side by side: launch geometry, register cap, fast arithmetic.

    python -m bench.gpu_launch [--scenes ...] [--variants base,groups,...] [--json F]

Every variant renders the same scene descriptions (``bench.ab``'s) at the issue's launch
sizes; a figure is the median of ``--repeats`` passes after a warm-up pass (compile time
apart), in camera paths/s. ``registers`` is the pass kernel's count from the CUDA driver.
Optionally Mitsuba 3 (``cuda_ad_rgb``) renders the same scenes at the same sizes and spp in
the same process, for ratios at equal launch sizes.
"""
import argparse
import json
import sys
import time

from bench.ab import _describe

# scene -> [(resolution, spp per pass)]
SIZES = {
    "cornell-box": [((1024, 1024), 64)],
    "bunny-studio": [((256, 192), 64), ((1024, 768), 16)],
    "sun": [((256, 192), 64), ((1024, 768), 16)],
    "textured": [((256, 192), 64), ((1024, 768), 16)],
    # the scaling scene (bench.scenes.mesh_desc: diffuse mesh, constant sky, 3 bounces)
    "bunny-mesh": [((1024, 1024), 16)],
    "dragon-1.6m": [((1024, 1024), 16)],
}
DEFAULT_SCENES = ("cornell-box", "bunny-studio", "sun")

# name -> CUDABackend options
VARIANTS = {
    "pixel-exact": dict(target_threads=1, max_registers=None, fast=False),  # 2026-11-22's
    "groups-exact": dict(max_registers=None, fast=False),
    "groups-r64": dict(fast=False),
    "groups-fast": dict(max_registers=None),
    "default": dict(),              # what ships: the wavefront kernels for scenes with an
    #                                 HDRI, else the megakernel in groups (2^23 threads, 2^21
    #                                 without an environment); 64 registers (56 with an
    #                                 HDRI), approximate arithmetic
    "megakernel": dict(wavefront=False),
    # path regeneration (kernels.integrator.regenerates) forced on / off
    "regen": dict(regenerate=True),                 # 2^21 threads
    "regen-t2^23": dict(regenerate=True, target_threads=1 << 23),
    "nested": dict(regenerate=False),               # 2^23 threads
    "nested-t2^21": dict(regenerate=False, target_threads=1 << 21),
    "r48": dict(max_registers=48),
    "r56": dict(max_registers=56),
    "r64": dict(max_registers=64),
    "r72": dict(max_registers=72),
    "b32x4": dict(block=(32, 4)),
    "b8x8": dict(block=(8, 8)),
    "b16x16": dict(block=(16, 16)),
    "t2^19": dict(target_threads=1 << 19),
    "t2^20": dict(target_threads=1 << 20),
    "t2^21": dict(target_threads=1 << 21),
    "t2^22": dict(target_threads=1 << 22),
    "t2^23": dict(target_threads=1 << 23),
    "t2^24": dict(target_threads=1 << 24),
    # the wavefront kernels (backends.wavefront); t: the queue launches' threads
    "wave": dict(wavefront=True),
    "wave-r48": dict(wavefront=True, max_registers=48),
    "wave-r56": dict(wavefront=True, max_registers=56),
    "wave-r64": dict(wavefront=True, max_registers=64),
    "wave-r96": dict(wavefront=True, max_registers=96),
    "wave-rnone": dict(wavefront=True, max_registers=None),
    "wave-t2^18": dict(wavefront=True, target_threads=1 << 18),
    "wave-t2^19": dict(wavefront=True, target_threads=1 << 19),
    "wave-t2^21": dict(wavefront=True, target_threads=1 << 21),
    # l: vertices launched apart before one launch finishes the paths (all: every vertex)
    "wave-l1": dict(wavefront=dict(wave_levels=1)),
    "wave-l2": dict(wavefront=dict(wave_levels=2)),
    "wave-l3": dict(wavefront=dict(wave_levels=3)),
    "wave-l4": dict(wavefront=dict(wave_levels=4)),
    "wave-all": dict(wavefront=dict(wave_levels=None)),
    # the hit queue sorted by material kind (backends.wavefront's sort_hits, the default
    # since 2026-11-26) or not
    "wave-sort": dict(wavefront=dict(sort_hits=True)),
    "wave-unsorted": dict(wavefront=dict(sort_hits=False)),
}


def time_ours(scene, options, spp, repeats, kernel_times=False):
    from numba import cuda

    from bench.common import median_time
    from pathtracer.backends.cuda import CUDABackend
    b = CUDABackend(scene, **options)
    t0 = time.perf_counter()
    b.compile()
    compile_s = time.perf_counter() - t0
    mb, rr = scene.max_bounces, scene.rr_depth
    start = [0]

    def one():
        b.launch(start[0], spp, 0, mb, rr)
        cuda.synchronize()
        start[0] += spp

    one()
    t, times = median_time(one, repeats)
    extra = {}
    if kernel_times and b.wavefront is not None:
        # one more pass with each launch between CUDA events: GPU seconds per kernel and
        # per vertex, and the queues' lengths (of the pass's last sample range)
        b.wavefront.events = []
        one()
        extra["kernel_s"] = b.wavefront.kernel_times()
        b.wavefront.events = None
        extra["queue_lengths"] = b.wavefront.queue_lengths()
    regs = b.registers()
    if len(regs) == 1:
        regs = list(regs.values())[0]
    return {"pass_s": times, "paths_per_s": scene.width * scene.height * spp / t,
            "compile_s": compile_s, "registers": regs or None, **extra}


def time_mitsuba(name, desc, spp, repeats):
    import mitsuba as mi

    from bench.common import mitsuba_cornell, mitsuba_pass_times
    from pathtracer.mitsuba import mitsuba_dict
    mi.set_variant("cuda_ad_rgb")
    w, h = desc.camera.resolution
    if name == "cornell-box":
        scene = mitsuba_cornell(w, h, spp)
    else:
        scene = mi.load_dict(mitsuba_dict(desc))
    _, t, times = mitsuba_pass_times(scene, spp, repeats)
    return {"pass_s": times, "paths_per_s": w * h * spp / t}


def main(argv=None):
    from bench.common import command, machine, now, versions
    from pathtracer.scene import compile_scene
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", nargs="*", default=list(DEFAULT_SCENES), choices=list(SIZES))
    p.add_argument("--variants", default="pixel-exact,default")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--mitsuba", action="store_true")
    p.add_argument("--sampler", choices=("sobol", "independent"),
                   help="override the scenes' sampler (default: theirs, sobol)")
    p.add_argument("--kernel-times", action="store_true",
                   help="wavefront variants: also GPU time per kernel and vertex (one pass)")
    p.add_argument("--json")
    a = p.parse_args(argv)
    rec = {"command": command(), "machine": machine(), "date": now(), "versions": versions(),
           "results": []}
    for name in a.scenes:
        for res, spp in SIZES[name]:
            desc = _describe(name, res)
            if a.sampler:
                desc.render.sampler = a.sampler
            scene = compile_scene(desc)
            row = {}
            for v in a.variants.split(","):
                got = time_ours(scene, VARIANTS[v], spp, a.repeats, a.kernel_times)
                rec["results"].append(dict(scene=name, resolution=res, spp=spp, variant=v,
                                           **got))
                row[v] = got["paths_per_s"]
                print(f"{name:13s} {res[0]}x{res[1]} x{spp:3d} {v:16s} "
                      f"{got['paths_per_s'] / 1e6:8.1f} M paths/s  regs {got['registers']}  "
                      f"compile {got['compile_s']:.1f} s", flush=True)
                if "kernel_s" in got:
                    print("    GPU ms: " + ", ".join(f"{k} {t * 1e3:.2f}" for k, t in
                                                    got["kernel_s"].items()), flush=True)
            if a.mitsuba:
                try:
                    got = time_mitsuba(name, desc, spp, a.repeats)
                except Exception as e:     # noqa: BLE001  (a scene Mitsuba cannot express)
                    print(f"{name}: Mitsuba: {e}", file=sys.stderr)
                else:
                    rec["results"].append(dict(scene=name, resolution=res, spp=spp,
                                               variant="mitsuba cuda_ad_rgb", **got))
                    print(f"{name:13s} {res[0]}x{res[1]} x{spp:3d} {'Mitsuba':16s} "
                          f"{got['paths_per_s'] / 1e6:8.1f} M paths/s", flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rec, f, indent=1)


if __name__ == "__main__":
    main()
