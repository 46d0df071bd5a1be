"""A/B of the headless pass ramp (progressive.render's ``headless``: passes aimed at
pass_seconds from the last pass's speed since 2026-11-26, 4x growth while 4x stayed under
pass_seconds before; against doubling) on whole renders through the Python API, both
behaviours alternating in one process, the median of 5 after a warm-up of each. (The
label "ramp4" is the headless rule, whichever it is.)

    python -m bench.headless_ramp OUT.json   (needs the CUDA backend)
"""
import json
import statistics
import sys

from bench.common import machine, now
from bench.distributed import load

CASES = (("cornell-box", (1024, 1024), 2048), ("bunny-studio", (1024, 768), 1024),
         ("cornell-box", (256, 256), 256))
REPEATS = 5


def main(out):
    import pathtracer as pt
    from pathtracer import progressive
    original = progressive.render

    def use(headless):
        # api.render imports progressive.render at each call: replace it for the A/B
        def forced(*args, **kwargs):
            kwargs["headless"] = headless
            return original(*args, **kwargs)
        progressive.render = forced

    modes = (("doubling", False), ("ramp4", True))
    record = {"command": "python -m bench.headless_ramp " + out, "machine": machine(),
              "date": now(), "scenes": {}}
    try:
        for name, res, spp in CASES:
            scene = load(name, res)
            rows = {label: [] for label, _ in modes}
            for _, headless in modes:                       # warm-up of each
                use(headless)
                pt.render(scene, spp=spp // 8, backend="cuda")
            for _ in range(REPEATS):
                for label, headless in modes:
                    use(headless)
                    r = pt.render(scene, spp=spp, backend="cuda")
                    rows[label].append((r.stats["paths_per_second"], len(r.passes)))
            med = {label: statistics.median(p for p, _ in v) for label, v in rows.items()}
            key = f"{name} {res[0]}x{res[1]} x {spp}"
            record["scenes"][key] = {"rows": rows, "median": med,
                                     "ratio": med["ramp4"] / med["doubling"]}
            print(key, {label: round(m / 1e6, 1) for label, m in med.items()}, "passes",
                  {label: v[0][1] for label, v in rows.items()}, "ratio",
                  round(med["ramp4"] / med["doubling"], 4), flush=True)
    finally:
        progressive.render = original
    with open(out, "w") as f:
        json.dump(record, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1])
