"""pt-render's disk cache: compiled kernels (``numba/``) and parsed meshes (``meshes/``).

Why the kernel folder is keyed by our source hash:

Numba's ``cache=True`` re-validates a cached function only against its *own* source file;
a change in a device function it calls (another module) is not seen, and the stale binary
would be reused. So the cache lives in a folder named after a hash of every source file of
this package: any change to any kernel gives a fresh cache. ``NUMBA_CACHE_DIR``, when set by
the user, is respected; ``PT_RENDER_CACHE`` moves pt-render's whole cache.

A cache must never cost a render:

- **Unusable folder** (read-only, a file, no space to create it): kernels are compiled
  without a disk cache this run, with a warning. Numba would otherwise fall back to a
  ``__pycache__`` inside the installed package, where a later edit of a kernel module was
  not seen (a stale image); :func:`jit_cache` tells every decorator whether to cache.
- **Damaged files** (a truncated or corrupt index or binary): Numba raises an unpickling
  error on load. :func:`install_guards` wraps Numba's load so that a failure moves the
  damaged folder aside (``<folder>.damaged-<time>``), warns once, and compiles afresh into
  a new folder.
- **Failed writes** (disk full): the kernel is used uncached, with one warning.
- **Several processes at once** (a batch on Ray workers, a preview beside a render): Numba
  updates a function's index without a lock (read the index, pick the first free data-file
  number, write both). Two processes saving different kernels of one function (the same
  closure, other scene features) at once both take the same number: one kernel is lost, and
  when the index of one and the data file of the other win, a later run loads the other
  scene's kernel for this one, a silently wrong image (seen once in CI). Loads and saves of
  our folder therefore hold a lock on the function's index (``flock``: shared to load,
  exclusive to save).
- **Several processes need the same new kernel** (Ray workers on one machine, a batch
  beside a preview, the test suite's workers): each would compile it, 20-40 s of a core
  apiece. The first compile of a kernel in a process therefore holds a lock named after
  the kernel in the cache folder (:func:`compile_lock`); a second process that needs the
  same kernel waits for it and then loads what the first one saved.
- **Kernels compiled in different processes, loaded into one.** Numba names a compiled
  function's symbol after its qualified name, argument types and a counter that starts at
  1 in every process. Closures of one factory for two scenes (``render_pass``,
  ``direct_light``, ... with other features) compiled first thing in two processes get the
  same names; both go to the disk cache, and a process that loads the two links the second
  kernel to the first one's functions (one definition per name): the second scene rendered
  with the first scene's code, black in the test (and the cause of a CI failure). The
  counter therefore starts at a random 60-bit number in every process
  (:func:`unique_symbol_names`): names stay unique within a process, as Numba needs, and no
  longer repeat across processes. The cache's index keys do not contain them, so cache hits
  are unchanged.
"""
import contextlib
import hashlib
import itertools
import os
import secrets
import sys
import time

import numba

try:
    import fcntl
except ImportError:          # not POSIX: Numba's own (unlocked) behaviour
    fcntl = None

_state = {"enabled": True, "folder": None, "warned": set()}


def warn(message):
    """One ``pt-render: warning:`` line on stderr, once per message."""
    if message not in _state["warned"]:
        _state["warned"].add(message)
        print(f"pt-render: warning: {message}", file=sys.stderr)


def source_hash():
    root = os.path.dirname(os.path.abspath(__file__))
    h = hashlib.sha256(numba.__version__.encode())
    # steps kept as calls for a profile (kernels.device.KEEP_CALLS) compile other code
    h.update(os.environ.get("PT_RENDER_CPU_CALLS", "").encode())
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


def writable(folder):
    """None if files can be created in ``folder`` (made if missing), else the reason."""
    try:
        os.makedirs(folder, exist_ok=True)
        probe = os.path.join(folder, f".probe-{os.getpid()}")
        with open(probe, "wb") as f:
            f.write(b"x")
        os.unlink(probe)
        return None
    except OSError as e:
        return e.strerror or str(e)


def unique_symbol_names():
    """Start Numba's per-process function counter (part of every compiled symbol's name) at
    a random 60-bit number, so that functions compiled in different processes never share
    a symbol name (see the module's docstring). Idempotent."""
    from numba.core import bytecode
    if not getattr(bytecode.FunctionIdentity, "_pt_render_unique", False):
        bytecode.FunctionIdentity._unique_ids = itertools.count(secrets.randbits(60) + 1)
        bytecode.FunctionIdentity._pt_render_unique = True


def configure():
    """Point Numba's cache at this version's kernel folder (unless NUMBA_CACHE_DIR is set),
    or turn disk caching off if that folder cannot be written."""
    unique_symbol_names()
    folder = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(cache_root(), "numba",
                                                               source_hash())
    reason = writable(folder)
    if reason is not None:
        _state["enabled"] = False
        which = "NUMBA_CACHE_DIR" if os.environ.get("NUMBA_CACHE_DIR") else (
            "PT_RENDER_CACHE" if os.environ.get("PT_RENDER_CACHE") else "the cache folder")
        warn(f"kernel cache {folder} is not usable ({reason}); compiling without a disk "
             f"cache (set {which} to a writable folder to keep compiled kernels)")
        return
    _state["folder"] = folder
    if not os.environ.get("NUMBA_CACHE_DIR"):
        numba.config.CACHE_DIR = folder
    install_guards()


def read_only(a):
    """A read-only view of the array ``a`` (no copy), for the arguments of compiled
    functions that only read them. Numba compiles a function once per argument type, and
    read-only is part of an array's type: arrays that come from Ray's object store are
    read-only, so a Ray worker compiled the scene's kernel, the wide BVH's collapse and the
    film's sum afresh (30 + 9 s of a core on the Cornell box) beside the versions cached
    for writable arrays. Passed read-only everywhere, they are the same functions."""
    v = a.view()
    v.flags.writeable = False
    return v


def jit_cache():
    """The ``cache=`` value for every pt-render ``@njit`` / ``@cuda.jit``."""
    return _state["enabled"]


def _ours(cache):
    folder = _state["folder"]
    path = getattr(cache, "_cache_path", None)
    return folder is not None and path is not None and os.path.abspath(path).startswith(
        os.path.abspath(folder) + os.sep)


def _quarantine(cache, error):
    """Move the damaged cache folder (the one of this function's source folder, not the
    whole cache root: that may be a user's NUMBA_CACHE_DIR shared with other projects)
    aside; later loads miss and recompile, and Numba's save recreates the folder."""
    folder = os.path.abspath(cache._cache_path)
    aside = f"{folder}.damaged-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    try:
        os.replace(folder, aside)
        where = f"moved to {aside}"
    except OSError:
        where = "left in place"
    warn(f"the kernel cache in {folder} is damaged ({type(error).__name__}: "
         f"{' '.join(str(error).split())[:120]}); it was {where} and the kernels are "
         "compiled afresh")


def _flock(path, operation, make_folder=False, wait_seconds=None, on_wait=None):
    """A descriptor of ``path`` (created if missing) that holds ``flock(operation)``, or None
    where no lock can be had (a folder that does not exist or cannot be written, a file
    system without flock). ``wait_seconds``: poll for the lock (so that Ctrl-C ends the
    wait) and give up after that long, calling ``on_wait()`` once if another holder makes
    it wait; None: block until it is free."""
    fd = None
    try:
        if make_folder:
            os.makedirs(os.path.dirname(path), exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        if wait_seconds is None:
            fcntl.flock(fd, operation)
            return fd
        deadline = time.monotonic() + wait_seconds
        while True:
            try:
                fcntl.flock(fd, operation | fcntl.LOCK_NB)
                return fd
            except BlockingIOError:
                if on_wait is not None:
                    on_wait()
                    on_wait = None
                if time.monotonic() > deadline:
                    os.close(fd)
                    return None
                time.sleep(0.1)
    except OSError:
        if fd is not None:
            os.close(fd)
        return None


@contextlib.contextmanager
def _holding(fd):
    try:
        yield
    finally:
        if fd is not None:
            os.close(fd)       # releases the lock


@contextlib.contextmanager
def index_lock(cache, exclusive):
    """Hold an ``flock`` on ``<index file>.lock`` of a Numba cache: shared while loading (the
    index and the data file it names are read as one), exclusive while saving. Where no
    lock can be had (no fcntl, a folder that does not exist yet or cannot be written, a file
    system without flock) this is Numba's unlocked behaviour."""
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    fd = None
    if fcntl is not None and index is not None:
        fd = _flock(index + ".lock", fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH,
                    make_folder=exclusive)
    with _holding(fd):
        yield


# How long a process waits for another one's compile of the same kernel before it
# compiles the kernel itself (a holder stopped with SIGSTOP, or a machine so loaded that
# one compile takes this long).
COMPILE_WAIT_SECONDS = 900.0


@contextlib.contextmanager
def compile_lock(name, dispatcher):
    """Hold the lock ``<cache folder>/compile-locks/<name>.lock`` while ``dispatcher`` (a
    Numba dispatcher) is compiled or loaded for the first time in this process: another
    process compiling the same kernel finishes first and this one loads its result from
    the disk cache. Nothing is locked once the dispatcher has a compiled signature, when the
    disk cache is off, or where no lock can be had (no fcntl, a read-only folder). The wait
    polls, so Ctrl-C ends it; after COMPILE_WAIT_SECONDS the kernel is compiled anyway. A
    process that has to wait says so on stderr, once."""
    folder = _state["folder"]
    fd = None
    if not (dispatcher.signatures or not _state["enabled"] or folder is None
            or fcntl is None):
        path = os.path.join(folder, "compile-locks", name + ".lock")

        def on_wait():     # (else a long wait looks like a hang)
            print(f"pt-render: waiting for another process that is compiling the same "
                  f"kernel ({path}); it will then be loaded from the disk cache",
                  file=sys.stderr, flush=True)
        fd = _flock(path, fcntl.LOCK_EX, make_folder=True,
                    wait_seconds=COMPILE_WAIT_SECONDS, on_wait=on_wait)
    with _holding(fd):
        yield


def _guarded(cls):
    if getattr(cls, "_pt_render_guarded", False):
        return
    load, save = cls.load_overload, cls.save_overload

    def load_overload(self, sig, target_context):
        if not _ours(self):
            return load(self, sig, target_context)
        try:
            with index_lock(self, exclusive=False):
                return load(self, sig, target_context)
        except Exception as e:    # unpickling errors of every kind: a damaged file
            _quarantine(self, e)
            return None           # a cache miss: Numba compiles

    def save_overload(self, sig, data):
        if not _ours(self):
            return save(self, sig, data)
        try:
            with index_lock(self, exclusive=True):
                return save(self, sig, data)
        except Exception as e:    # disk full, folder removed, damaged index
            warn(f"could not write the kernel cache in {_state['folder']} "
                 f"({getattr(e, 'strerror', None) or type(e).__name__}); the kernels work "
                 "but will be compiled again next run")

    cls.load_overload = load_overload
    cls.save_overload = save_overload
    cls._pt_render_guarded = True


def install_guards():
    """Wrap Numba's (and numba-cuda's) cache load and save for pt-render's folder only."""
    from numba.core import caching
    _guarded(caching.Cache)
    try:
        from numba.cuda.core import caching as cuda_caching
    except ImportError:      # numba-cuda absent or laid out differently: CPU only
        return
    if cuda_caching.Cache is not caching.Cache:
        _guarded(cuda_caching.Cache)
