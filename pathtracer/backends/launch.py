"""Kernel launches whose argument packing is kept between launches.

A launch through a Numba dispatcher (``kernel[grid, block](*args)``) types every argument
(to pick the compiled overload) and flattens it into the driver's parameter list: for the
scene's ~25 device arrays (shape, strides, pointer of each: ~255 parameters) that is
~180 us of host time per launch on an H200's host (2026-11-26, an ad-hoc probe: typing
42 us, flattening 111 us, the driver's launch of the packed list 16 us). The wavefront's
passes launch ~13 kernels, so a pass of fewer than ~2M paths was bound by the host
(kernels.drivers.WAVE_MIN_PATHS), and each progressive pass of the megakernel paid it too.

``Launcher`` binds to the overload the first launch compiled (or found) and keeps, per
argument position, the flattened parameters of the last device array (or tuple of device
arrays, the scene) passed there: the next launch with the same object reuses them, a new
object of the same Numba type is flattened once, and anything else (another type, a host
array that Numba would copy, the CUDA simulator, a numba-cuda without these internals)
goes through the dispatcher as before. The kernel's parameters are the dispatcher's own
flattening (``_Kernel._prepare_args``), so the GPU sees the same bytes.

``PT_RENDER_PLAIN_LAUNCH=1`` sends every launch through the dispatcher.
"""
import os

from numba import config

try:        # numba-cuda's internals, as its own _Kernel.launch uses them (0.30)
    from cuda.core import LaunchConfig
    from cuda.core import launch as _core_launch
    from numba.cuda.cudadrv import driver as _driver
    from numba.cuda.cudadrv.devicearray import DeviceNDArray
    from numba.cuda import types as _types
    _AVAILABLE = hasattr(_driver, "_to_core_stream")
except Exception:       # pragma: no cover - an older or newer numba-cuda
    _AVAILABLE = False


def _fast_launches():
    return _AVAILABLE and not config.ENABLE_CUDASIM and \
        os.environ.get("PT_RENDER_PLAIN_LAUNCH", "") in ("", "0")


def _on_device(value):
    """Whether ``value`` is a device array or a tuple holding only device arrays (what can
    be flattened once and passed again: nothing is copied for it)."""
    if isinstance(value, DeviceNDArray):
        return True
    if isinstance(value, tuple):
        return len(value) > 0 and all(_on_device(v) for v in value)
    return False


def _dims(d):
    return tuple(d) + (1,) * (3 - len(d)) if isinstance(d, tuple) else (d, 1, 1)


class Launcher:
    """``Launcher(kernel)(grid, block, *args)`` launches the Numba CUDA kernel as
    ``kernel[grid, block](*args)`` does, on the default stream, without waiting. One
    Launcher per caller that launches it repeatedly (it is not shared between threads)."""

    def __init__(self, dispatcher):
        self.dispatcher = dispatcher
        self._fast = _fast_launches()
        self._kernel = None     # the bound overload (numba-cuda's _Kernel)
        self._types = None      # its argument types
        self._scalars = None    # per position: the Python type of a scalar argument
        self._cached = None     # per position: (object, its flattened parameters)
        self._configs = {}
        self._stream = None

    def __call__(self, griddim, blockdim, *args):
        if self._kernel is not None:
            params = self._pack(args)
            if params is not None:
                key = (griddim, blockdim)
                cfg = self._configs.get(key)
                if cfg is None:
                    cfg = self._configs[key] = LaunchConfig(
                        grid=_dims(griddim), block=_dims(blockdim), shmem_size=0)
                cufunc = self._kernel._codelibrary.get_cufunc()   # this context's
                _core_launch(self._stream, cfg, cufunc.kernel, *params)
                return
        self.dispatcher[griddim, blockdim](*args)
        if self._fast:
            self._bind(args)

    def _bind(self, args):
        """Bind to the overload the dispatcher chose for ``args`` (or stay unbound)."""
        self._kernel = None
        try:
            d = self.dispatcher
            argtypes = tuple(d.typeof_pyval(a) for a in args)
            kernel = d.overloads.get(argtypes)
            if kernel is None or getattr(kernel, "debug", True) or \
                    getattr(kernel, "cooperative", True) or \
                    tuple(kernel.argument_types) != argtypes:
                return
            scalars = []
            for t, a in zip(argtypes, args):
                if isinstance(t, (_types.Array, _types.BaseTuple)):
                    if not _on_device(a):
                        return      # a host array: the dispatcher copies it each time
                    scalars.append(None)
                elif isinstance(t, (_types.Integer, _types.Float, _types.Boolean)):
                    scalars.append(type(a))
                else:
                    return
            self._stream = _driver._to_core_stream(0)
        except Exception:       # pragma: no cover - internals changed: the dispatcher
            return
        self._types = argtypes
        self._scalars = scalars
        self._cached = [None] * len(args)
        self._kernel = kernel
        try:    # the internals a launch uses, tried once here: a numba-cuda whose
            #     internals differ gets the dispatcher, not a traceback at the next launch
            LaunchConfig(grid=(1, 1, 1), block=(1, 1, 1), shmem_size=0)
            kernel._codelibrary.get_cufunc().kernel
            if self._pack(args) is None:
                self._kernel = None
        except Exception:       # pragma: no cover
            self._kernel = None

    def _pack(self, args):
        """The kernel's parameters for ``args``, or None where the dispatcher must launch
        (a type other than the bound overload's)."""
        if len(args) != len(self._types):
            return None
        kernel, stream = self._kernel, self._stream
        params, copies = [], []    # copies: what Numba would copy back (none, see below)
        for i, (t, a) in enumerate(zip(self._types, args)):
            scalar = self._scalars[i]
            if scalar is not None:
                if type(a) is not scalar:
                    return None
                kernel._prepare_args(t, a, stream, copies, params)
                continue
            cached = self._cached[i]
            if cached is not None and cached[0] is a:
                params.extend(cached[1])
                continue
            if not _on_device(a) or self.dispatcher.typeof_pyval(a) != t:
                return None
            flat = []
            kernel._prepare_args(t, a, stream, copies, flat)
            if copies:      # (a copy back to a host array: device arrays need none)
                return None
            self._cached[i] = (a, flat)
            params.extend(flat)
        return params
