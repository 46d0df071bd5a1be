"""The markers for device functions.

``numba.extending.register_jitable`` makes a plain Python function callable from ``@njit``
and from ``@cuda.jit`` code (numba 0.68 + numba-cuda 0.30, checked on CPU, the CUDA
simulator and H100/H200), while the function stays an ordinary Python object that the
interpreted backend can call.

:func:`step_marker` marks the integrator's named steps (functions that take the scene's
arrays); the kernel factories take the target. On the CPU every step is compiled with
``forceinline=True`` (LLVM's ``alwaysinline``): LLVM does not inline functions that large
by itself, and a call that passes a dozen arrays (each expanded to its meminfo, data
pointer, shape and strides: direct_light took 95 arguments, most of them copied through
the stack at every call) and checks an error status cost a third of the Cornell box's CPU
throughput when the steps were first split out (measured with ``python -m bench.ab``).
Numba's own IR-level inlining (``inline='always'``) does the same at 2-4x the cold compile
time, and it breaks the CUDA target (as does a CPU-only inlined overload beside a generic
one: typing errors on H100), so for CUDA the steps are ordinary device functions, which
NVVM inlines itself.

One marker per function: ``register_jitable(**options)`` returns a decorator that *pops*
``inline`` from its options, so a decorator object shared by several functions inlined
only the first it marked (numba 0.68, ``numba/core/extending.py``); until 2026-11-27 only
the first step of each kernel factory was inlined on the CPU (docs/benchmarks.md, "Every
step inlined on the CPU").
"""
import os

from numba.extending import register_jitable

# LLVM's fast-math flags that the compiled kernels use (CPU always; CUDA with fast=True,
# its default): every flag but nnan and ninf, as the kernels test for NaN and rely on IEEE
# infinities (the slab test divides by zero). On the CPU they let LLVM fuse multiplies and
# adds (FMA) and reorder sums: the Cornell box and the textured scene +5 % camera paths/s on
# 2 EPYC cores, bunny-studio and sun unchanged within the noise (docs/benchmarks.md).
# They change rounding, not the random numbers: CPU, GPU and interpreted images agree to
# rounding, not bit for bit.
FAST_MATH_FLAGS = frozenset({"nsz", "arcp", "contract", "afn", "reassoc"})


# Options of every device function. no_cfunc_wrapper: Numba otherwise compiles, for each
# device function and each of its signatures, a C-callable wrapper (and emits its machine
# code), which nothing calls: device functions are only called from other compiled code
# (and, in the interpreted backend, as plain Python). Without them the Cornell box's CPU
# kernel compiled in ~0.87x the time (22.3-23.6 -> 19.5-20.6 s cold, alternating, 2-core
# Xeon, 2026-12-08; docs/benchmarks.md, "Compile time"). numba-cuda never builds these wrappers and accepts the option.
DEVICE_OPTIONS = {"no_cfunc_wrapper": True}


def device(fn):
    """Mark ``fn`` as device code shared by the CPU, CUDA and Python backends."""
    return register_jitable(**DEVICE_OPTIONS)(fn)


def step_marker(target):
    """The marker of the integrator's named steps when compiling for ``target``: on the
    CPU always inlined by LLVM, elsewhere an ordinary device function."""
    if target == "cpu":
        return _always_inlined
    return device


# qualified names of the functions marked as CPU steps (tests check that the compiled CPU
# kernels call none of them)
CPU_INLINED = set()


# A profiling aid (``python -m bench.cpu_profile --calls direct_light,...``): the steps and
# other device functions (e.g. closest_hit_wide) named here stay calls on the CPU, so that
# a profile shows their share apart (see _cpu_calls_kept). Part of the kernel cache's key
# (pathtracer._cache.source_hash).
KEEP_CALLS = frozenset(filter(None, os.environ.get("PT_RENDER_CPU_CALLS", "").split(",")))


def _always_inlined(fn, **options):
    if fn.__name__ in KEEP_CALLS:
        return register_jitable(**DEVICE_OPTIONS, **options)(fn)
    # a new register_jitable per function (see the module's docstring)
    CPU_INLINED.add(fn.__qualname__)
    return register_jitable(forceinline=True, **DEVICE_OPTIONS, **options)(fn)


def _always_inlined_entry(fn):
    return _always_inlined(fn, _nrt=False)


def entry_marker(target, inlined=False):
    """The marker of the per-pixel and per-sample functions that the backends call.
    ``inlined``: on the CPU inlined by LLVM into the caller, as the steps are (the one-path
    function into the pixel's loop over samples, and that into the pass's loop over
    pixels: a call passed the scene's arrays, ~200 words through the stack, once per
    camera path; docs/benchmarks.md, "The path inlined into the pixel's loop")."""
    if target == "cpu":
        if inlined:
            return _always_inlined_entry
        return register_jitable(_nrt=False, **DEVICE_OPTIONS)
    return device


def _cpu_calls_kept():
    """Mark Numba's CPU calls of the KEEP_CALLS functions with LLVM's noinline call-site
    attribute: LLVM inlines a called step, or the traversal, into the one function that the
    pass's loop has become (everything but the pass loop itself is inlined there since
    2026-11-28), and a profile then cannot show its share apart. Only for the profiling
    aid: with PT_RENDER_CPU_CALLS unset nothing is patched."""
    from numba.core.callconv import CPUCallConv
    if getattr(CPUCallConv, "_pt_render_calls_kept", False):
        return
    original = CPUCallConv.call_function
    # Itanium-style mangled names carry each name component with its length
    marks = tuple(f"{len(name)}{name}" for name in KEEP_CALLS)

    def call_function(self, builder, callee, resty, argtys, args, attrs=None):
        if attrs is None and "pathtracer" in callee.name and any(
                m in callee.name for m in marks):
            attrs = ("noinline",)
        return original(self, builder, callee, resty, argtys, args, attrs=attrs)
    CPUCallConv.call_function = call_function
    CPUCallConv._pt_render_calls_kept = True


if KEEP_CALLS:
    _cpu_calls_kept()


def _link_only_cpu_libraries(prefix=__name__.rsplit(".", 1)[0] + "."):
    """Compile the device functions of ``prefix`` (pathtracer.kernels) as LLVM IR to be
    linked into the kernels, not as functions of their own.

    Numba compiles each function it meets into its own code library and makes it
    executable: it links the callees' IR in, runs LLVM's whole optimisation pipeline on the
    result and emits machine code, which on the CPU (every step inlined into the pass's
    loop) repeats the work for each level of the call tree: the path's bounce is optimised
    and emitted in render_sample, again in render_pixel_nested, again in the kernel. A
    device function is never called from Python, only from other compiled code, which links
    its IR; so its library here only links its own callees' IR, and the kernel's library,
    which Numba finalises as before, optimises and emits the whole once. (Its function
    object has no machine code behind it; nothing calls it.) The Cornell box's CPU kernel
    compiled in ~0.8x the time (docs/benchmarks.md, "Compile time", 2026-12-08). Skipped,
    with everything compiled as Numba does, where the internals it uses are missing
    (pathtracer.numba_internals)."""
    try:
        from numba._dynfunc import make_function
        from numba.core import codegen, cpu
        library_class, context_class = codegen.CPUCodeLibrary, cpu.CPUContext
        finalize, get_executable = library_class.finalize, context_class.get_executable
    except (ImportError, AttributeError):
        return
    if getattr(library_class, "_pt_render_link_only_installed", False):
        return

    def finalize_link_only(self):
        if not getattr(self, "_pt_render_link_only", False):
            return finalize(self)
        # (Numba's finalize, less its optimisation, the engine and the machine code)
        codegen.require_global_compiler_lock()
        self._raise_if_finalized()
        seen = set()
        for library in self._linking_libraries:
            if library not in seen:
                self._reload_init.update(library._reload_init)
                seen.add(library)
                self._final_module.link_in(library._get_module_for_linking(),
                                           preserve=True)
        self._finalized = True

    def get_executable_link_only(self, library, fndesc, env):
        if not (fndesc.modname or "").startswith(prefix):
            return get_executable(self, library, fndesc, env)
        library._pt_render_link_only = True
        library._ensure_finalized()
        return make_function(fndesc.lookup_module(), fndesc.qualname.split(".")[-1],
                             "pt-render device function (linked into kernels, not callable)",
                             0, env, (library,))

    library_class.finalize = finalize_link_only
    context_class.get_executable = get_executable_link_only
    library_class._pt_render_link_only = False
    library_class._pt_render_link_only_installed = True


_link_only_cpu_libraries()
