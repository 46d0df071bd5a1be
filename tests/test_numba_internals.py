"""The Numba internals pt-render relies on (pathtracer.numba_internals) are there as it uses
them, and the installed Numba is a version they were checked on: an upgrade that moves one
fails here, loudly, not as a silently slower or unguarded render."""
from importlib import metadata

import pytest

from pathtracer import numba_internals as N


@pytest.mark.parametrize("package", ["numba", "numba_cuda"])
def test_installed_numba_is_a_checked_version(package):
    lo, hi = N.SUPPORTED[package]
    version = metadata.version(package.replace("_", "-"))
    assert lo <= N.version_tuple(version) < hi, (
        f"{package} {version} is outside the range pt-render's use of its internals was "
        f"checked on ({lo} to {hi}, exclusive): check pathtracer/numba_internals.py's list, "
        "then widen SUPPORTED and pyproject.toml's pin")


def test_the_pin_in_pyproject_is_the_checked_range():
    import os
    import re
    text = open(os.path.join(os.path.dirname(__file__), "..", "pyproject.toml")).read()
    for package, name in (("numba", "numba"), ("numba_cuda", "numba-cuda")):
        lo, hi = N.SUPPORTED[package]
        m = re.search(rf'"{name}>=([\d.]+),<([\d.]+)"', text)
        assert m, f"pyproject.toml pins no range for {name}"
        assert N.version_tuple(m.group(1)) == lo and N.version_tuple(m.group(2)) == hi


def test_every_internal_is_there_as_used():
    assert N.unsupported() == []


def test_a_missing_or_changed_internal_is_reported(monkeypatch):
    monkeypatch.setattr(N, "INTERNALS", N.INTERNALS + (
        ("numba.core.caching", "Cache.no_such_method", None, "nowhere", False),
        ("numba.core.caching", "Cache.load_overload", ["self", "other"], "nowhere", False)))
    problems = N.unsupported()
    assert len(problems) == 2 and "missing" in problems[0] and "takes" in problems[1]
    assert N.version_tuple("0.68.1") == (0, 68) and N.version_tuple("1.0rc1") == (1, 0)
