"""The Numba internals pt-render relies on, listed in one place with the versions they were
checked on, so that an upgrade that moves one fails a test loudly instead of silently
slowing or breaking a render (tests/test_numba_internals.py).

Each is used where its reason is written down:

- ``numba.core.bytecode.FunctionIdentity._unique_ids`` (``_cache.unique_symbol_names``):
  compiled symbols unique across processes, so that cached kernels of different processes
  never collide;
- ``numba.core.caching.Cache.load_overload`` / ``save_overload`` (``_cache._guarded``):
  the kernel cache's file locks and its recovery from damaged files;
- ``numba.core.callconv.CPUCallConv.call_function(..., attrs=)``
  (``kernels.device._cpu_calls_kept``): the profiling aid that keeps chosen steps as calls;
- ``numba.core.codegen.CPUCodeLibrary.finalize`` and ``numba.core.cpu.CPUContext.
  get_executable`` (``kernels.device._link_only_cpu_libraries``): device functions compiled
  as IR for the kernels to link, not optimised and emitted on their own at every level;
- ``numba.cuda.core.callconv.MinimalCallConv.call_function`` (``backends.cuda``): the
  principled evaluation called, not inlined, on the GPU (+14-24 % on the HDRI scenes);
- ``numba.cuda.cudadrv.driver._to_core_stream`` and a kernel's ``_codelibrary``
  (``backends.launch``): launches that keep their arguments' packing (~30 us of host time a
  launch instead of ~180).

Without one of them the renderer still renders (each use falls back or is skipped), but
slower or without the cache's guards; the supported versions are pinned in pyproject.toml.
"""
import importlib
import inspect

# (major, minor) ranges checked: numba 0.68 (0.68.0-0.68.1), numba-cuda 0.30 (0.30.4)
SUPPORTED = {"numba": ((0, 68), (0, 69)), "numba_cuda": ((0, 30), (0, 31))}


def version_tuple(text):
    """(major, minor) of a version string such as '0.68.1'."""
    parts = []
    for p in text.split(".")[:2]:
        digits = p[:len(p) - len(p.lstrip("0123456789"))]     # its leading digits
        parts.append(int(digits or 0))
    return tuple(parts)


def _attribute(module, path):
    obj = importlib.import_module(module)
    for name in path.split("."):
        obj = getattr(obj, name)
    return obj


def _parameters(fn):
    return list(inspect.signature(fn).parameters)


# (module, attribute path, parameters it must take or None, where pt-render uses it,
#  whether it belongs to numba-cuda)
INTERNALS = (
    ("numba.core.bytecode", "FunctionIdentity._unique_ids", None,
     "_cache.unique_symbol_names", False),
    ("numba.core.caching", "Cache.load_overload", ["self", "sig", "target_context"],
     "_cache._guarded", False),
    ("numba.core.caching", "Cache.save_overload", ["self", "sig", "data"],
     "_cache._guarded", False),
    ("numba.core.callconv", "CPUCallConv.call_function",
     ["self", "builder", "callee", "resty", "argtys", "args", "attrs"],
     "kernels.device._cpu_calls_kept", False),
    ("numba.core.codegen", "CPUCodeLibrary.finalize", ["self"],
     "kernels.device._link_only_cpu_libraries", False),
    ("numba.core.codegen", "CPUCodeLibrary._get_module_for_linking", ["self"],
     "kernels.device._link_only_cpu_libraries", False),
    ("numba.core.codegen", "CPUCodeLibrary._raise_if_finalized", ["self"],
     "kernels.device._link_only_cpu_libraries", False),
    ("numba.core.codegen", "require_global_compiler_lock", None,
     "kernels.device._link_only_cpu_libraries", False),
    ("numba.core.cpu", "CPUContext.get_executable", ["self", "library", "fndesc", "env"],
     "kernels.device._link_only_cpu_libraries", False),
    ("numba._dynfunc", "make_function", None, "kernels.device._link_only_cpu_libraries",
     False),
    ("numba.cuda.core.callconv", "MinimalCallConv.call_function",
     ["self", "builder", "callee", "resty", "argtys", "args"], "backends.cuda", True),
    ("numba.cuda.cudadrv.driver", "_to_core_stream", None, "backends.launch", True),
)


def unsupported():
    """The internals missing or changed in the installed Numba, as one line each (empty:
    all present as pt-render uses them)."""
    problems = []
    for module, path, params, where, _ in INTERNALS:
        try:
            obj = _attribute(module, path)
        except (ImportError, AttributeError) as e:
            problems.append(f"{module}.{path} (used by {where}): missing ({e})")
            continue
        if params is not None:
            # (a wrapped method keeps the wrapped one's parameters in front)
            got = _parameters(getattr(obj, "__wrapped__", obj))
            if got[:len(params)] != params and got != params:
                problems.append(f"{module}.{path} (used by {where}): takes {got}, "
                                f"pt-render calls it with {params}")
    return problems
