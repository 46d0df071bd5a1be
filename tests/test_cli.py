"""The pt-render command: outputs, formats, progressive writes, --time, --reference, Ctrl-C."""
import csv
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from pathtracer.film import read_image, write_image
from tests.conftest import ROOT
from tests.helpers import furnace_scene, write_scene


def pt_render(*args, **kw):
    return subprocess.run([sys.executable, "-m", "pathtracer", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, **kw)


@pytest.fixture
def small_scene(tmp_path):
    return write_scene(tmp_path, furnace_scene(0.5, 0.5, 3, res=(16, 12)))


def test_png_with_float_image_beside(tmp_path, small_scene):
    out = tmp_path / "img.png"
    r = pt_render(small_scene, "-o", out, "--spp", 8, "--backend", "cpu", "--quiet")
    assert r.returncode == 0, r.stderr
    assert out.exists() and (tmp_path / "img.exr").exists()
    img = read_image(str(tmp_path / "img.exr"))
    assert img.shape == (12, 16, 3)
    assert abs(img.mean() - 0.5 * 1.875) < 0.05
    png = read_image(str(out))     # sRGB-decoded 8-bit: close to the clamped float image
    assert np.abs(png - np.clip(img, 0, 1)).max() < 0.01


@pytest.mark.parametrize("ext", [".hdr", ".exr", ".npy"])
def test_float_formats_and_overrides(tmp_path, small_scene, ext):
    out = tmp_path / ("img" + ext)
    r = pt_render(small_scene, "-o", out, "--spp", 4, "--resolution", "8x6", "--seed", 3,
                  "--max-bounces", 0, "--quiet")
    assert r.returncode == 0, r.stderr
    img = read_image(str(out))
    assert img.shape == (6, 8, 3)
    # max bounces 0: only the emission (0.5) is seen; .hdr keeps ~1% precision (RGBE).
    assert np.allclose(img, 0.5, rtol=0.01)


def test_same_seed_same_image(tmp_path, small_scene):
    a, b, c = (tmp_path / n for n in ("a.npy", "b.npy", "c.npy"))
    for out, seed in ((a, 5), (b, 5), (c, 6)):
        assert pt_render(small_scene, "-o", out, "--spp", 4, "--seed", seed,
                         "--quiet").returncode == 0
    assert np.array_equal(np.load(a), np.load(b))
    assert not np.array_equal(np.load(a), np.load(c))


def test_reference_table_and_csv(tmp_path, small_scene):
    ref = tmp_path / "ref.npy"
    np.save(ref, np.full((12, 16, 3), 0.5 * 1.875, np.float32))
    out = tmp_path / "img.png"
    r = pt_render(small_scene, "-o", out, "--spp", 16, "--reference", ref, "--quiet")
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "img.relmse.csv")))
    assert rows and int(rows[-1]["spp"]) == 16
    errs = [float(x["relmse"]) for x in rows]
    assert errs[-1] < errs[0]          # error falls as samples accumulate
    assert "relMSE" in r.stderr


def test_time_limit(tmp_path, small_scene):
    out = tmp_path / "img.npy"
    t0 = time.time()
    r = pt_render(small_scene, "-o", out, "--time", 2, "--quiet")
    assert r.returncode == 0, r.stderr
    assert time.time() - t0 < 60
    assert out.exists()


def test_bad_arguments_exit_2(tmp_path, small_scene):
    assert pt_render(small_scene, "-o", tmp_path / "x.gif").returncode == 2
    assert pt_render(small_scene, "--resolution", "12").returncode == 2
    assert pt_render(tmp_path / "missing.json").returncode == 2
    r = pt_render(small_scene, "--reference", tmp_path / "nope.npy", "-o", tmp_path / "a.png")
    assert r.returncode == 2 and "nope.npy" in r.stderr


def test_ctrl_c_keeps_the_image(tmp_path):
    scene = write_scene(tmp_path, furnace_scene(0.5, 0.5, 8, res=(64, 64)))
    out = tmp_path / "img.npy"
    p = subprocess.Popen([sys.executable, "-m", "pathtracer", scene, "-o", str(out),
                          "--spp", "1000000", "--quiet"], cwd=ROOT, stderr=subprocess.PIPE,
                         text=True)
    # Wait until rendering has started (the first image appears after ~1 s of rendering).
    deadline = time.time() + 120
    while not out.exists() and time.time() < deadline:
        time.sleep(0.2)
    assert out.exists(), "no progressive image written"
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert "interrupted" in err
    img = np.load(out)
    assert img.shape == (64, 64, 3) and np.isfinite(img).all() and img.mean() > 0.5


def test_atomic_write_never_partial(tmp_path):
    """A reader polling the file while it is rewritten always gets a whole image."""
    path = str(tmp_path / "x.png")
    a = np.random.default_rng(0).random((64, 64, 3)).astype(np.float32)
    for k in range(20):
        write_image(path, a * (k % 2))
        assert read_image(path).shape == (64, 64, 3)
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".tmp")]


@pytest.mark.skipif(not os.path.isdir(os.path.join(os.path.dirname(ROOT), "shared")) and
                    not os.environ.get("PT_RENDER_SHARED"), reason="needs ../shared")
def test_thesis_folder_missing_files_and_allow_missing(tmp_path):
    from tests.conftest import SHARED
    folder = os.path.join(SHARED, "assets", "seed-scenes", "ClockCC0")
    r = pt_render(folder, "-o", tmp_path / "c.png", "--quiet")
    assert r.returncode == 2
    assert "plant.obj" in r.stderr and "hdri.hdr" in r.stderr and "--allow-missing" in r.stderr
    r = pt_render(folder, "-o", tmp_path / "c.png", "--quiet", "--allow-missing",
                  "--resolution", "32x18", "--spp", "1", "--backend", "cpu")
    assert r.returncode == 0, r.stderr
    assert "warning" in r.stderr and (tmp_path / "c.png").exists()


def test_sampler_option(tmp_path, small_scene):
    """--sampler overrides render.sampler: both render, differently, and agree in the mean;
    a bad name is a one-line error."""
    imgs = {}
    for sampler in ("sobol", "independent"):
        out = tmp_path / f"{sampler}.npy"
        r = pt_render(small_scene, "-o", out, "--spp", 16, "--sampler", sampler, "--quiet")
        assert r.returncode == 0, r.stderr
        assert ("sobol" in r.stderr.split("features")[1]) == (sampler == "sobol")
        imgs[sampler] = np.load(out)
    assert not np.array_equal(imgs["sobol"], imgs["independent"])
    assert abs(imgs["sobol"].mean() - imgs["independent"].mean()) < 0.02
    r = pt_render(small_scene, "--sampler", "halton")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


def test_light_sampler_option(tmp_path, small_scene):
    """--light-sampler overrides render.lightSampler (the furnace's 288 emitting triangles
    pick the tree by default); both agree in the mean."""
    means = {}
    for choice in (None, "power"):
        out = tmp_path / f"{choice}.npy"
        extra = () if choice is None else ("--light-sampler", choice)
        r = pt_render(small_scene, "-o", out, "--spp", 16, "--quiet", *extra)
        assert r.returncode == 0, r.stderr
        assert ("light_tree" in r.stderr.split("features")[1]) == (choice is None), r.stderr
        means[choice] = np.load(out).mean()
    assert abs(means[None] - means["power"]) < 0.02
    r = pt_render(small_scene, "--light-sampler", "bvh")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1


def test_adaptive_option(tmp_path, small_scene):
    out = tmp_path / "a.npy"
    r = pt_render(small_scene, "-o", out, "--spp", 64, "--adaptive", "1e-2", "--quiet")
    assert r.returncode == 0, r.stderr
    assert "adaptive:" in r.stderr and np.isfinite(np.load(out)).all()
    for bad in ("0", "2", "nan", "x"):
        r = pt_render(small_scene, "--adaptive", bad)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, bad
