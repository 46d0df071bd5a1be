"""pt-render --preview: the page, its status and image endpoints over HTTP while a render
runs, and what a browser shows (headless Chromium, where installed)."""
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

from tests.conftest import ROOT
from tests.helpers import write_scene
from tests.test_api import room


def fetch(url, timeout=10):
    with urllib.request.urlopen(url, timeout=timeout) as r:
        return r.status, r.headers.get("Content-Type"), r.read()


def start_preview(tmp_path, *extra):
    scene = room()
    scene["camera"]["resolution"] = [32, 24]
    path = write_scene(tmp_path, scene)
    proc = subprocess.Popen(
        [sys.executable, "-m", "pathtracer", path, "-o", str(tmp_path / "out.png"),
         "--backend", "cpu", "--time", "120", "--spp", "1000000", "--quiet", "--preview",
         "0", *extra], stderr=subprocess.PIPE, text=True, cwd=ROOT)
    lines = []
    deadline = time.time() + 300          # a cold kernel cache compiles first
    while time.time() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if "preview at" in line:
            url = line.split("preview at ")[1].split()[0]
            return proc, url, line
    proc.kill()
    raise AssertionError("no preview address printed:\n" + "".join(lines))


def wait_status(url, predicate, timeout=300):
    deadline = time.time() + timeout
    while time.time() < deadline:
        status = json.loads(fetch(url + "status.json")[2])
        if predicate(status):
            return status
        time.sleep(0.2)
    raise AssertionError(f"status never satisfied the condition: {status}")


def stop(proc):
    proc.send_signal(signal.SIGINT)
    try:
        err = proc.communicate(timeout=60)[1]
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return proc.returncode, err


def test_preview_serves_a_converging_image(tmp_path):
    import imageio.v3 as iio
    proc, url, line = start_preview(tmp_path)
    try:
        assert url.startswith("http://127.0.0.1:") and "this machine only" in line
        code, ctype, page = fetch(url)
        assert code == 200 and ctype.startswith("text/html") and b"pt-render" in page
        first = wait_status(url, lambda s: s["spp"] > 0)
        assert first["passes"] == ["beauty", "samples"] and first["target_spp"] == 1000000
        code, ctype, png = fetch(url + "image.png?pass=beauty&exposure=1&tonemap=agx")
        assert code == 200 and ctype == "image/png"
        img = iio.imread(io.BytesIO(png))
        assert img.shape == (24, 32, 3) and img.max() > 0
        later = wait_status(url, lambda s: s["spp"] > first["spp"])
        assert later["samples_per_second"] > 0 and later["eta"] is not None
        samples = iio.imread(io.BytesIO(fetch(url + "image.png?pass=samples")[2]))
        assert samples.shape == (24, 32) and samples.min() == 255    # uniform sampling
        for query, code in (("pass=beauty&tonemap=sepia", 400), ("pass=beauty&exposure=x", 400),
                            ("pass=depth", 404)):
            with pytest.raises(urllib.error.HTTPError) as e:
                fetch(url + "image.png?" + query)
            assert e.value.code == code
    finally:
        returncode, err = stop(proc)
    assert returncode == 130, err
    assert (tmp_path / "out.png").exists()


def test_preview_binds_where_told_and_says_so():
    from pathtracer.preview import PreviewServer
    local = PreviewServer("127.0.0.1", 0)
    try:
        assert local.reach == "this machine only"
        assert local.server.server_address[0] == "127.0.0.1"
    finally:
        local.close()
    shared = PreviewServer("0.0.0.0", 0)
    try:
        assert "open to other machines" in shared.reach
    finally:
        shared.close()


def test_preview_error_is_one_line_not_a_traceback(capsys):
    """An exception while answering (a bug) becomes a 500 with one line, and nothing is
    printed on the render's terminal."""
    from pathtracer.preview import PreviewServer
    server = PreviewServer("127.0.0.1", 0)
    try:
        def broken(*args):
            raise RuntimeError("boom")
        server.image = broken
        with pytest.raises(urllib.error.HTTPError) as e:
            fetch(server.url + "image.png")
        assert e.value.code == 500 and b"RuntimeError: boom" in e.value.read()
    finally:
        server.close()
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("chromium") is None and shutil.which("chromium-browser")
                    is None, reason="headless Chromium is not installed")
def test_preview_page_in_a_browser(tmp_path):
    """What a person sees: the page's status line (DOM after its scripts ran) and a
    screenshot in which the image is shown."""
    import imageio.v3 as iio
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    proc, url, _ = start_preview(tmp_path)
    try:
        wait_status(url, lambda s: s["spp"] >= 8)
        flags = ["--headless", "--disable-gpu", "--no-sandbox", "--hide-scrollbars",
                 "--virtual-time-budget=4000", f"--user-data-dir={tmp_path / 'profile'}"]
        dom = subprocess.run([browser, *flags, "--dump-dom", url], capture_output=True,
                             text=True, timeout=120).stdout
        assert " spp" in dom and "M samples/s" in dom, dom[-2000:]
        shot = tmp_path / "shot.png"
        subprocess.run([browser, *flags, f"--screenshot={shot}", "--window-size=640,480",
                        url], capture_output=True, timeout=120)
        pixels = iio.imread(shot)[..., :3].astype(int)
        body = pixels[90:]                       # below the controls
        background = np.array([0x1d, 0x1f, 0x21])
        lit = np.abs(body - background).sum(axis=2) > 40
        # the 32x24 image is scaled up to the window's height: a large lit area
        assert lit.mean() > 0.2, f"the image is not shown ({lit.mean():.3f} of the page lit)"
    finally:
        stop(proc)
