"""The benchmark's metrics and its quick mode (a tiny run, as CI runs it)."""
import csv
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from bench.metrics import rays_per_second, relmse, time_to_threshold
from tests.conftest import ROOT, needs_shared


def test_relmse():
    ref = np.full((4, 4, 3), 2.0)
    assert relmse(ref, ref) == 0
    img = ref * 1.1          # 10% everywhere: (0.2^2) / (4 + 0.01)
    assert relmse(img, ref) == pytest.approx(0.04 / 4.01)
    # dark pixels are not blown up: eps = 0.01 in the denominator
    assert relmse(np.full((2, 2, 3), 0.1), np.zeros((2, 2, 3))) == pytest.approx(1.0)


def test_time_to_threshold_interpolates_in_log_log():
    t = [1.0, 2.0, 4.0, 8.0]
    e = [1e-1, 5e-2, 2.5e-2, 1.25e-2]            # error = 0.1 / t
    assert time_to_threshold(t, e, 5e-2) == pytest.approx(2.0)
    assert time_to_threshold(t, e, 0.035355) == pytest.approx(2 * math.sqrt(2), rel=1e-4)
    assert time_to_threshold(t, e, 1e-3) is None          # never reached: no extrapolation
    assert time_to_threshold(t, e, 1.0) == 1.0             # reached at the first point
    assert time_to_threshold([1, 2, 3], [0.5, 0.05, 0.2], 0.1) == pytest.approx(
        math.exp(math.log(2) * (math.log(0.1) - math.log(0.5)) / (math.log(0.05) -
                                                                   math.log(0.5))))


def test_sampler_means_carry_their_standard_errors():
    from bench.run import mean_and_error, ratio_error
    m, se = mean_and_error([1.0, 2.0, 3.0, 4.0])
    assert m == 2.5 and se == pytest.approx(np.std([1, 2, 3, 4], ddof=1) / 2)
    assert mean_and_error([5.0]) == (5.0, 0.0)
    # a / b with 10 % and 20 % relative errors: sqrt(0.01 + 0.04) of the ratio
    assert ratio_error(1.0, 0.1, 2.0, 0.4) == pytest.approx(0.5 * math.sqrt(0.05))
    assert ratio_error(0.0, 0.1, 2.0, 0.4) == 0.0


def test_relative_variance_between_seeds():
    from bench.sampler_depth import relative_variances
    rng = np.random.default_rng(1)
    a = 2.0 + rng.normal(0.0, 0.1, (4000, 8, 8, 3))     # mean 2, variance 0.01
    b = 4.0 + rng.normal(0.0, 0.3, (4000, 8, 8, 3))     # mean 4, variance 0.09
    v = relative_variances({"a": a, "b": b})
    # each divided by the pooled mean's square (3^2 + 0.01), not by its own mean's: every
    # sampler's variance over the same image, as relMSE divides by one reference
    assert v["a"] == pytest.approx(0.01 / 9.01, rel=0.03)
    assert v["b"] == pytest.approx(0.09 / 9.01, rel=0.03)


def test_median_curve_takes_each_pass_median_time():
    from bench.run import median_curve
    runs = [[(0.1, 1, 0.5), (0.3, 3, 0.2)], [(0.2, 1, 0.5), (0.9, 3, 0.2)],
            [(0.15, 1, 0.5), (0.4, 3, 0.2)]]
    assert median_curve(runs) == [(0.15, 1, 0.5), (0.4, 3, 0.2)]
    assert median_curve(runs[:1]) == runs[0]
    # runs whose passes differ are not mixed: the first is kept
    assert median_curve([runs[0], [(0.2, 2, 0.4)]]) == runs[0]


def test_rays_per_second_counts_every_ray():
    assert rays_per_second(100, 250, 180, 2.0) == pytest.approx(265.0)
    with pytest.raises(ValueError):
        rays_per_second(1, 1, 1, 0)


def test_counted_rays_match_a_traced_path(tmp_path):
    """The kernels' ray counters: inside a closed diffuse shell with a point light at its
    centre (always visible, never behind the surface) and no Russian roulette, every path
    scatters maxBounces times, tracing one shadow ray and one bounce ray per event."""
    from pathtracer.backends import make_backend
    from pathtracer.scene import load_scene
    from tests.helpers import furnace_scene, write_scene
    d = furnace_scene(0.5, 0.0, 3, res=(4, 4))
    d["lights"] = [{"position": [0, 0, 0], "intensity": 1}]
    d["render"]["rrDepth"] = 100
    s = load_scene(write_scene(tmp_path, d))
    _, stats = make_backend("cpu", s).render_pass(0, 2, 0, 3, 100)
    per_path = stats.reshape(-1, 3).sum(0) / (4 * 4 * 2)
    assert per_path[0] == 3 and per_path[1] == 3, per_path


@needs_shared
def test_quick_mode_writes_csv_plot_and_summary(tmp_path):
    r = subprocess.run([sys.executable, "-m", "bench", "--quick", "--tiny", "--out",
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = list(csv.DictReader(open(tmp_path / "results.csv")))
    sections = {row["section"] for row in rows}
    assert {"convergence", "samplers", "throughput", "filtering", "bvh", "scaling",
            "compile"} <= sections
    assert {row["renderer"] for row in rows if row["section"] == "samplers"} >= {
        "pt-render cpu sobol", "pt-render cpu independent"}
    for row in rows:
        assert row["command"] and row["machine"] and row["date"]
        assert "numba=" in row["versions"]
    from bench.scenes import CONVERGENCE
    assert {row["scene"] for row in rows if row["section"] == "convergence"} == set(CONVERGENCE)
    for png in ("convergence.png", "scaling.png"):
        assert (tmp_path / png).stat().st_size > 1000
    summary = (tmp_path / "summary.md").read_text()
    assert "relMSE" in summary and "paths/s" in summary


def test_replot_reads_the_csv(tmp_path):
    from bench.run import Results, curves_from_csv
    r = Results(str(tmp_path))
    for spp, sec, err in ((1, 0.1, 0.3), (2, 0.2, 0.15)):
        r.add("convergence", "cornell-box", "x", "relMSE", err, "", "spp", spp)
        r.add("convergence", "cornell-box", "x", "seconds", sec, "s", "spp", spp)
    r.write()
    assert curves_from_csv([str(tmp_path / "results.csv")]) == {
        ("cornell-box", "x"): [(0.1, 1, 0.3), (0.2, 2, 0.15)]}


def test_reference_noise_estimate_matches_the_true_error():
    """Two noisy halves of a known image: the estimate (from the halves alone) equals the
    relMSE of their mean against the truth, to sampling precision."""
    from bench.references import reference_noise
    rng = np.random.default_rng(1)
    truth = rng.uniform(0.0, 3.0, (200, 200, 3))
    sigma = 0.02 * (1 + truth)
    a = truth + sigma * rng.standard_normal(truth.shape)
    b = truth + sigma * rng.standard_normal(truth.shape)
    assert reference_noise(a, b) == pytest.approx(relmse((a + b) / 2, truth), rel=0.02)
    assert reference_noise(truth, truth) == 0


def test_growth_exponent_of_a_power_law():
    from bench.scaling import growth_exponent
    n = [1e3, 1e4, 1e5, 1e6]
    assert growth_exponent(n, [2.0 * x ** 0.25 for x in n]) == pytest.approx(0.25)
    assert growth_exponent(n, [7.0] * 4) == pytest.approx(0.0, abs=1e-12)


def test_committed_references_are_converged_and_match_their_scenes():
    """The error-against-time references (bench/references/, made on a GPU): high spp, noise
    far under the thresholds the benchmark reports, the resolution the benchmark renders."""
    from bench.scenes import CONVERGENCE, load_reference
    for name, (_, res) in CONVERGENCE.items():
        if name == "cornell-box":
            continue
        image, meta = load_reference(name)
        assert image.shape == (res[1], res[0], 3) and np.isfinite(image).all()
        assert meta["spp"] >= 16384 and meta["noise_relmse"] < 1e-4, meta
        for key in ("command", "machine", "date"):
            assert meta[key]


def _block_means(x, k=16):
    h, w, c = x.shape
    return x[:h // k * k, :w // k * k].reshape(h // k, k, w // k, k, c).mean((1, 3))


def _reference_mismatch(desc, reference, spp=32):
    """Two independent CPU renders a, c of ``desc`` against a reference, in 16x16-pixel
    block means (so that noise is small): relMSE((a + c) / 2, ref) / relMSE(a, c). If the
    reference is the noise-free image of this scene the ratio is 1/4 (the mean carries half
    the variance of one render, a - c twice it); any difference between the scene and the
    reference's scene adds to the numerator only."""
    from pathtracer.backends import make_backend
    from pathtracer.progressive import render
    from pathtracer.scene import compile_scene
    scene = compile_scene(desc)
    backend = make_backend("cpu", scene)
    a, c = (_block_means(render(scene, backend, spp=spp, seed=s).film.image())
            for s in (11, 12))
    return relmse((a + c) / 2, _block_means(reference)) / relmse(a, c)


@needs_shared
def test_committed_references_are_the_current_scenes():
    """A reference made before a scene was edited would measure error against the wrong
    image: each committed reference must be the limit of its scene as defined now."""
    from bench.scenes import CONVERGENCE, convergence_desc, load_reference
    for name in CONVERGENCE:
        if name == "cornell-box":
            continue
        ratio = _reference_mismatch(convergence_desc(name), load_reference(name)[0])
        assert ratio < 0.4, (name, ratio)
    # the check's power: the bunny 10% rougher is caught
    desc = convergence_desc("bunny-studio")
    desc.materials["bunny"].numbers["roughness"] *= 1.1
    assert _reference_mismatch(desc, load_reference("bunny-studio")[0]) > 0.4


def test_sweep_benchmark_runs_api_and_cli(tmp_path):
    """bench/sweep.py's two ways of ours, tiny: the API re-renders compile nothing and the
    CLI runs render the same number of samples."""
    from bench.sweep import run_api, run_cli
    api = run_api("cpu", 3, 2, 16, 12)
    assert api["compile_later_s"] == 0.0 and len(api["walls_s"]) == 3
    assert 0 <= api["overhead_median_s"] < api["median_s"]
    cli = run_cli("cpu", 3, 2, 16, 12)
    assert len(cli["walls_s"]) == 3 and cli["render_median_s"] >= 0   # (printed to 0.01 s)


def test_cpu_profile_names_and_symbol_table():
    """bench.cpu_profile: the kernel's compiled functions are found with their addresses
    (from a fresh compile's object code), and their mangled names read back short."""
    import json
    import os
    import shutil
    import tempfile
    from bench.cpu_profile import short_name
    assert short_name("_ZN10pathtracer7kernels8traverse11closest_hitB3v78B52c8tJT") == \
        "traverse.closest_hit"
    assert short_name("_ZN10pathtracer7kernels7drivers10megakernel15make_megakernel"
                      "12_3clocals_3e13render_sampleB3v62") == "megakernel.render_sample"
    if shutil.which("nm") is None:
        pytest.skip("needs nm (binutils)")
    with tempfile.TemporaryDirectory() as tmp:
        syms = os.path.join(tmp, "syms.json")
        # (--calls: one step kept as a call, so that it has a symbol of its own)
        env = dict(os.environ, PT_RENDER_CACHE=os.path.join(tmp, "cache"),
                   PT_RENDER_CPU_CALLS="direct_light")
        env.pop("NUMBA_CACHE_DIR", None)
        code = os.path.join(tmp, "code.json")
        r = subprocess.run([sys.executable, "-m", "bench.cpu_profile", "cornell-box", "--child",
                            "--syms", syms, "--code", code, "--seconds", "0.1", "--spp", "1"],
                           cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        rows = json.load(open(syms))
        code_bytes = json.load(open(code))
        rate = json.loads(r.stdout.strip().splitlines()[-1])
    names = {short_name(row[2]) for row in rows}
    # the kernel, and the step kept as a call (everything else is inlined into the kernel;
    # device functions have no machine code of their own: kernels.device)
    assert {"pass_kernel.render_pass", "path.direct_light"} <= names, sorted(names)
    # the machine code of every function, as long as its symbol says
    assert all(len(code_bytes[str(a)]) == 2 * n for a, n, _ in rows)
    assert rate["render_start"] <= rate["render_end"]


def test_cpu_profile_attributes_samples():
    """perf script lines: kernel samples by function and address; the others by library,
    only those taken while rendering."""
    from bench.cpu_profile import attribute
    table = [(0x1000, 0x100, "_ZN10pathtracer7kernels4wide16closest_hit_wideB2v1"),
             (0x2000, 0x80, "_ZN10pathtracer7kernels6envmap6env_uvB2v1")]
    script = "\n".join([
        "   10.500000:     1004 ([JIT] tid 7)",              # before rendering
        "   11.000000:     1004 ([JIT] tid 7)",
        "   11.100000:     1010 ([JIT] tid 7)",
        "   11.200000:     2040 ([JIT] tid 8)",
        "   11.300000: 7f0000001234 (/usr/lib/x86_64-linux-gnu/libm.so.6)",
        "   11.400000:     1100 ([JIT] tid 7)",              # just past closest_hit_wide
        "    9.000000: 7f0000009999 (/usr/lib/libLLVM.so.19)",  # compiling: not rendering
        "garbage"])
    counts, per_ip, libraries, in_window, outside = attribute(script, table, (11.0, 12.0))
    assert counts == {"wide.closest_hit_wide": 3, "envmap.env_uv": 1}
    assert per_ip == {0x1004: 2, 0x1010: 1, 0x2040: 1}
    assert libraries == {"libm.so.6": 1, "[JIT] tid 7": 1}
    assert in_window == 3 and outside == 3


def test_cpu_profile_annotates_instructions(capsys):
    """--annotate: each instruction of the function with its share of the samples."""
    import shutil
    from bench.cpu_profile import annotate
    if shutil.which("objdump") is None:
        pytest.skip("needs objdump (binutils)")
    base = 0x1000
    # nop; nop; mov %rdi,%rax; ret
    annotate(base, bytes.fromhex("90904889f8c3"), {base + 2: 30, base + 5: 10}, 40, 0.1)
    out = capsys.readouterr().out
    assert "4 instructions, 100.0%" in out
    assert " 75.00%       2  mov" in out and " 25.00%       5  ret" in out


def test_watertight_counts_rays_that_slip_through():
    """bench.watertight: rays aimed at a closed sphere's edges from outside, those that
    clearly cross it (not grazing its silhouette: 84 % of those drawn here), and rays aimed
    at a split quad's diagonal; the counts are the cracks of the ray-triangle test. The
    eight-wide tree runs the binary tree's test bit for bit, so both lose the same rays;
    rays aimed at triangle interiors never slip through."""
    from bench.watertight import (CASES, QUAD_CASES, edge_rays, measure, measure_quads,
                                  sphere, trace)
    rec = measure(cases=CASES[:1], rays=20000, seed=3)[0]
    assert 0.6 * rec["rays_drawn"] < rec["rays"] < 0.95 * rec["rays_drawn"]
    assert rec["binary_missed"] == rec["wide_missed"]
    assert rec["binary_unoccluded"] == rec["wide_unoccluded"]
    assert 0 <= rec["binary_missed"] <= rec["rays"]
    for rec in measure_quads(cases=QUAD_CASES[:2], rays=5000, seed=3):
        assert rec["binary_missed"] == rec["wide_missed"] <= rec["rays"]
        assert rec["binary_unoccluded"] == rec["wide_unoccluded"]
    # interiors: the same rays moved to triangle centres hit every time
    v, f, tri_v, bvh = sphere(*CASES[0][:4])
    rng = np.random.default_rng(5)
    centres = v[f].mean(axis=1)
    o, _ = edge_rays(v, f, CASES[0][3], CASES[0][4], 5000, rng)
    target = centres[rng.integers(0, len(f), len(o))]
    d = (target - o).astype(np.float64)
    d = (d / np.linalg.norm(d, axis=1)[:, None]).astype(np.float32)
    tri, occluded = trace("binary", o, d, tri_v, bvh.box, bvh.child)
    assert (tri >= 0).all() and occluded.all()


def test_traversal_rays_in_origin_order_are_the_random_ones_sorted():
    """bench.traversal --order origin traces the rays of the default random order, sorted
    by the triangle they leave (each ray keeping its origin and direction)."""
    from bench.traversal import make_rays
    tri_v = np.random.default_rng(0).random((50, 9)).astype(np.float32)
    o_r, d_r, s_r = make_rays(tri_v, 500, "random")
    o_s, d_s, s_s = make_rays(tri_v, 500, "origin")
    assert (np.diff(s_s) >= 0).all() and not (np.diff(s_r) >= 0).all()

    def rays(o, d, s):
        return sorted(zip(s.tolist(), map(tuple, d.tolist()), map(tuple, o.tolist())))
    assert rays(o_r, d_r, s_r) == rays(o_s, d_s, s_s)
    # every ray starts at the centroid of the triangle it leaves
    v = tri_v[s_s]
    assert np.allclose(o_s, v[:, 0:3] + (v[:, 3:6] + v[:, 6:9]) / 3, atol=1e-6)


def test_traversal_benchmark_on_the_cuda_simulator(tmp_path):
    """bench.traversal --backend cuda (both trees' traversal as CUDA kernels, one ray per
    thread), run on the CUDA simulator: the two trees find the same hits (the rays in
    --order origin)."""
    import json
    import os
    out = tmp_path / "t.json"
    r = subprocess.run([sys.executable, "-m", "bench.traversal", "cornell-box", "--backend",
                        "cuda", "--rays", "300", "--repeats", "1", "--order", "origin",
                        "--json", str(out)],
                       cwd=ROOT, env=dict(os.environ, NUMBA_ENABLE_CUDASIM="1"),
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rec = json.loads(out.read_text())
    assert rec["same_hits"] and rec["backend"] == "cuda" and rec["order"] == "origin"
    assert set(rec["results"]) == {"binary", "wide"}


def test_traversal_benchmark_against_mitsuba(tmp_path):
    """bench.traversal --mitsuba: Mitsuba 3's closest and any hits (Embree) on the same
    rays and triangles beside both of our trees, and its hits agree with ours."""
    import json
    from bench.common import usable_mitsuba
    ok, why = usable_mitsuba("llvm_ad_rgb")
    if not ok:
        pytest.skip(f"Mitsuba not usable here: {why}")
    out = tmp_path / "t.json"
    r = subprocess.run([sys.executable, "-m", "bench.traversal", "cornell-box", "--rays",
                        "3000", "--repeats", "1", "--mitsuba", "--json", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    rec = json.loads(out.read_text())
    assert set(rec["results"]) == {"binary", "wide", "mitsuba"}
    assert rec["results"]["mitsuba"]["closest_hit_rays_per_s"] > 0
    assert rec["same_hits"] and rec["mitsuba_hits_agree"] >= 0.999


def test_throughput_on_the_convergence_scenes_alternates_rounds(monkeypatch):
    """`python -m bench.throughput --cpu --scenes ...`: a figure per round for pt-render,
    at the scene's benchmark size; without a usable Mitsuba the peer's rounds are left
    out, and so is the ratio (never a ratio to nothing). The scene is built and its kernel
    loaded once for all rounds, once per sampler asked for (the first the main figure)."""
    import bench.throughput as tp
    monkeypatch.setattr(tp, "usable_mitsuba", lambda variant: (False, "not here"))
    calls = []
    real_ours = tp.ours

    def ours(*args, **kw):
        calls.append(kw["prepared"])
        return real_ours(*args, **kw)
    monkeypatch.setattr(tp, "ours", ours)
    (rec,) = tp.convergence_scenes(["cornell-box"], spp=1, repeats=1, rounds=2,
                                   samplers=("sobol", "independent"))
    assert rec["scene"] == "cornell-box" and rec["rounds"] == 2
    # round 0: sobol, independent (then Mitsuba); round 1 the other way round
    assert len(calls) == 4 and calls[0] is calls[3] and calls[1] is calls[2]
    assert calls[0][0].features.sobol and not calls[1][0].features.sobol
    scene = calls[0][0]
    assert (scene.width, scene.height) == (256, 256) and rec["resolution"] == [256, 256]
    assert rec["sampler"] == "sobol" and len(rec["pt_render_paths_per_s"]) == 2
    by = rec["pt_render_paths_per_s_by_sampler"]
    assert by["sobol"] == rec["pt_render_paths_per_s"] and len(by["independent"]) == 2
    assert all(x > 0 for x in by["sobol"] + by["independent"])
    assert rec["mitsuba_paths_per_s"] == [] and "ratio_of_medians" not in rec
    assert "ratio_of_medians_by_sampler" not in rec


def test_ab_paired_alternates_live_workers(tmp_path):
    """`python -m bench.ab throughput --paired N --blocks K`: K blocks of fresh workers, one
    live worker per tree in each, their timed passes alternating; the record has N times
    per tree and block, N x K pair ratios, K block ratios whose median is the figure, with
    the bootstrap interval around it (a tree against itself, on a tiny image)."""
    import json
    out = tmp_path / "ab.json"
    r = subprocess.run([sys.executable, "-m", "bench.ab", "throughput", "--trees", ".", ".",
                        "--paired", "3", "--blocks", "2", "--scenes", "cornell-box",
                        "--resolution", "32x24", "--spp", "1", "--json", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    rec = json.loads(out.read_text())
    s = rec["summary"]["cornell-box"]
    assert s["pairs"] == 3 and s["blocks"] == 2 and len(s["pair_ratios"]) == 6
    assert len(s["block_ratios"]) == 2
    assert s["ratio"] == pytest.approx(float(np.median(s["block_ratios"])))
    assert s["ratio_interval_95"][0] <= s["ratio"] <= s["ratio_interval_95"][1]
    assert [len(x["pass_s"]) for x in rec["results"]] == [3, 3, 3, 3]
    assert [x["block"] for x in rec["results"]] == [0, 0, 1, 1]
    assert all(x["resolution"] == [32, 24] and x["spp"] == 1 for x in rec["results"])
    assert "ratio" in r.stdout and "2 blocks of 3 pairs" in r.stdout


def test_throughput_in_processes_takes_the_median_of_processes(monkeypatch, tmp_path):
    """`python -m bench.throughput --cpu --scenes ... --processes K`: the comparison run K
    times as a child command (the same options, without --processes), and per scene and
    sampler the median of the K processes' ratios (children faked here: each writes a
    record with its own ratios)."""
    import json
    import bench.throughput as tp
    calls = []

    def run(cmd):
        calls.append(cmd)
        k = len(calls)
        scenes = [{"scene": "sun", "ratio_of_medians": 0.9 + 0.1 * k,
                   "ratio_of_medians_by_sampler": {"sobol": 0.9 + 0.1 * k,
                                                   "independent": 1.0 + 0.1 * k}}]
        with open(cmd[cmd.index("--json") + 1], "w") as f:
            json.dump({"scenes": scenes}, f)
    monkeypatch.setattr(tp, "_run_child", run)
    out = tmp_path / "rec.json"
    monkeypatch.setattr(sys, "argv", ["throughput", "--cpu", "--scenes", "sun", "--samplers",
                                      "sobol", "independent", "--rounds", "2",
                                      "--processes", "3", "--json", str(out)])
    tp.main()
    assert len(calls) == 3
    assert all("--processes" not in c and c[c.index("--rounds") + 1] == "2" for c in calls)
    assert all(c[c.index("--samplers") + 1:c.index("--samplers") + 3] == ["sobol",
               "independent"] for c in calls)
    rec = json.loads(out.read_text())
    assert len(rec["processes"]) == 3
    s = rec["summary"]["sun"]
    assert s["sobol"]["ratio_per_process"] == pytest.approx([1.0, 1.1, 1.2])
    assert s["sobol"]["median"] == pytest.approx(1.1)
    assert s["independent"]["median"] == pytest.approx(1.2)


def test_throughput_child_that_fails_ends_in_one_line():
    """A child process of --processes that fails (here: an unknown scene) ends the run with
    a message naming its command, not a traceback."""
    import bench.throughput as tp
    with pytest.raises(SystemExit) as e:
        tp._run_child(["--cpu", "--scenes", "nope"])
    assert "child process failed (exit 2)" in str(e.value) and "nope" in str(e.value)


def test_ab_paired_stops_on_a_tree_that_fails(tmp_path):
    """A tree whose worker cannot start (here: no pt-render in it) ends the run with a
    message naming the worker; the other tree's worker is not left behind."""
    r = subprocess.run([sys.executable, "-m", "bench.ab", "throughput", "--trees", ".",
                        str(tmp_path), "--paired", "2", "--scenes", "cornell-box",
                        "--resolution", "16x16", "--spp", "1"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode != 0
    assert "worker ended early" in r.stderr and str(tmp_path) in r.stderr


def test_bootstrap_median_interval():
    from bench.ab import bootstrap_median_interval
    lo, hi = bootstrap_median_interval([1.0] * 10)
    assert lo == hi == 1.0
    v = np.random.default_rng(3).normal(1.0, 0.05, 200)
    lo, hi = bootstrap_median_interval(v)
    assert lo < np.median(v) < hi and hi - lo < 0.05


def test_bench_scripts_refuse_bad_arguments_in_one_line():
    """A malformed size or a tree that is not a folder (a revision's name) for bench.ab, and
    bench.throughput --scenes without --cpu or with an unknown scene, --samplers without
    --scenes or with an unknown sampler, --processes without --scenes, bench.ab's --blocks
    without --paired: argparse's one-line error (exit 2), no traceback."""
    for args in (["bench.ab", "throughput", "--trees", ".", ".", "--resolution", "64"],
                 ["bench.ab", "throughput", "--trees", "HEAD", ".", "--scenes", "sun"],
                 ["bench.ab", "images", "--trees", ".", ".", "--resolution", "0x5"],
                 ["bench.throughput", "--gpu", "--scenes", "sun"],
                 ["bench.throughput", "--cpu", "--scenes", "nope"],
                 ["bench.throughput", "--cpu", "--samplers", "independent"],
                 ["bench.throughput", "--cpu", "--scenes", "sun", "--samplers", "halton"],
                 ["bench.throughput", "--cpu", "--processes", "3"],
                 ["bench.throughput", "--scenes", "sun", "--processes", "3"],
                 ["bench.ab", "throughput", "--trees", ".", ".", "--blocks", "3"],
                 ["bench.denoise_budget", "--first", "3"],
                 ["bench.denoise_budget", "--step", "0"],
                 ["bench.denoise_budget", "--seeds", "0"],
                 ["bench.scene_survey", "/no/such/folder"],
                 ["bench.mitsuba_compare", ".", "--size", "2"]):
        r = subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 2, (args, r.stderr)
        assert "Traceback" not in r.stderr and "error:" in r.stderr, (args, r.stderr)


def test_denoise_budget_spends_the_mean_spp_where_the_halves_disagree():
    """bench.denoise_budget's adaptive split, with a backend that returns known samples
    (every sample 1, but one pixel's first half 100 and its second 0): exactly spp samples
    per pixel on average, all the extra ones in the disagreeing pixel and its 3x3
    neighbours, the other pixels kept at the uniform first samples, and every pixel the
    plain mean of its own samples."""
    from types import SimpleNamespace
    from bench.denoise_budget import adaptive_image, max3x3
    h, w = 6, 8
    noisy = (2, 3)

    class Fake:
        def render_pass(self, start, n, seed, mb, rr, active=None):
            s = np.arange(start, start + n)
            out = np.ones((h, w, 3)) * n
            out[noisy] = 100.0 * (s < 4).sum()
            if active is not None:
                out[active == 0] = 0.0
            return out.astype(np.float32), None
    scene = SimpleNamespace(height=h, width=w, max_bounces=3, rr_depth=5)
    img, count = adaptive_image(Fake(), scene, 0, spp=16, first=8, step=4, power=1.0)
    assert count.sum() == 16 * h * w
    near = np.zeros((h, w), bool)
    near[1:4, 2:5] = True
    assert (count[~near] == 8).all() and (count[near] >= 8 + 4 * 10).all()
    expect = np.ones((h, w))
    expect[noisy] = 400.0 / count[noisy]
    np.testing.assert_allclose(img[..., 0], expect, rtol=1e-6)
    assert (max3x3(np.eye(3)) == 1).all() and max3x3(np.zeros((2, 2))).max() == 0


def test_scene_survey_counts_what_loads_and_groups_what_stops(tmp_path):
    """bench.scene_survey: every <scene> file below the folder loaded; the errors grouped by
    their message; files that are not scenes left out; a JSON record."""
    sensor = ('<sensor type="perspective"><transform name="to_world"><lookat origin="0,0,3" '
              'target="0,0,0" up="0,1,0"/></transform><film type="hdrfilm"><integer '
              'name="width" value="4"/><integer name="height" value="4"/></film></sensor>')
    (tmp_path / "ok.xml").write_text(f'<scene version="3.0.0">{sensor}<shape type="cube"/>'
                                     '</scene>')
    for k in range(2):
        (tmp_path / f"bad{k}.xml").write_text(f'<scene version="3.0.0">{sensor}<shape '
                                              'type="bsplinecurve"/></scene>')
    (tmp_path / "other.xml").write_text("<html/>")
    out = tmp_path / "survey.json"
    r = subprocess.run([sys.executable, "-m", "bench.scene_survey", str(tmp_path), "--json",
                        str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "3 scene files" in r.stdout and "pt-render loads 1" in r.stdout, r.stdout
    assert "   2  shape … is not supported" in r.stdout, r.stdout
    rows = json.load(open(out))["files"]
    assert sorted(os.path.basename(x["file"]) for x in rows) == ["bad0.xml", "bad1.xml",
                                                                 "ok.xml"]
