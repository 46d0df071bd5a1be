"""A/B of the headless pass ramp (progressive.render's ``headless``: passes grow 4x while
4x stays under pass_seconds, instead of 2x) on whole renders through the Python API,
both behaviours alternating in one process, the median of 5 after a warm-up of each.

    python -m bench.headless_ramp OUT.json   (needs the CUDA backend)
"""
import json, statistics, sys, time
import pathtracer as pt
from pathtracer import api, progressive
from bench.distributed import load
from bench.common import machine, now
orig = progressive.render
def forced(flag):
    def f(*a, **k):
        k["headless"] = flag
        return orig(*a, **k)
    return f
rec = {"command": "python -m bench.headless_ramp " + sys.argv[1], "machine": machine(), "date": now(), "scenes": {}}
for name, res, spp in (("cornell-box", (1024, 1024), 2048), ("bunny-studio", (1024, 768), 1024), ("cornell-box", (256, 256), 256)):
    scene = load(name, res)
    rows = {"doubling": [], "ramp4": []}
    for label, flag in (("doubling", False), ("ramp4", True)):
        progressive.render = forced(flag); pt.render(scene, spp=spp // 8, backend="cuda")
    for _ in range(5):
        for label, flag in (("doubling", False), ("ramp4", True)):
            progressive.render = forced(flag)
            r = pt.render(scene, spp=spp, backend="cuda")
            rows[label].append((r.stats["paths_per_second"], len(r.passes)))
    key = f"{name} {res[0]}x{res[1]} x {spp}"
    med = {l: statistics.median(p for p, _ in v) for l, v in rows.items()}
    rec["scenes"][key] = {"rows": rows, "median": med, "ratio": med["ramp4"] / med["doubling"]}
    print(key, {l: round(m / 1e6, 1) for l, m in med.items()}, "passes", {l: v[0][1] for l, v in rows.items()}, "ratio", round(med["ramp4"] / med["doubling"], 4), flush=True)
json.dump(rec, open(sys.argv[1], "w"), indent=1)
