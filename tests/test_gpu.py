"""Checks that need a real CUDA GPU (skipped elsewhere; run on the device machine)."""
import numpy as np

from pathtracer.kernels.rng import path_key, sample_1d
from tests.conftest import gpu
from tests.test_rng import GOLDEN, _python_values


@gpu
def test_rng_identical_on_gpu():
    from numba import cuda

    @cuda.jit
    def k(args, out):
        i = cuda.grid(1)
        if i < args.shape[0]:
            out[i] = sample_1d(path_key(args[i, 0], args[i, 1], args[i, 3]), args[i, 2])

    args = np.array(GOLDEN, np.int64)
    out = np.zeros(len(args), np.float32)
    k[1, 32](args, out)
    assert np.array_equal(out, np.array(_python_values(), np.float32))


@gpu
def test_no_float64_in_ptx():
    """Kernel math is float32: no double-precision instruction in the render kernel."""
    import os

    from pathtracer.backends import make_backend
    from pathtracer.scene import load_scene
    from tests.conftest import ROOT
    scene = load_scene(os.path.join(ROOT, "scenes", "cornell-box.json"))
    backend = make_backend("cuda", scene)
    backend.compile()
    ptx = backend.ptx()
    f64 = [line for line in ptx.splitlines() if ".f64" in line]
    assert not f64, f64[:10]
