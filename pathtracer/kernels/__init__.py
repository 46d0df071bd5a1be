"""Device code shared by every backend.

The kernel contract (what both Numba targets, ``@njit`` and ``@cuda.jit``, accept):

- functions are plain Python decorated with :func:`device` (``register_jitable``), so the
  same source is compiled for the CPU, for CUDA, and also runs interpreted in the
  ``python`` backend for debugging;
- arguments are scalars, tuples of scalars and flat NumPy arrays (float32 / int32);
  vectors travel as 3-tuples;
- no classes, allocation, I/O, exceptions, ``with`` or comprehensions;
- all floating point is float32: constants come from :mod:`.constants` (a bare Python
  literal such as ``0.5`` is float64 and would promote the expression on the GPU);
- integer hashing is done on ``uint64`` values masked to 32 bits (see :mod:`.rng`).

Per-scene specialisation happens in :mod:`.integrator`, whose factory closes over a frozen
feature set; nothing else branches on scene features.
"""
