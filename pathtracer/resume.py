"""Resumable renders: the film's accumulation saved beside the image, and read back.

``pt-render`` writes ``OUTPUT_STEM.state.npz`` with every save of the image (the same pass,
atomically): the float64 radiance sums, each pixel's sample count (and the adaptive
halves), the samples per pixel done, the seed, the spp the texture footprints were narrowed
for, the seconds spent, the ray counts, and a hash of what decides the samples (the
compiled scene arrays, the kernel's feature set with the sampler, the image size, the
bounce limits). ``pt-render scene.json --resume out.png`` continues from it with sample
indices ``spp, spp + 1, ...``: the samples an uninterrupted render would have drawn next,
so the result is that render's image up to the float32 rounding of the pass sums, which
depends on how the samples were cut into passes (tests/test_resume.py states the
tolerance). Sample indices are per pixel (up to 2^31 - 1 each) and the counts are 64-bit,
so no total number of samples limits a render or its continuation.
"""
import hashlib
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from .film import Film
from .kernels.principled import Lobes

FORMAT_VERSION = 1
SUFFIX = ".state.npz"


# arrays computed from others that the hash covers (the sky's guide tables: from env_marg
# and env_cond, since 2026-11-28), left out so that a state saved before they existed
# still resumes: they change no sample
DERIVED_ARRAYS = frozenset({"env_guide"})


def state_path(output):
    """The state file of an output image (or the path itself if it is a state file)."""
    if output.endswith(SUFFIX):
        return output
    return os.path.splitext(output)[0] + SUFFIX


def scene_hash(compiled, max_bounces, rr_depth):
    """A hash of everything that decides a pixel's samples except the seed and the
    sample index: the compiled arrays (geometry, BVH, materials, textures, lights,
    camera), the feature set the kernel is specialised on (the sampler among them), the
    image size and the path-length settings. (The principled lobes' flags are left out of
    the feature set: they follow from the material arrays, and a state saved before they
    existed still resumes.)"""
    h = hashlib.blake2b(digest_size=16)
    features = tuple(v for k, v in compiled.features._asdict().items() if k not in Lobes._fields)
    h.update(repr((features, compiled.width, compiled.height,
                   int(max_bounces), int(rr_depth))).encode())
    for name, a in zip(compiled.arrays._fields, compiled.arrays):
        if name in DERIVED_ARRAYS:
            continue
        a = np.ascontiguousarray(a)
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.reshape(-1).view(np.uint8))
    return h.hexdigest()


@dataclass
class RenderState:
    """A saved accumulation: what ``--resume`` continues."""
    film: Film
    seed: int
    scene_hash: str
    footprint_spp: int      # the spp texture footprints were narrowed for (0: none)
    seconds: float          # rendering time spent so far
    adaptive: float = 0.0   # the adaptive target it was rendered with (0: none)


def save(path, state):
    """Write ``state`` to ``path`` atomically (a temporary file renamed over it)."""
    f = state.film
    arrays = dict(version=np.int64(FORMAT_VERSION), sum=f.sum, count=f.count,
                  spp=np.int64(f.spp),
                  rays=np.array([f.bounce_rays, f.shadow_rays, f.nonfinite], np.int64),
                  seed=np.int64(state.seed), scene_hash=np.array(state.scene_hash),
                  footprint_spp=np.int64(state.footprint_spp or 0),
                  seconds=np.float64(state.seconds), adaptive=np.float64(state.adaptive))
    if f.sum_b is not None:
        arrays.update(sum_b=f.sum_b, count_b=f.count_b)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=SUFFIX)
    try:
        with os.fdopen(fd, "wb") as out:
            np.savez(out, **arrays)
            out.flush()
            os.fsync(out.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


class StateError(ValueError):
    """A state file that cannot be read or does not fit the render."""


def load(path):
    """The :class:`RenderState` saved at ``path``; StateError names what is wrong."""
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise StateError(f"{path}: no saved render state (pt-render writes it beside the "
                         "image, as OUTPUT_STEM.state.npz)") from None
    except Exception as e:
        raise StateError(f"{path}: not a readable render state ({type(e).__name__}: "
                         f"{' '.join(str(e).split())[:200]})") from None
    need = ("version", "sum", "count", "spp", "rays", "seed", "scene_hash",
            "footprint_spp", "seconds")
    missing = [k for k in need if k not in data]
    if missing:
        raise StateError(f"{path}: not a render state (missing {', '.join(missing)})")
    if int(data["version"]) != FORMAT_VERSION:
        raise StateError(f"{path}: state format {int(data['version'])}, this pt-render "
                         f"reads {FORMAT_VERSION}")
    s, c = data["sum"], data["count"]
    if (s.ndim != 3 or s.shape[2] != 3 or s.dtype != np.float64 or c.shape != s.shape[:2]
            or c.dtype != np.int64):
        raise StateError(f"{path}: damaged render state (array shapes)")
    spp = int(data["spp"])
    if spp < 0 or (c.size and (c.min() < 0 or c.max() > spp)):
        raise StateError(f"{path}: damaged render state (sample counts)")
    film = Film(s.shape[0], s.shape[1])
    film.sum, film.count, film.spp = s, c, spp
    film.bounce_rays, film.shadow_rays, film.nonfinite = (int(x) for x in data["rays"])
    if "sum_b" in data:
        film.sum_b, film.count_b = data["sum_b"], data["count_b"]
    return RenderState(film, int(data["seed"]), str(data["scene_hash"]),
                       int(data["footprint_spp"]), float(data["seconds"]),
                       float(data.get("adaptive", 0.0)))
