import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# ../shared beside the clone; PT_RENDER_SHARED points elsewhere (the GPU machine gets a copy).
SHARED = os.environ.get("PT_RENDER_SHARED") or os.path.join(os.path.dirname(ROOT), "shared")
sys.path.insert(0, ROOT)


from pathtracer.backends import cuda_available  # noqa: E402

HAS_GPU = cuda_available()
gpu = pytest.mark.skipif(not HAS_GPU, reason="needs a CUDA GPU")
needs_shared = pytest.mark.skipif(not os.path.isdir(SHARED), reason="needs ../shared")

# Backends every render test runs on: the CPU always, CUDA when a GPU is present.
BACKENDS = ["cpu"] + (["cuda"] if HAS_GPU else [])


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
