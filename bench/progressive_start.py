"""Time to a relMSE in progressive renders through the Python API, as the command renders
(a callback sees every pass), the median over many renders: what the first passes cost.

    python -m bench.progressive_start cornell-box bunny-studio sun [--backend cuda]
        [--renders 15] [--json FILE] [--passes]

Each render is ``bench.run.progressive_curve`` (passes doubling from the API's first pass,
``api.first_pass_spp``) to 256 spp (the sun: 1,024), each pass's image taken in the clock
and its error measured after the render, and ``bench.metrics.time_to_threshold`` reads
the time to each threshold. Seeds 0 .. renders - 1, after a warm-up render. To compare with
another tree, put its folder first on PYTHONPATH (the script prints which ``pathtracer`` it
measured).
"""
import argparse
import json
import statistics

THRESHOLDS = (1e-2, 3e-3, 1e-3)


def measure(name, backend, renders):
    import pathtracer as pt
    from bench.metrics import time_to_threshold
    from bench.run import load_reference, progressive_curve
    from bench.scenes import convergence_scene
    ref, _ = load_reference(name)
    scene = convergence_scene(name)
    pt.render(scene, spp=4, backend=backend)            # warm-up (compile, first launches)
    spp = 1024 if name == "sun" else 256
    times = {th: [] for th in THRESHOLDS}
    first = None
    curves = []
    for seed in range(renders):
        points = progressive_curve(scene, ref, backend, spp, seed=seed)
        curves.append(points)
        first = points[0][1]
        for th in THRESHOLDS:
            times[th].append(time_to_threshold([p[0] for p in points], [p[2] for p in points],
                                               th))
    out = {"scene": name, "first_pass_spp": first, "renders": renders}
    for th, v in times.items():
        if None not in v:
            out[f"median_s_to_{th:g}"] = statistics.median(v)
    # each pass's time and error, medians over the renders (the passes are the same in
    # every render but the last ones, whose sizes may follow the time taken)
    passes = min(len(c) for c in curves)
    out["passes"] = [{"spp": curves[0][k][1],
                      "median_s": statistics.median(c[k][0] for c in curves),
                      "median_relmse": statistics.median(c[k][2] for c in curves)}
                     for k in range(passes) if all(c[k][1] == curves[0][k][1] for c in curves)]
    return out


def main(argv=None):
    from bench.common import command, machine, now, versions
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="+")
    p.add_argument("--backend", default="cuda", choices=("cpu", "cuda"))
    p.add_argument("--renders", type=int, default=15)
    p.add_argument("--json")
    p.add_argument("--passes", action="store_true",
                   help="also print each pass's median time and relMSE (always recorded)")
    args = p.parse_args(argv)
    import pathtracer
    print("pathtracer:", pathtracer.__file__, flush=True)
    record = {"command": command(), "machine": machine(), "date": now(),
              "versions": versions(), "pathtracer": pathtracer.__file__, "results": []}
    for name in args.scenes:
        r = measure(name, args.backend, args.renders)
        record["results"].append(r)
        print(f"{name}: first pass {r['first_pass_spp']} spp, " + ", ".join(
            f"to {th:g} {r[f'median_s_to_{th:g}'] * 1e3:.2f} ms" for th in THRESHOLDS
            if f"median_s_to_{th:g}" in r), flush=True)
        if args.passes:
            print("  passes: " + ", ".join(f"{p['spp']} spp {p['median_s'] * 1e3:.2f} ms "
                                           f"{p['median_relmse']:.2e}" for p in r["passes"]))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(record, f, indent=1)


if __name__ == "__main__":
    main()
