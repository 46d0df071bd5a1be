"""Bad input and faults: a clear one-line error or a finite image, never a traceback, and
nothing lost (pathtracer.errors lists the exit codes).

- A property-based fuzz test (Hypothesis) mutates valid scenes (types, ranges, missing and
  extra keys, NaN / 1e39 / huge integers, broken references) and runs the command on each:
  exit 0 with a finite image, or exit 2 with one error line.
- Fault tests: a damaged, unwritable or full kernel cache; failing periodic and final
  saves; SIGTERM / SIGHUP / SIGINT (also during compilation); a full disk.
"""
import copy
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from pathtracer import cli
from pathtracer.errors import EXIT_INPUT, EXIT_IO
from pathtracer.film import read_image
from tests.conftest import ROOT
from tests.helpers import furnace_scene, write_scene

ASSETS = os.path.join(ROOT, "scenes", "assets")

QUAD = "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n" \
       "f 1/1 3/3 2/2\nf 1/1 4/4 3/3\n"

VALID = {
    "camera": {"resolution": [8, 6], "position": [0, 1, 4], "lookAt": [0, 0.5, 0], "fov": 50,
               "aperture": 8, "focusDistance": 4},
    "render": {"spp": 2, "maxBounces": 3, "rrDepth": 2, "seed": 1},
    "materials": [
        {"name": "floor", "albedo": {"texture": "checker.png", "tile": [2, 2], "scale": 0.8},
         "roughness": 0.4, "normalMap": "normal.png"},
        {"name": "glass", "transmission": 1, "eta": 1.5, "roughness": 0.1},
        {"name": "lamp", "type": "diffuse", "albedo": 0, "emission": [4, 4, 3]}],
    "objects": [
        {"name": "floor", "file": "quad.obj", "material": "floor",
         "transform": {"scale": 2}},
        {"name": "ball", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
         "faces": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], "material": "glass",
         "smooth": True},
        {"name": "lamp", "vertices": [[-0.5, 2, -0.5], [0.5, 2, -0.5], [0.5, 2, 0.5]],
         "faces": [[0, 1, 2]], "material": "lamp"}],
    "lights": [{"type": "point", "position": [1, 2, 1], "intensity": 3}],
    "environment": {"file": "sky.hdr", "intensity": 0.5, "rotation": 30},
}


def _scene_folder(tmp_path):
    shutil.copy(os.path.join(ASSETS, "checker.png"), tmp_path / "checker.png")
    shutil.copy(os.path.join(ASSETS, "factory_wall_nor_gl_256.png"), tmp_path / "normal.png")
    shutil.copy(os.path.join(ASSETS, "studio_small_03_256.hdr"), tmp_path / "sky.hdr")
    (tmp_path / "quad.obj").write_text(QUAD)


def run_cli(args, capsys):
    """The command in-process: (exit code, stderr lines)."""
    try:
        rc = cli.main([str(a) for a in args])
    except SystemExit as e:      # argparse
        rc = e.code
    err = capsys.readouterr().err
    return rc, err


def assert_one_line_error(rc, err, code=EXIT_INPUT):
    assert "Traceback" not in err, err
    assert rc == code, err
    errors = [line for line in err.splitlines() if line.startswith("pt-render: error:")]
    assert len(errors) == 1, err
    assert not [line for line in err.splitlines()
                if line.strip() and not line.startswith("pt-render:")], err


# ---------------------------------------------------------------------------------------
# Fuzz: mutated valid scenes

BAD_VALUES = [None, True, False, -1, 0, 0.5, 1e39, -1e39, 1e300, 2 ** 64, 2 ** 31, -2 ** 63,
              float("nan"), float("inf"), "", "x", "missing.png", [], [1], [1, 2, 3],
              [1e39, 0, 0], [-1, -1, -1], {}, {"texture": "missing.png"},
              {"texture": "checker.png", "scale": -1}, {"unknown": 1}]


def _paths(node, prefix=()):
    """Every key path of a JSON value."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out.extend(_paths(v, prefix + (k,)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append(prefix + (i,))
            out.extend(_paths(v, prefix + (i,)))
    return out


ALL_PATHS = _paths(VALID)


@st.composite
def mutated_scenes(draw):
    scene = copy.deepcopy(VALID)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(ALL_PATHS))
        parent = scene
        try:
            for k in path[:-1]:
                parent = parent[k]
            key = path[-1]
            parent[key]      # the path may be gone after an earlier mutation
        except (KeyError, IndexError, TypeError):
            continue
        action = draw(st.sampled_from(["delete", "value", "value", "value", "extra", "number"]))
        if action == "delete":
            del parent[key]
        elif action == "extra" and isinstance(parent[key], dict):
            parent[key]["notAKey"] = 1
        elif action == "number":
            parent[key] = draw(st.one_of(
                st.floats(allow_nan=True, allow_infinity=True),
                st.integers(-2 ** 70, 2 ** 70)))
        else:
            parent[key] = copy.deepcopy(draw(st.sampled_from(BAD_VALUES)))
    return scene


@pytest.mark.filterwarnings("ignore")
@settings(max_examples=int(os.environ.get("PT_FUZZ_EXAMPLES", "150")), deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                 HealthCheck.too_slow],
          derandomize=not os.environ.get("PT_FUZZ_RANDOM"))
@given(scene=mutated_scenes())
def test_fuzzed_scene_gives_finite_image_or_one_line_error(tmp_path, capsys, scene):
    if not (tmp_path / "quad.obj").exists():
        _scene_folder(tmp_path)
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))     # NaN / Infinity written as JS tokens: refused
    out = tmp_path / "out.npy"
    if out.exists():
        out.unlink()
    rc, err = run_cli([path, "--backend", "python", "--spp", 1, "--resolution", "4x3",
                       "--max-bounces", 2, "--quiet", "-o", out], capsys)
    assert "Traceback" not in err, err
    assert rc in (0, EXIT_INPUT), err
    if rc == 0:
        img = np.load(out)
        assert img.shape == (3, 4, 3) and np.isfinite(img).all(), err
        assert "NaN or infinite" not in err, err
    else:
        assert_one_line_error(rc, err)


def test_fuzz_base_scene_is_valid(tmp_path, capsys):
    """The fuzz test's starting point renders (so its mutations test something)."""
    _scene_folder(tmp_path)
    path = write_scene(tmp_path, VALID)
    rc, err = run_cli([path, "--backend", "python", "--spp", 1, "--resolution", "4x3",
                       "--quiet", "-o", tmp_path / "o.npy"], capsys)
    assert rc == 0, err
    assert np.load(tmp_path / "o.npy").max() > 0


# ---------------------------------------------------------------------------------------
# Each class of bad input, by example

def _bad(scene_edit):
    s = copy.deepcopy(VALID)
    scene_edit(s)
    return s


FLOAT32_CASES = [
    ("emission 1e39", lambda s: s["materials"][2].update(emission=[1e39, 1, 1]),
     "/materials/2/emission"),
    ("emission above the radiance bound", lambda s: s["materials"][2].update(emission=1e30),
     "/materials/2/emission"),
    ("light 1e39", lambda s: s["lights"][0].update(intensity=1e39), "/lights/0/intensity"),
    ("env intensity", lambda s: s["environment"].update(intensity=1e39),
     "/environment/intensity"),
    ("env map x intensity", lambda s: s["environment"].update(intensity=1e15),
     "/environment/file"),
    ("texture scale negative", lambda s: s["materials"][0]["albedo"].update(scale=-1),
     "/materials/0/albedo/scale"),
    ("texture tile 1e30", lambda s: s["materials"][0]["albedo"].update(tile=[1e30, 1]),
     "/materials/0/albedo/tile/0"),
    ("camera 1e39", lambda s: s["camera"].update(position=[0, 1, 1e39]), "/camera/position"),
    ("tiny focal length", lambda s: (s["camera"].pop("fov"),
                                     s["camera"].update(focalLength=1e-12)),
     "/camera/focalLength"),
    ("focus 1e39", lambda s: s["camera"].update(focusDistance=1e39),
     "/camera/focusDistance"),
    ("spp 2^40", lambda s: s["render"].update(spp=2 ** 40), "/render/spp"),
    ("face index 2^63", lambda s: s["objects"][1]["faces"][0].__setitem__(0, 2 ** 63),
     "/objects/1/faces/0/0"),
    ("resolution 1e20", lambda s: s["camera"].update(resolution=[1e20, 2]),
     "/camera/resolution/0"),
    ("normal map without UVs", lambda s: s["objects"][1].update(material="floor"),
     "/objects/1"),
]


@pytest.mark.parametrize("name,edit,pointer", FLOAT32_CASES, ids=[c[0] for c in FLOAT32_CASES])
def test_bad_values_are_one_line_errors_naming_the_key(tmp_path, capsys, name, edit, pointer):
    _scene_folder(tmp_path)
    path = write_scene(tmp_path, _bad(edit))
    rc, err = run_cli([path, "--backend", "python", "--spp", 1, "--resolution", "4x3",
                       "--quiet", "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert f": {pointer}" in err


@pytest.mark.parametrize("mtl,key", [("Kd nan 0 0", "Kd"), ("Kd -1 0 0", "Kd"),
                                     ("Ni -1.5", "Ni"), ("Ke 1e39 0 0", "Ke"),
                                     ("Pr 5", "Pr"), ("Ns nan", "Ns")])
def test_mtl_values_are_checked(tmp_path, capsys, mtl, key):
    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl red\n"
                                    "f 1 2 3\n")
    (tmp_path / "m.mtl").write_text(f"newmtl red\nKs 0.5 0.5 0.5\n{mtl}\n")
    scene = {"camera": {"resolution": [4, 3]},
             "objects": [{"name": "m", "file": "m.obj"}]}
    rc, err = run_cli([write_scene(tmp_path, scene), "--backend", "python", "--quiet",
                       "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert f"{key} must be within" in err and "'red'" in err


@pytest.mark.parametrize("obj,message", [
    ("v 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n", "too few numbers"),
    ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2\n", "fewer than 3 vertices"),
    ("v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nf 1/1 2/2 3/3\n", "out of range"),
    ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 0 1 2\n", "out of range"),
    ("v 0 0 zz\nf 1 2 3\n", "line 1: a vertex line with something other than numbers"),
])
def test_obj_problems_are_named(tmp_path, capsys, obj, message):
    (tmp_path / "m.obj").write_text(obj)
    scene = {"camera": {"resolution": [4, 3]}, "objects": [{"name": "m", "file": "m.obj"}]}
    rc, err = run_cli([write_scene(tmp_path, scene), "--backend", "python", "--quiet",
                       "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert message in err and "m.obj" in err


def test_obj_with_and_without_uvs_per_material_keeps_uvs(tmp_path):
    """Faces of one material with vt and of another without: the first keep their UVs."""
    from pathtracer.scene.meshes import load_obj
    (tmp_path / "m.mtl").write_text("newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n")
    (tmp_path / "m.obj").write_text(
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\n"
        "usemtl a\nf 1/1 2/2 3/3\nusemtl b\nf 1 3 4\n")
    mesh = load_obj(str(tmp_path / "m.obj"), use_cache=False)
    assert mesh.uvs is not None
    a = [i for i, m in enumerate(mesh.materials) if m["name"] == "a"][0]
    assert np.allclose(mesh.uvs[mesh.face_material == a][0], [[0, 0], [1, 0], [1, 1]])


@pytest.mark.parametrize("args,flag", [
    (["--seed", 2 ** 40], "--seed"), (["--seed", 2 ** 64], "--seed"), (["--seed", "abc"], "--seed"),
    (["--time", "inf"], "--time"), (["--time", "nan"], "--time"), (["--spp", 2 ** 63], "--spp"),
    (["--max-bounces", 2 ** 31], "--max-bounces"),
    (["--resolution", "100000x100000"], "--resolution"), (["-o", ""], "--output"),
    (["-o", "/proc/out.png"], "--output"), (["--pixel", "9,9"], "--pixel"),
    (["--reference-csv", "/nonexistent/x.csv", "--reference", "r.npy"], "--reference-csv"),
])
def test_command_line_numbers_and_paths_are_checked(tmp_path, capsys, args, flag):
    path = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(4, 3)))
    if "-o" not in args:
        args = args + ["-o", tmp_path / "o.npy"]
    rc, err = run_cli([path, "--backend", "python", "--quiet", *args], capsys)
    assert_one_line_error(rc, err)
    assert flag.lstrip("-") in err


def test_film_too_big_for_memory_is_refused_before_allocating(tmp_path, capsys, monkeypatch):
    from pathtracer import memory
    monkeypatch.setattr(memory, "available_bytes", lambda: 2 ** 30)
    path = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(4, 3)))
    rc, err = run_cli([path, "--backend", "python", "--resolution", "8192x8192", "--quiet",
                       "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert "8192x8192" in err and "GiB" in err


@pytest.mark.parametrize("content,name", [
    (b"[" * 100000 + b"]" * 100000, "deep.json"),
    (b'{"camera": \xff\xfe}', "bad-utf8.json"),
    (b"", "empty.json"),
])
def test_unreadable_scene_files(tmp_path, capsys, content, name):
    (tmp_path / name).write_bytes(content)
    rc, err = run_cli([tmp_path / name, "--quiet", "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert name in err


def test_thesis_folder_with_invalid_utf8(tmp_path, capsys):
    (tmp_path / "Objects").mkdir()
    (tmp_path / "scene.json").write_bytes(b'{camera: \xff}')
    rc, err = run_cli([tmp_path, "--quiet", "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert "UTF-8" in err


@pytest.mark.parametrize("content", [b"garbage", b"\x93NUMPYxx", b"\x89PNG\r\n\x1a\nxx"])
def test_damaged_reference_image(tmp_path, capsys, content):
    path = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(4, 3)))
    ref = tmp_path / ("ref.npy" if b"NUMPY" in content else "ref.png")
    ref.write_bytes(content)
    rc, err = run_cli([path, "--backend", "python", "--quiet", "--reference", ref,
                       "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert "--reference" in err


# ---------------------------------------------------------------------------------------
# Faults while writing

def test_failing_periodic_save_warns_and_the_final_save_succeeds(tmp_path, capsys,
                                                                 monkeypatch):
    from pathtracer import film
    calls = []
    real = film.write_images

    def flaky(paths, image, display=None):
        calls.append(paths)
        if len(calls) == 1:      # the first save is a periodic one (at >= 1 s of 2.5)
            raise OSError(28, "No space left on device")
        return real(paths, image, display)

    monkeypatch.setattr(cli, "write_images", flaky)
    path = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(8, 6)))
    rc, err = run_cli([path, "--backend", "python", "--time", 2.5, "--quiet",
                       "-o", tmp_path / "o.png"], capsys)
    assert rc == 0, err
    assert len(calls) >= 2 and "No space left on device" in err and "retries" in err
    assert (tmp_path / "o.png").exists() and (tmp_path / "o.exr").exists()


def test_failing_final_save_falls_back_and_says_where(tmp_path, capsys, monkeypatch):
    from pathtracer import film
    real = film.write_images
    target = str(tmp_path / "out")

    def refuse_target(paths, image, display=None):
        if any(os.path.abspath(p).startswith(target) for p in paths):
            raise OSError(30, "Read-only file system")
        return real(paths, image, display)

    monkeypatch.setattr(cli, "write_images", refuse_target)
    (tmp_path / "out").mkdir()
    path = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(8, 6)))
    rc, err = run_cli([path, "--backend", "python", "--spp", 2, "--quiet",
                       "-o", tmp_path / "out" / "img.png"], capsys)
    assert_one_line_error(rc, err, EXIT_IO)
    saved = err.split("saved to ")[1].split(" instead")[0].split(" and ")
    assert len(saved) == 2 and all(os.path.exists(p) for p in saved), err
    assert np.isfinite(read_image(saved[1])).all()
    for p in saved:
        os.unlink(p)


def pt_render(*args, preexec=None, **kw):
    return subprocess.run([sys.executable, "-m", "pathtracer", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, preexec_fn=preexec, **kw)


def _file_size_limit(nbytes):
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)    # a write fails (EFBIG) instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))
    return limit


def test_disk_full_at_the_final_save(tmp_path):
    """Every write fails past 2 kB (the output, the fallback folders, the kernel cache):
    one line, exit 3, no traceback."""
    path = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(32, 24)))
    r = pt_render(path, "--backend", "cpu", "--spp", 2, "--quiet", "-o", tmp_path / "o.exr",
                  preexec=_file_size_limit(2048))
    assert "Traceback" not in r.stderr, r.stderr
    assert r.returncode == EXIT_IO, r.stderr
    assert "cannot write" in r.stderr and "o.exr" in r.stderr


# ---------------------------------------------------------------------------------------
# Signals

@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_save_the_image(tmp_path, sig):
    scene = write_scene(tmp_path, furnace_scene(0.5, 0.5, 8, res=(64, 64)))
    out = tmp_path / "img.npy"
    p = subprocess.Popen([sys.executable, "-m", "pathtracer", scene, "-o", str(out),
                          "--spp", "1000000", "--quiet", "--backend", "cpu"], cwd=ROOT,
                         stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not out.exists() and time.time() < deadline:
        time.sleep(0.2)
    assert out.exists(), "no progressive image written"
    first = os.stat(out).st_mtime_ns
    time.sleep(0.5)
    p.send_signal(sig)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 128 + sig, err
    assert signal.Signals(sig).name in err and "Traceback" not in err
    assert os.stat(out).st_mtime_ns > first      # saved at the stop, not only before
    img = np.load(out)
    assert img.shape == (64, 64, 3) and np.isfinite(img).all() and img.mean() > 0.5


def test_ctrl_c_during_compilation_is_one_line(tmp_path):
    """With an empty kernel cache the first seconds are compilation."""
    scene = write_scene(tmp_path, furnace_scene(0.5, 0.5, 2, res=(8, 8)))
    env = dict(os.environ, PT_RENDER_CACHE=str(tmp_path / "cache"))
    p = subprocess.Popen([sys.executable, "-m", "pathtracer", scene, "-o",
                          str(tmp_path / "o.npy"), "--backend", "cpu"], cwd=ROOT, env=env,
                         stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    err_lines = []
    while time.time() < deadline:    # wait for "compiling kernels"
        line = p.stderr.readline()
        err_lines.append(line)
        if "compiling" in line or not line:
            break
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    err = "".join(err_lines) + err
    assert p.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    assert not (tmp_path / "o.npy").exists()


# ---------------------------------------------------------------------------------------
# The kernel cache

PROBE = textwrap.dedent("""
    import sys
    import pathtracer                      # configures the cache and its guards
    from pathtracer._cache import jit_cache
    from numba import njit
    sys.path.insert(0, sys.argv[1])
    import probe_mod
    print(probe_mod.run(jit_cache()))
""")
PROBE_MOD = textwrap.dedent("""
    from numba import njit

    def run(cache):
        @njit(cache=cache)
        def triple_sum(n):
            s = 0
            for i in range(n):
                s += 3 * i
            return s
        return triple_sum(1000)
""")


def _probe(tmp_path, cache, preexec=None):
    mod = tmp_path / "mod"
    mod.mkdir(exist_ok=True)
    (mod / "probe_mod.py").write_text(PROBE_MOD)
    env = dict(os.environ, PT_RENDER_CACHE=str(cache), PYTHONPATH=ROOT)
    env.pop("NUMBA_CACHE_DIR", None)
    return subprocess.run([sys.executable, "-c", PROBE, str(mod)], capture_output=True,
                          text=True, env=env, preexec_fn=preexec, cwd=str(tmp_path))


def _cache_files(root, ext):
    return [os.path.join(d, f) for d, _, fs in os.walk(root) for f in fs if f.endswith(ext)]


@pytest.mark.parametrize("damage", ["garbage index", "truncated binary", "garbage binary"])
def test_damaged_kernel_cache_is_rebuilt_with_a_warning(tmp_path, damage):
    cache = tmp_path / "cache"
    r = _probe(tmp_path, cache)
    assert r.returncode == 0 and r.stdout.strip() == str(3 * 999 * 1000 // 2), r.stderr
    files = _cache_files(cache, ".nbi" if "index" in damage else ".nbc")
    assert files, "nothing was cached"
    for f in files:
        data = open(f, "rb").read()
        open(f, "wb").write(data[:len(data) // 2] if "truncated" in damage else b"garbage" * 9)
    r = _probe(tmp_path, cache)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(3 * 999 * 1000 // 2)
    assert "damaged" in r.stderr and "Traceback" not in r.stderr
    # ... and the next run loads the rebuilt cache silently
    r = _probe(tmp_path, cache)
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr


@pytest.mark.parametrize("kind", ["a file", "unwritable"])
def test_unusable_cache_folder_compiles_uncached_never_in_the_package(tmp_path, kind):
    if kind == "a file":
        cache = tmp_path / "cachefile"
        cache.write_text("x")
    else:
        cache = "/proc/pt-render-cache"      # not writable, even for root
    r = _probe(tmp_path, cache)
    assert r.returncode == 0 and r.stdout.strip() == str(3 * 999 * 1000 // 2), r.stderr
    assert "not usable" in r.stderr and "Traceback" not in r.stderr
    for where in (tmp_path / "mod", os.path.join(ROOT, "pathtracer")):
        assert not _cache_files(where, ".nbi"), f"numba cached into {where}"


def test_full_disk_while_writing_the_cache_still_runs(tmp_path):
    r = _probe(tmp_path, tmp_path / "cache", preexec=_file_size_limit(64))
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == str(3 * 999 * 1000 // 2)
    assert "could not write the kernel cache" in r.stderr and "Traceback" not in r.stderr


RACER = textwrap.dedent("""
    import os, sys, time
    import pathtracer                      # configures the cache and its guards
    from numba import njit
    from numba.core import caching
    k, folder, delay = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
    if delay:
        # widen Numba's window between reading a function's index and writing it back, so
        # that the processes' saves overlap for certain
        read_index = caching.IndexDataCacheFile._load_index
        def slow_read_index(self):
            index = read_index(self)
            time.sleep(delay)
            return index
        caching.IndexDataCacheFile._load_index = slow_read_index
    sys.path.insert(0, folder)
    import racer_mod
    f = racer_mod.make(k)
    if delay:                              # start together
        open(os.path.join(folder, f"ready-{k}"), "w").close()
        while not os.path.exists(os.path.join(folder, "go")):
            time.sleep(0.01)
    value = f()
    print(value, sum(f.stats.cache_hits.values()))
""")
RACER_MOD = textwrap.dedent("""
    from numba import njit

    def make(k):
        # one function, a kernel per closure value: the shape of pt-render's kernels, which
        # are closures over the scene's features
        @njit(cache=True)
        def kernel():
            return k * 1000 + 7
        return kernel
""")


def test_concurrent_processes_keep_every_kernel_in_the_cache(tmp_path):
    """Three processes compile three kernels of one cached function at the same moment;
    afterwards each kernel loads from the cache and is its own (Numba alone loses all but
    one of them here, and can hand one scene's kernel to another)."""
    n = 3
    folder = tmp_path / "mod"
    folder.mkdir()
    (folder / "racer_mod.py").write_text(RACER_MOD)
    env = dict(os.environ, PT_RENDER_CACHE=str(tmp_path / "cache"), PYTHONPATH=ROOT)
    env.pop("NUMBA_CACHE_DIR", None)

    def racer(k, delay):
        return subprocess.Popen([sys.executable, "-c", RACER, str(k), str(folder), str(delay)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env, cwd=str(tmp_path))
    procs = [racer(k, 0.5) for k in range(n)]
    deadline = time.time() + 120
    while (not all((folder / f"ready-{k}").exists() for k in range(n))
           and time.time() < deadline and all(p.poll() is None for p in procs)):
        time.sleep(0.01)
    (folder / "go").touch()
    for k, p in enumerate(procs):
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        assert out.split()[0] == str(k * 1000 + 7)
    for k in range(n):                     # one at a time: every kernel is a cache hit
        p = racer(k, 0)
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        assert out.split() == [str(k * 1000 + 7), "1"], f"kernel {k}: {out} {err}"


LOCKER = textwrap.dedent("""
    import os, sys, time
    import pathtracer                      # configures the cache and its guards
    from pathtracer._cache import compile_lock
    folder, role = sys.argv[1], sys.argv[2]
    sys.path.insert(0, folder)
    import racer_mod
    f = racer_mod.make(5)
    t0 = time.monotonic()
    with compile_lock("racer", f):
        if role == "first":                # holds the lock a while, as a long compile does
            open(os.path.join(folder, "holding"), "w").close()
            time.sleep(3.0)
        value = f()
    print(value, sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values()),
          round(time.monotonic() - t0, 2))
""")


def test_a_kernel_another_process_is_compiling_is_waited_for_and_loaded(tmp_path):
    """Two processes need the same new kernel: the second waits on the kernel's compile
    lock (_cache.compile_lock) while the first compiles it, then loads it from the disk
    cache instead of compiling it again (Ray workers on one machine each compiled the
    scene's kernel, 20-40 s of a core apiece)."""
    folder = tmp_path / "mod"
    folder.mkdir()
    (folder / "racer_mod.py").write_text(RACER_MOD)
    env = dict(os.environ, PT_RENDER_CACHE=str(tmp_path / "cache"), PYTHONPATH=ROOT)
    env.pop("NUMBA_CACHE_DIR", None)

    def locker(role):
        return subprocess.Popen([sys.executable, "-c", LOCKER, str(folder), role],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env, cwd=str(tmp_path))
    first = locker("first")
    deadline = time.time() + 120
    while not (folder / "holding").exists() and time.time() < deadline:
        assert first.poll() is None, first.communicate()[1]
        time.sleep(0.01)
    second = locker("second")
    out1, err1 = first.communicate(timeout=120)
    out2, err2 = second.communicate(timeout=120)
    assert first.returncode == 0 and second.returncode == 0, err1 + err2
    value1, hits1, misses1, _ = out1.split()
    value2, hits2, misses2, waited = out2.split()
    assert value1 == value2 == "5007"
    assert (hits1, misses1) == ("0", "1")          # the first compiled it
    assert (hits2, misses2) == ("1", "0"), err2    # the second loaded it
    assert float(waited) > 1.0                     # ... after waiting for the first
    assert "waiting for another process" in err2, err2     # ... and said so
    assert "waiting" not in err1, err1


KERNEL_PROBE = textwrap.dedent("""
    import sys
    import numpy as np
    import pathtracer as pt
    s = 50.0
    for what in sys.argv[1:]:
        scene = {"camera": {"resolution": [6, 4], "position": [0, 0, 3], "lookAt": [0, 0, 0],
                            "up": [0, 1, 0], "fov": 20},
                 "render": {"maxBounces": 1, "spp": 4},
                 "materials": [{"name": "m", "type": "diffuse", "albedo": 0.8}],
                 "objects": [{"name": "plane", "vertices": [[-s, -s, 0], [s, -s, 0], [s, s, 0],
                                                           [-s, s, 0]],
                              "faces": [[0, 1, 2], [0, 2, 3]], "material": "m"}]}
        if what == "sky":
            scene["environment"] = {"color": [0.5, 1.0, 2.0]}
        elif what == "lamp":
            scene["lights"] = [{"type": "point", "position": [0, 0, 1], "intensity": 2.0}]
        else:       # warm-up: another feature set
            scene["camera"].update(aperture=8.0, focusDistance=3.0)
            scene["environment"] = {"color": [1.0, 1.0, 1.0]}
        print(what, repr(float(pt.render(pt.load_scene(scene), backend="cpu").image.mean())))
""")


def test_kernels_compiled_in_different_processes_load_together(tmp_path):
    """Two scenes' CPU kernels, each compiled first thing in its own process (after a
    third process filled the cache with everything else), then loaded from the cache into
    one process: each still renders its own scene (Numba gave both kernels' functions the
    same symbols, and the second scene rendered with the first scene's code, until every
    process numbered its symbols from its own random start: _cache.unique_symbol_names)."""
    env = dict(os.environ, PT_RENDER_CACHE=str(tmp_path / "cache"), PYTHONPATH=ROOT)
    env.pop("NUMBA_CACHE_DIR", None)

    def probe(*what):
        r = subprocess.run([sys.executable, "-c", KERNEL_PROBE, *what], capture_output=True,
                           text=True, env=env, cwd=str(tmp_path), timeout=600)
        assert r.returncode == 0, r.stderr[-3000:]
        return dict(line.split() for line in r.stdout.splitlines())
    probe("warm-up")
    alone = {**probe("sky"), **probe("lamp")}
    assert float(alone["sky"]) > 0 and float(alone["lamp"]) > 0
    assert probe("sky", "lamp") == alone
    assert probe("lamp", "sky") == alone


def test_unsupported_mesh_format_is_an_error(tmp_path, capsys):
    (tmp_path / "m.stl").write_text("solid m\nendsolid m\n")
    scene = {"camera": {"resolution": [4, 3]}, "objects": [{"name": "m", "file": "m.stl"}]}
    rc, err = run_cli([write_scene(tmp_path, scene), "--backend", "python", "--quiet",
                       "-o", tmp_path / "o.npy"], capsys)
    assert_one_line_error(rc, err)
    assert "/objects/0/file" in err and ".stl" in err


def test_mesh_cache_resolves_mtl_textures_per_folder(tmp_path, monkeypatch):
    """The same OBJ + MTL in two folders: each names its own folder's texture (a cache
    keyed by content alone handed the second the first folder's paths)."""
    from pathtracer.scene.meshes import load_obj
    monkeypatch.setenv("PT_RENDER_CACHE", str(tmp_path / "cache"))
    paths = []
    for name in ("a", "b"):
        d = tmp_path / name
        d.mkdir()
        (d / "m.mtl").write_text("newmtl t\nKd 1 1 1\nmap_Kd tex.png\n")
        (d / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\n"
                                 "vt 1 1\nusemtl t\nf 1/1 2/2 3/3\n")
        mesh = load_obj(str(d / "m.obj"))
        paths.append(os.path.join(str(d), mesh.materials[0]["map_Kd"]))
    assert os.path.dirname(paths[0]) == str(tmp_path / "a")
    assert os.path.dirname(paths[1]) == str(tmp_path / "b")


def test_finaliser_errors_after_a_stop_stay_quiet(monkeypatch):
    """A stop signal that cuts an LLVM object's constructor short makes its finaliser fail
    later ('PipelineTuningOptions' has no '_as_parameter_'): after a stop such errors are
    kept quiet (the stop is one line); before one they are shown as usual."""
    import types
    from pathtracer.cli import StopSignals
    shown = []
    monkeypatch.setattr(sys, "unraisablehook", shown.append)
    info = types.SimpleNamespace(exc_value=AttributeError("_as_parameter_"))
    with StopSignals() as signals:
        sys.unraisablehook(info)
        assert len(shown) == 1
        signals.stopping = True
        sys.unraisablehook(info)
        assert len(shown) == 1
    sys.unraisablehook(info)             # still quiet as the process exits after a stop
    assert len(shown) == 1
