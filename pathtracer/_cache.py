"""pt-render's disk cache: compiled kernels (``numba/``) and parsed meshes (``meshes/``).

Why the kernel folder is keyed by our source hash:

Numba's ``cache=True`` re-validates a cached function only against its *own* source file;
a change in a device function it calls (another module) is not seen, and the stale binary
would be reused. So the cache lives in a folder named after a hash of every source file of
this package: any change to any kernel gives a fresh cache. It also keeps compiled files out
of the installed package (which may be read-only). ``NUMBA_CACHE_DIR``, when set by the
user, is respected; ``PT_RENDER_CACHE`` moves pt-render's whole cache.
"""
import hashlib
import os

import numba


def source_hash():
    root = os.path.dirname(os.path.abspath(__file__))
    h = hashlib.sha256(numba.__version__.encode())
    for folder, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                h.update(os.path.relpath(path, root).encode())
                with open(path, "rb") as f:
                    h.update(f.read())
    return h.hexdigest()[:16]


def cache_root():
    d = os.environ.get("PT_RENDER_CACHE")
    if not d:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        d = os.path.join(base, "pt-render")
    return d


def configure():
    """Point Numba's cache at this version's kernel folder (unless NUMBA_CACHE_DIR is set)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    numba.config.CACHE_DIR = os.path.join(cache_root(), "numba", source_hash())
