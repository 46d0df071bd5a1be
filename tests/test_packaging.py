"""What ``pip install`` gives a new user: every package and data file of pathtracer in the
wheel, no generic top-level module, a core without the optional stacks (CUDA, denoiser,
Ray, tests), and flags whose extra is missing saying which one to install."""
import glob
import os
import re
import subprocess
import sys
import zipfile

import pytest

from tests.conftest import ROOT

try:
    import tomllib
except ImportError:          # Python 3.10
    tomllib = None


def _pyproject():
    text = open(os.path.join(ROOT, "pyproject.toml"), encoding="utf-8").read()
    if tomllib is None:
        pytest.skip("needs tomllib (Python 3.11)")
    return tomllib.loads(text)


def test_core_dependencies_leave_the_optional_stacks_to_extras():
    project = _pyproject()["project"]
    core = " ".join(project["dependencies"]).lower()
    for optional in ("numba-cuda", "pyoidn", "ray", "pytest", "mitsuba", "matplotlib"):
        assert not re.search(rf"\b{optional}\b", core), optional
    extras = project["optional-dependencies"]
    assert any("numba-cuda" in d for d in extras["cuda"])
    assert any("pyoidn" in d for d in extras["denoise"])
    assert any("ray" in d for d in extras["cluster"])
    assert "<" in project["requires-python"]


def test_every_package_and_data_file_is_in_the_wheel(tmp_path):
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w",
                        str(tmp_path), ROOT],
                       capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        pytest.skip("cannot build a wheel here: " + (r.stderr + r.stdout)[-300:])
    names = set(zipfile.ZipFile(glob.glob(str(tmp_path / "*.whl"))[0]).namelist())
    here = {os.path.relpath(f, ROOT).replace(os.sep, "/")
            for f in glob.glob(os.path.join(ROOT, "pathtracer", "**", "*"), recursive=True)
            if os.path.isfile(f) and "__pycache__" not in f}
    assert here - names == set()
    # nothing outside the pathtracer package (no top-level `cli` module)
    assert {n.split("/")[0] for n in names if ".dist-info" not in n} == {"pathtracer"}


def test_a_missing_extra_is_named(monkeypatch):
    import importlib.util

    import pathtracer.backends as backends
    from pathtracer import denoise
    from pathtracer.errors import InputError
    real = importlib.util.find_spec
    monkeypatch.setattr(backends, "cuda_available", lambda simulator=False: False)
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "numba_cuda" else real(name, *a))
    with pytest.raises(RuntimeError, match=r"pt-render\[cuda\]"):
        backends.make_backend("cuda", None)
    monkeypatch.setattr(denoise.importlib, "import_module",
                        lambda name: (_ for _ in ()).throw(ImportError("no pyoidn")))
    with pytest.raises(InputError, match=r"pt-render\[denoise\]"):
        denoise.check_available()
