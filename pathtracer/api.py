"""The Python API: load a scene (a file or a dict in the JSON scene format), change it by
JSON path, render it, and look at or save the result. See docs/python-api.md.

A kernel is specialised on the *features* a scene uses (textures, an HDRI, a thin lens,
principled materials, ...), never on their values, so a changed colour, light, camera or
transform re-renders without compiling anything: :meth:`Scene.set` re-validates the scene
and rebuilds only its flat arrays (the BVH only when geometry moved), and :func:`render`
keeps the backend, and its compiled kernel, while the feature set stays the same.
"""
import copy
import dataclasses
import json
import math
import os
import time as _time
import warnings

import numpy as np

from . import limits
from .errors import DarkImageWarning, InputError
from .scene import SceneError
from .scene.compile import CompileMemo, compile_scene
from .scene.loader import SAMPLERS, TONEMAPS, describe, read_scene_data

DICT_NAME = "<scene dict>"     # how error messages name a scene given as a dict
# Paths in the first pass of a render whose passes are seen (a callback: the command's
# progress line and saves, the live preview), per backend (others: 1 spp). On the GPU a pass
# too small to fill it costs almost what one of this size costs (Cornell box 256^2 on an
# H200: 1 spp 0.72 ms, 8 spp 1.71 ms a pass; 2026-11-26, docs/benchmarks.md), so starting
# at 1 spp spent a small image's first milliseconds on thin waves: 1, 2, 4 and 8 spp took
# 5.0 ms where one pass of 8 took 1.7. A first image ~1-2 ms later is not seen. The CPU's
# pass time grows with its samples: it starts at 1 spp.
PREVIEW_FIRST_PASS_PATHS = {"cuda": 1 << 19}


def first_pass_spp(spp, pixels, most):
    """The first pass's samples per pixel: the largest power of 2 whose paths (times
    ``pixels``) stay within ``most`` and that is at most ``spp`` (None: any), at least 1."""
    n = 1
    while (spp is None or n * 2 <= spp) and n * 2 * pixels <= most:
        n *= 2
    return n


# ---------------------------------------------------------------------------------------
# JSON paths

def _plain(value):
    """``value`` as plain JSON types (NumPy arrays and numbers, tuples -> lists, numbers),
    deep-copied, so that a scene never shares state with the caller's objects."""
    def default(o):
        if hasattr(o, "tolist"):
            return o.tolist()
        if isinstance(o, (set, frozenset)):
            return list(o)
        raise TypeError(f"{type(o).__name__} is not a JSON value")
    try:
        return json.loads(json.dumps(value, default=default, allow_nan=True))
    except (TypeError, ValueError) as e:
        raise SceneError(f"not representable as JSON: {e}", DICT_NAME) from None


def _split(path):
    """The tokens of a JSON pointer ("/materials/light/emission"), RFC 6901 escapes."""
    if not isinstance(path, str) or not path.startswith("/"):
        raise SceneError(f"expected a JSON path such as '/camera/position', got {path!r}")
    return [t.replace("~1", "/").replace("~0", "~") for t in path[1:].split("/")]


def _child(container, token, where, file=None):
    """The key or index ``token`` names in ``container``: a list takes an index or the
    "name" of one of its objects (``/materials/light`` is the material named light)."""
    if isinstance(container, dict):
        return token
    if isinstance(container, list):
        if token.isdigit():
            i = int(token)
            if i < len(container):
                return i
            raise SceneError(f"index {i} is beyond the list's {len(container)} items",
                             file, where)
        for i, item in enumerate(container):
            if isinstance(item, dict) and item.get("name") == token:
                return i
        names = [item.get("name") for item in container if isinstance(item, dict)
                 and isinstance(item.get("name"), str)]
        raise SceneError(f"no item named {token!r} (names: {', '.join(names) or 'none'})",
                         file, where)
    raise SceneError("is not an object or a list", file, where)


def _resolve(data, path, file=None):
    """(parent container, key, JSON pointer) of ``path`` in ``data``; the parent must
    exist (a missing object on the way is an error: set the whole object instead)."""
    tokens = _split(path)
    node, where = data, ""
    for token in tokens[:-1]:
        key = _child(node, token, where or "/", file)
        where += f"/{key}"
        if isinstance(node, dict) and key not in node:
            raise SceneError("no such key (set the whole object one level up)", file, where)
        node = node[key]
    key = _child(node, tokens[-1], where or "/", file)
    return node, key, f"{where}/{key}"


# ---------------------------------------------------------------------------------------
# Scenes

class Scene:
    """A scene: its JSON description (``data``), validated and compiled to the kernel's
    flat arrays. Change it with :meth:`set` / :meth:`update`; render it with
    :func:`render`. Properties: ``width``, ``height``, ``spp``, ``features`` (the set the
    kernel is specialised on), ``n_triangles``, ``warnings``, ``last_update`` (what the
    last change rebuilt and how long it took)."""

    def __init__(self, data, path, base=None, warnings=(), _overrides=None, _check=None):
        self._check = _check
        self._path = path
        self._base = base
        self._overrides = dict(_overrides or {})
        self._memo = CompileMemo()
        self._backends = {}
        self._data = data
        t0 = _time.perf_counter()
        self._desc = self._describe(data)
        self._desc.warnings.extend(warnings)
        self.compiled = compile_scene(self._desc, memo=self._memo)
        self.last_update = {"what": "loaded", "bvh": self.compiled.timings["bvh"],
                            "bvh_seconds": self.compiled.timings["bvh_build"],
                            "seconds": _time.perf_counter() - t0}

    # -- reading
    @property
    def data(self):
        """A copy of the scene's JSON description as it stands."""
        return copy.deepcopy(self._data)

    def get(self, path):
        """The JSON value at ``path`` (a copy)."""
        parent, key, where = _resolve(self._data, path, self._path)
        if isinstance(parent, dict) and key not in parent:
            raise SceneError("no such key (the default applies)", self._path, where)
        return copy.deepcopy(parent[key])

    description = property(lambda self: self._desc)
    features = property(lambda self: self.compiled.features)
    width = property(lambda self: self.compiled.width)
    height = property(lambda self: self.compiled.height)
    spp = property(lambda self: self.compiled.spp)
    seed = property(lambda self: self.compiled.seed)
    n_triangles = property(lambda self: self.compiled.n_triangles)
    warnings = property(lambda self: list(self._desc.warnings) + list(self.compiled.warnings))
    display = property(lambda self: (self._desc.render.exposure, self._desc.render.tonemap))

    def __repr__(self):
        on = [k for k, v in self.features._asdict().items() if v]
        return (f"<Scene {self._path}: {self.width}x{self.height}, {self.n_triangles} "
                f"triangles, features {', '.join(on) or 'none'}>")

    # -- changing
    def set(self, path, value):
        """Set the value at JSON path ``path`` ("/materials/light/emission",
        "/camera/position", "/objects/bunny/transform", "/environment/intensity"; a list
        item by index or by its "name"). The scene is validated as a file would be (same
        messages) and recompiled: a material, light, camera or environment change keeps
        the BVH, a geometry or transform change rebuilds it (``last_update`` says which
        and times it). On an error the scene is left as it was."""
        self.update({path: value})

    def update(self, changes):
        """Several :meth:`set` at once (one recompile): ``{path: value, ...}``; a value
        of ``None`` removes the key (its default applies)."""
        data = copy.deepcopy(self._data)
        for path, value in changes.items():
            parent, key, where = _resolve(data, path, self._path)
            if value is None:
                if isinstance(parent, dict):
                    parent.pop(key, None)
                else:
                    del parent[key]
            else:
                parent[key] = _plain(value)
        t0 = _time.perf_counter()
        desc = self._describe(data)
        desc.warnings.extend(self._desc.warnings)
        compiled = compile_scene(desc, memo=self._memo)
        self._data, self._desc, self.compiled = data, desc, compiled
        self.last_update = {"what": ", ".join(changes), "bvh": compiled.timings["bvh"],
                            "bvh_seconds": compiled.timings["bvh_build"],
                            "seconds": _time.perf_counter() - t0}

    def _describe(self, data):
        desc = describe(data, self._path, self._base)
        o = self._overrides
        if o.get("resolution"):
            desc.camera.resolution = tuple(o["resolution"])
        for key in ("sampler", "light_sampler", "exposure", "tonemap"):
            if o.get(key) is not None:
                setattr(desc.render, key, o[key])
        from .memory import check_film
        check_film(*desc.camera.resolution, "cpu")    # the film in host memory
        if self._check is not None:
            self._check(desc)
        return desc

    # -- backends: one per kind, kept while the features and image size stay the same
    def _backend(self, name, options, split=None):
        from .backends import make_backend
        from .backends import cuda_available
        if name == "auto":
            name = "cuda" if cuda_available() else "cpu"
        c = self.compiled
        key = (name, tuple(sorted(options.items())), split)
        got = self._backends.get(key)
        if got is not None and got[1] == (c.features, c.width, c.height):
            backend = got[0]
            if backend.scene is not c:
                backend.update(c)
            return backend, False
        try:
            if split is not None:
                backend = _split_backend(c, name, split)
            else:
                backend = make_backend(name, c, **options)
        except RuntimeError as e:
            raise InputError(str(e)) from None
        self._backends[key] = (backend, (c.features, c.width, c.height))
        return backend, True


def _split_backend(compiled, name, split):
    """A SplitBackend over local GPUs (("devices", ids)) or Ray workers (("ray", address,
    workers))."""
    from .distribute import SplitBackend, ThreadPool
    if split[0] == "devices":
        if name not in ("cuda", "cpu"):
            raise InputError("devices: the cuda backend (or cpu, for tests) splits over "
                             f"devices, not {name}")
        kinds = [(name, d if name == "cuda" else None) for d in split[1]]
        return SplitBackend(compiled, ThreadPool(kinds), name)
    from .cluster import pool
    p = pool(split[1], split[2])
    kinds = {i["device"].split(" ")[0].split(":")[0] for i in p.infos}
    return SplitBackend(compiled, p, kinds.pop() if len(kinds) == 1 else "mixed")


def load_scene(source, allow_missing=False, base=None, camera=None, environment=None,
               params=None, _overrides=None, _check=None):
    """A :class:`Scene` from a scene file's path (JSON, a glTF 2.0 model ``.gltf``/``.glb``,
    a Mitsuba 3 XML scene, or a thesis renderer scene folder) or from a dict in the JSON
    format (validated alike; relative file names in a dict are read from ``base``, by
    default the current folder). Raises :class:`SceneError` with the file and JSON path of
    what is wrong.

    ``camera``: for a glTF model, which of its cameras: an index or a name, or "auto" (a
    camera framing the model; the default when the file has none); for any scene, a dict
    of camera keys (``{"position": ..., "lookAt": ...}``) that replace the scene's.
    ``environment``: an environment map's path (or a dict of the format's environment
    keys) that replaces the scene's environment, or "none" to remove it.
    ``params``: a Mitsuba 3 XML scene's parameters, ``{"spp": 64}`` for its ``$spp``
    (over its ``<default>`` values; Mitsuba's and pt-render's ``-D spp=64``).

    (``_overrides``: resolution, sampler, light_sampler, exposure or tonemap that replace
    the scene's, as the CLI's flags; ``_check(description)``: a test run before compiling, such as the
    CLI's GPU memory check.)"""
    if isinstance(source, dict):
        if params:
            raise SceneError("params (-D NAME=VALUE) are for Mitsuba XML scenes, not a dict",
                             DICT_NAME)
        data = _with_view(_plain(source), camera, environment, None)
        return Scene(data, DICT_NAME, base=os.path.abspath(base or os.getcwd()),
                     _overrides=_overrides, _check=_check)
    if not isinstance(source, (str, os.PathLike)):
        raise TypeError(f"load_scene takes a path or a dict, not {type(source).__name__}")
    source = os.fspath(source)
    pick = camera if isinstance(camera, (str, int)) and not isinstance(camera, bool) else None
    if pick is not None and not source.lower().endswith((".gltf", ".glb")):
        raise SceneError(f"camera {pick!r}: choosing a camera by name or index is for glTF "
                         "files; other scenes take a position (--camera X,Y,Z[:X,Y,Z], or "
                         "a dict of camera keys in Python)", source)
    if params and not source.lower().endswith(".xml"):
        raise SceneError("params (-D NAME=VALUE) are for Mitsuba XML scenes", source)
    data, path, warnings = read_scene_data(source, allow_missing, camera=pick,
                                           environment_given=environment is not None,
                                           params=params)
    data = _with_view(data, None if pick is not None else camera, environment, path)
    return Scene(data, path, warnings=warnings, _overrides=_overrides, _check=_check)


def _with_view(data, camera, environment, path):
    """The scene data with the camera keys and environment given to load_scene."""
    if camera is not None:
        if not isinstance(camera, dict):
            raise SceneError("camera: expected a dict of camera keys, a glTF camera's "
                             f"index or name, or 'auto'; got {type(camera).__name__}",
                             path or DICT_NAME)
        cam = dict(data.get("camera") or {})
        if "lookAt" in camera:
            cam.pop("rotation", None)
        if "rotation" in camera:
            cam.pop("lookAt", None)
        cam.update(camera)
        data = dict(data, camera=cam)
    if environment is not None:
        data = dict(data)
        if isinstance(environment, str) and environment.lower() == "none":
            data.pop("environment", None)
        elif isinstance(environment, (str, os.PathLike)):
            env = os.path.abspath(os.fspath(environment))
            if not os.path.isfile(env):
                raise SceneError(f"environment map not found: {env} (given to replace the "
                                 "scene's environment)", path or DICT_NAME)
            data["environment"] = {"file": env}
        elif isinstance(environment, dict):
            data["environment"] = environment
        else:
            raise SceneError("environment: expected a file path, a dict or 'none'",
                             path or DICT_NAME)
    return data


# ---------------------------------------------------------------------------------------
# Rendering

@dataclasses.dataclass
class Progress:
    """What a render's ``callback`` receives after each pass."""
    spp: int                  # samples per pixel so far
    target_spp: object        # the spp asked for (None: a time budget)
    elapsed: float            # seconds rendering (compile excluded)
    time_limit: object        # the seconds asked for (None: an spp target)
    samples_per_second: float
    film: object              # the accumulation (pathtracer.film.Film)
    aovs: object = None       # {"albedo", "normal"} when the render makes them

    @property
    def fraction(self):
        """How far the render is, 0..1 (by spp, or by time for a time budget)."""
        parts = []
        if self.target_spp:
            parts.append(self.spp / self.target_spp)
        if self.time_limit:
            parts.append(self.elapsed / self.time_limit)
        return min(1.0, max(parts)) if parts else 0.0

    @property
    def eta(self):
        """Estimated seconds left."""
        f = self.fraction
        return self.elapsed * (1 - f) / f if f > 0 else float("inf")

    def image(self):
        """The image so far (float32 H x W x 3, linear)."""
        return self.film.image()


@dataclasses.dataclass
class Result:
    """A finished (or stopped) render. ``image``: float32 H x W x 3 linear radiance (the
    denoised one when denoising was asked for; ``raw`` is then the raw one); ``aovs``:
    {"albedo", "normal"} images when asked for; ``seconds`` rendering,
    ``compile_seconds`` compiling (0.0: the kernel was ready); ``stats`` ray counts."""
    image: np.ndarray
    spp: int
    seconds: float
    compile_seconds: float
    interrupted: bool
    stats: dict
    display: tuple = (0.0, "clamp")     # (exposure EV, tone curve) of 8-bit outputs
    raw: object = None
    aovs: object = None
    film: object = None
    passes: list = dataclasses.field(default_factory=list)
    backend: str = ""
    signal: int = 0
    denoise_seconds: float = 0.0
    shares: object = None    # several devices or workers: each one's share of the samples
    denoise_device: str = ""     # "cpu" or "cuda": where the image was denoised

    def __repr__(self):
        return (f"<Result {self.image.shape[1]}x{self.image.shape[0]}, {self.spp} spp in "
                f"{self.seconds:.3g} s (compile {self.compile_seconds:.3g} s), "
                f"{self.backend}>")

    def display_image(self):
        """8-bit sRGB (H x W x 3 uint8) as a PNG output shows it (exposure, tone curve)."""
        from .film import to_display
        return to_display(self.image, self.display)

    def _repr_png_(self):
        """Jupyter shows a result as its tone-mapped PNG."""
        from .film import encode
        return encode(self.image, ".png", self.display)

    def outputs(self, path, aovs=False):
        """[(file, image)] that :meth:`save` writes for ``path``: see output_files."""
        files, kinds = output_files(path, denoised=self.raw is not None,
                                    aovs=aovs and self.aovs is not None)
        pick = {"image": self.image, "raw": self.raw}
        if self.aovs is not None:
            pick.update(self.aovs)
        return list(zip(files, (pick[k] for k in kinds)))

    def save(self, path, aovs=False):
        """Write what ``pt-render -o PATH`` writes: the image in PATH's format (a .png gets
        its linear .exr twin), with the raw image beside a denoised one (NAME-raw.EXT),
        and with ``aovs`` the albedo and normal images. Returns the files written."""
        from .film import ALL_FORMATS, write_images
        ext = os.path.splitext(os.fspath(path))[1].lower()
        if ext not in ALL_FORMATS:
            raise ValueError(f"{path}: unknown image format {ext!r} "
                             f"(use {', '.join(ALL_FORMATS)})")
        pairs = self.outputs(os.fspath(path), aovs)
        write_images([p for p, _ in pairs], [im for _, im in pairs], self.display)
        return [p for p, _ in pairs]


# An image is "black" when 99.9 % of its pixels, exposure applied, stay below this linear
# value: 1/255, which the 8-bit output shows as at most 13 of 255 (sRGB): a render that
# looks black or nearly, whatever the few bright pixels (fireflies, a lamp's edge).
DARK_LEVEL = 1 / 255
DARK_QUANTILE = 0.999


def dark_image(image, features, exposure=0.0):
    """None, or a one-line explanation of why ``image`` (linear, H x W x 3) came out
    black or nearly so and what to try: a silent black image misleads (glTF models whose
    only emitter was a black emissive texture did so until 2026-12)."""
    level = np.quantile(image.max(axis=2), DARK_QUANTILE) * 2.0 ** exposure
    if not (level < DARK_LEVEL):      # (a NaN image is reported elsewhere)
        return None
    f = features
    if not (f.tri_lights or f.point_lights or f.environment or f.env_map):
        return ("the image is black: the scene has no light (no emissive surface, light "
                "or environment); add one, or --env FILE for an environment map")
    peak = float(image.max())
    hidden = (" (render.hideEmitters hides the emitters the camera sees)"
              if f.hide_emitters else "")
    return (f"the image is black or nearly (99.9 % of its pixels below {DARK_LEVEL:.4f}, "
            f"brightest {peak:.3g}): little light reached the camera{hidden}; check where "
            "the camera looks and what lights the scene (--env FILE adds an environment "
            "map), or raise --exposure")


def output_files(output, denoised=False, aovs=False):
    """The files one output name stands for, and what each holds ("image", "raw",
    "albedo", "normal"): OUTPUT; a PNG's float twin STEM.exr; with the denoiser the raw
    image(s) STEM-raw.EXT; with aovs STEM-albedo.exr and STEM-normal.exr (.npy for a .npy
    output). The CLI and Result.save share it."""
    stem, ext = os.path.splitext(output)
    files = [output] + ([stem + ".exr"] if ext.lower() == ".png" else [])
    kinds = ["image"] * len(files)
    if denoised:
        raw = [os.path.splitext(t)[0] + "-raw" + os.path.splitext(t)[1] for t in files]
        files, kinds = files + raw, kinds + ["raw"] * len(raw)
    if aovs:
        aov_ext = ".npy" if ext.lower() == ".npy" else ".exr"
        files += [stem + "-albedo" + aov_ext, stem + "-normal" + aov_ext]
        kinds += ["albedo", "normal"]
    return files, kinds


def render(scene, spp=None, time=None, seed=None, backend="auto", sampler=None,
           callback=None, max_bounces=None, adaptive=None, aovs=False, denoise=False,
           pass_seconds=None, devices=None, ray=None, ray_workers=None, resume=None,
           denoise_device="auto", _backend_options=None, _on_stage=None):
    """Render ``scene`` (a :class:`Scene`, a path or a dict) to ``spp`` samples per pixel
    or for ``time`` seconds, whichever comes first (neither: the scene's spp).

    ``backend``: "auto" (CUDA when a GPU is present, else CPU), "cpu", "cuda" or
    "python". ``sampler``: "sobol" or "independent" (default: the scene's). ``seed``,
    ``max_bounces``: override the scene's. ``adaptive``: a target relMSE of the image
    for adaptive sampling (see progressive.render). ``aovs``: also render the albedo and
    normal images; ``denoise``: denoise the image with Open Image Denoise (``raw`` keeps
    the noisy one), on ``denoise_device``: "auto" (the GPU when rendering on CUDA and
    OIDN's CUDA device runs here, else the CPU), "cpu" or "cuda". ``callback(progress)``
    is called after every pass with a :class:`Progress`; returning False stops the
    render (the result holds the passes done). Ctrl-C stops it too. Returns a
    :class:`Result`.

    Several devices: ``devices`` (a list of CUDA device numbers, or "all") renders every
    pass on those GPUs at once; ``ray`` (an address, or "local" for a Ray runtime on this
    machine) on ``ray_workers`` Ray workers (default: one per GPU of the cluster, else
    one). The image is the one-device image up to float32 rounding (see
    :mod:`pathtracer.distribute`).

    ``resume``: continue a render: a :class:`pathtracer.resume.RenderState` (saved by
    ``pt-render``, read by ``pathtracer.resume.load``) or the ``film`` of an earlier
    :class:`Result` of the same scene and seed; ``spp`` is then the total to reach.
    Its samples are not repeated: the render goes on from its sample count.
    (``_on_stage(stage, seconds)``, for the CLI's messages: 'compiling', 'compiled',
    'aovs' done.)
    """
    from .progressive import render as progressive
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    for name, v in (("spp", spp), ("seed", seed), ("max_bounces", max_bounces)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer))):
            raise TypeError(f"{name} must be an integer, got {v!r}")
    if spp is not None and not 1 <= spp <= limits.MAX_SPP:
        raise ValueError(f"spp must be in [1, {limits.MAX_SPP}], got {spp}")
    if seed is not None and not 0 <= seed <= limits.MAX_SEED:
        raise ValueError(f"seed must be in [0, {limits.MAX_SEED}], got {seed}")
    if max_bounces is not None and not 0 <= max_bounces <= limits.MAX_BOUNCES:
        raise ValueError(f"max_bounces must be in [0, {limits.MAX_BOUNCES}], got "
                         f"{max_bounces}")
    if time is not None and not (math.isfinite(time) and time > 0):
        raise ValueError(f"time must be a finite number of seconds > 0, got {time!r}")
    if adaptive is not None and not 0 < adaptive < 1:
        raise ValueError(f"adaptive must be a relMSE in (0, 1), got {adaptive!r}")
    if sampler is not None and sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}, got {sampler!r}")
    if denoise:
        from .denoise import DEVICES, check_available, resolve_device
        if denoise_device not in DEVICES:
            raise ValueError(f"denoise_device must be one of {', '.join(DEVICES)}, "
                             f"got {denoise_device!r}")
        check_available()
        if denoise_device == "cuda":
            resolve_device("cuda", "cuda")     # an error now, before rendering
    split = None
    if devices is not None and ray is not None:
        raise ValueError("devices and ray: give one of them")
    if devices is not None:
        if isinstance(devices, str):
            from .distribute import local_devices
            devices = local_devices(devices) if backend != "cpu" else None
        if not devices or not all(isinstance(d, (int, np.integer)) for d in devices):
            raise ValueError(f"devices must be a list of device numbers or 'all', got "
                             f"{devices!r}")
        split = ("devices", tuple(int(d) for d in devices))
    elif ray is not None:
        split = ("ray", str(ray), None if ray_workers is None else int(ray_workers))
    if sampler is not None and sampler != scene.description.render.sampler:
        # the sampler is a feature (the kernel's code), not a value: a scene that differs
        # in it alone shares the arrays
        saved = scene.compiled
        scene.compiled = dataclasses.replace(
            saved, features=saved.features._replace(sobol=sampler == "sobol"))
        try:
            return render(scene, spp, time, seed, backend, None, callback, max_bounces,
                          adaptive, aovs, denoise, pass_seconds, devices, ray, ray_workers,
                          resume, _backend_options, _on_stage)
        finally:
            scene.compiled = saved

    be, new = scene._backend(backend, dict(_backend_options or {}), split)
    compile_seconds = 0.0
    stage = _on_stage or (lambda stage, seconds: None)
    if new:
        stage("compiling", None)
        t0 = _time.perf_counter()
        be.compile()
        compile_seconds = _time.perf_counter() - t0
        stage("compiled", compile_seconds)
    c = scene.compiled
    film, footprint_spp = None, None
    if resume is not None:
        from .film import Film
        from .resume import RenderState
        if isinstance(resume, RenderState):
            footprint_spp = resume.footprint_spp or None
            seed = resume.seed if seed is None else seed
            resume = resume.film
        if not isinstance(resume, Film):
            raise TypeError("resume takes a RenderState (pathtracer.resume.load) or a "
                            f"Result's film, not {type(resume).__name__}")
        film = copy.deepcopy(resume)
    seed = c.seed if seed is None else seed
    spp0 = 0 if film is None else film.spp
    aov_images = None
    if aovs or denoise:
        from .denoise import AOV_SPP
        from .kernels.layout import AOV_ALBEDO, AOV_NORMAL
        t0 = _time.perf_counter()
        a = be.aovs(AOV_SPP, seed)
        aov_images = {"albedo": a[..., AOV_ALBEDO:AOV_ALBEDO + 3],
                      "normal": a[..., AOV_NORMAL:AOV_NORMAL + 3]}
        stage("aovs", _time.perf_counter() - t0)
    if spp is None and time is None:
        spp = c.spp
    pixels = c.width * c.height

    def on_pass(film, elapsed):
        if callback is None:
            return
        p = Progress(film.spp, spp, elapsed, time,
                     (film.spp - spp0) * pixels / max(elapsed, 1e-9),
                     film, aov_images)
        return callback(p)
    if film is not None and spp is not None and film.spp >= spp:
        spp = film.spp          # a resumed render already there: nothing more to render
    if pass_seconds is None:
        pass_seconds = be.pass_seconds
    headless = callback is None and time is None and spp is not None
    if adaptive:
        # the first pass that fills one device, seen or not: an adaptive render's pass
        # sizes decide which samples make its two halves, and a split render's must be
        # one device's (the first ADAPTIVE_MIN_SPP samples are judged together anyway)
        most = PREVIEW_FIRST_PASS_PATHS.get(be.name, 0)
    elif headless:
        # Nobody sees the intermediate images: start with a pass of up to the backend's
        # first_pass_paths (backends.base.FIRST_PASS_PATHS; a power of 2 spp), so a small
        # re-render is one or two launches, not log2(spp).
        most = be.first_pass_paths
    else:
        most = PREVIEW_FIRST_PASS_PATHS.get(be.name, 0)
    first_pass = first_pass_spp(spp, pixels, most)
    before = (0, 0, 0) if film is None else (film.camera_rays, film.bounce_rays,
                                             film.shadow_rays)
    r = progressive(c, be, spp=spp, time_limit=time, seed=seed, max_bounces=max_bounces,
                    pass_seconds=pass_seconds, on_pass=on_pass if callback else None,
                    adaptive=adaptive, first_pass=first_pass, film=film,
                    footprint_spp=footprint_spp, headless=headless)
    r.compile_seconds = compile_seconds
    stopped = r.interrupted or r.stopped
    film = r.film
    image = film.image()
    raw = None
    denoise_seconds = 0.0
    dn_device = ""
    if denoise and film.spp > 0:
        from .denoise import denoise as run_denoiser, resolve_device
        dn_device = resolve_device(denoise_device, be.name)
        t0 = _time.perf_counter()
        raw, image = image, run_denoiser(image, aov_images, dn_device)
        denoise_seconds = _time.perf_counter() - t0
    if film.spp > 0:
        why = dark_image(image if raw is None else raw, scene.features, scene.display[0])
        if why:
            warnings.warn(why, DarkImageWarning, stacklevel=2)
    seconds = r.seconds
    # (the rates count this render's rays: a resumed film holds earlier ones too)
    new_rays = (film.camera_rays - before[0], film.bounce_rays - before[1],
                film.shadow_rays - before[2])
    stats = {"camera_rays": film.camera_rays, "bounce_rays": film.bounce_rays,
             "shadow_rays": film.shadow_rays, "nonfinite": film.nonfinite,
             "paths_per_second": new_rays[0] / seconds if seconds > 0 else float("nan"),
             "rays_per_second": sum(new_rays) / seconds if seconds > 0 else float("nan")}
    return Result(image, film.spp, seconds, compile_seconds, stopped, stats, scene.display,
                  raw, aov_images if aovs else None, film, r.passes, be.name, r.signal,
                  denoise_seconds, be.shares(), dn_device)


__all__ = ["Scene", "load_scene", "render", "Result", "Progress", "output_files",
           "TONEMAPS"]
