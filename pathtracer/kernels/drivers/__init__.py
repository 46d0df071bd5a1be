"""The drivers: thin loops around the one bounce (kernels.path), and the one table of which
runs where (:func:`choose_driver`).

=================  =====================================================================
driver             runs
=================  =====================================================================
``regenerating``   the GPU's megakernel in scenes without an environment: a pixel's paths
                   with path regeneration (drivers.megakernel)
``nested``         the GPU's megakernel in scenes with one, small passes of the wavefront's
                   scenes, the CPU without an environment map, the Python backend: one
                   path after the other (drivers.megakernel; on the CPU from camera-ray
                   packets)
``deferred``       the CPU with an environment map: escaped rays looked up a few paths
                   later (drivers.deferred)
``wavefront``      the GPU with an environment map, in passes of many paths: one vertex per
                   launch (drivers.wavefront, launched by backends.wavefront)
=================  =====================================================================

All add the same samples in the same order: the same image (up to float rounding between
targets; bit for bit within one, tests/test_render.py). The AOV pass (drivers.aov) is the
bounce's first-hit steps.
"""
from ..layout import specialise
from .aov import make_aov
from .deferred import Deferred, make_deferred
from .megakernel import Megakernel, make_megakernel
from .wavefront import Wavefront, make_wavefront

__all__ = ["choose_driver", "make_aov", "make_deferred", "make_megakernel", "make_wavefront",
           "Deferred", "Megakernel", "Wavefront", "WAVE_MIN_PATHS", "WAVE_MIN_PATHS_MIPMAPS",
           "wave_min_paths_for"]

REGENERATING = "regenerating"
NESTED = "nested"
DEFERRED = "deferred"
WAVEFRONT = "wavefront"

# The GPU's wavefront wins from 0.5-0.8M paths a pass: H200, 2026-11-26 (an ad-hoc probe of
# both kernels, 256x192), wavefront / megakernel paths/s at 0.39 / 0.79 / 1.57M paths:
# bunny-studio 0.99 / 1.12 / 1.30, the sun 0.96 / 1.05 / 1.23 (before its launches kept
# their arguments' packing the two crossed at 1.5-2M: 2^21).
WAVE_MIN_PATHS = 1 << 19
# ... and from this many in scenes with mip-mapped textures, whose megakernel diverges most
# (anisotropic probes at the first hits): the textured scene at 256x192, the same probe:
# the wavefront 1.42x the megakernel at 0.10M paths, 1.76x at 0.20M, 1.96x at 0.39M
# (docs/benchmarks.md).
WAVE_MIN_PATHS_MIPMAPS = 1 << 17


def wave_min_paths_for(features):
    """The smallest pass (in paths) that the wavefront renders where it is the GPU's
    driver."""
    return WAVE_MIN_PATHS_MIPMAPS if specialise(features).mipmaps else WAVE_MIN_PATHS


def choose_driver(target, features, paths=None):
    """The driver that renders a pass of ``paths`` paths (None: a pass large enough for
    any) of a scene with ``features`` on ``target`` ("cpu", "cuda" or "python"):

    - CPU: ``deferred`` with an environment map (its lookups, beyond a core's caches,
      prefetched a few paths ahead: docs/benchmarks.md), else ``nested``: regeneration
      measured slower on the CPU (the Cornell box 0.68x, 2-core EPYC, bench.ab), where a
      thread runs one path at a time either way.
    - CUDA: ``wavefront`` with an environment map, whose warps diverge most (H100,
      2026-11-24, bench.gpu_launch: bunny-studio 1.21-1.23x, the sun 1.10-1.19x), in passes
      of at least wave_min_paths_for(features) paths, unless a material has alpha (the
      wavefront's trace launch has no sampler state for stochastic transparency); the
      Cornell box lost 18-27 % to it.
      Else the megakernel: ``regenerating`` without an environment (the Cornell box +15 %,
      H100, 2026-11-23), ``nested`` with one (one path after the other measured 4-9 %
      faster where the vertices diverge anyway).
    - Python (interpreted): ``nested``.
    """
    S = specialise(features)
    if target == "cpu":
        return DEFERRED if S.env_map else NESTED
    if target == "cuda":
        if S.env_map and not S.alpha and (paths is None or paths >= wave_min_paths_for(features)):
            return WAVEFRONT
        return NESTED if S.any_environment else REGENERATING
    return NESTED
