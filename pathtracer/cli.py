"""``pt-render SCENE``: render a scene file progressively to PNG + a float image.

Failures are one line and an exit code (:mod:`pathtracer.errors`): 2 for bad input, 3 when
an output cannot be written, 128 + N when signal N stopped the render (after saving), 1
for a bug. ``--debug`` adds the traceback.
"""
import argparse
import contextlib
import csv
import math
import os
import re
import signal
import sys
import tempfile
import threading
import time
import traceback

from . import limits
from .errors import (EXIT_INPUT, EXIT_INTERNAL, EXIT_IO, EXIT_OK, InputError, Interrupted,
                     OutputError)
from .film import ALL_FORMATS, read_image, relmse, write_images
from .scene import SceneError
from .scene.loader import LIGHT_SAMPLERS, SAMPLERS, TONEMAPS

PREVIEW_PORT = 8765
# a compile that takes longer than this is announced (a cached one takes well under it)
COMPILE_NOTICE_SECONDS = 1.0
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, n))


# ---------------------------------------------------------------------------------------
# Arguments

class Parser(argparse.ArgumentParser):
    def error(self, message):
        """One line and exit 2 (argparse prints the usage block as well)."""
        print(f"pt-render: error: {message} (pt-render --help lists the options)",
              file=sys.stderr)
        sys.exit(EXIT_INPUT)


def _integer(lo, hi):
    def parse(text):
        try:
            v = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer in [{lo}, {hi}], got "
                                             f"{text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"must be in [{lo}, {hi}], got {v}")
        return v
    return parse


def _seconds(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") \
            from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return v


def _target(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a relMSE such as 1e-3, got {text!r}") \
            from None
    if not (math.isfinite(v) and 0 < v < 1):
        raise argparse.ArgumentTypeError(f"must be a number in (0, 1), got {text!r}")
    return v


def _exposure(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of stops (EV), got {text!r}") \
            from None
    if not (math.isfinite(v) and abs(v) <= limits.MAX_EXPOSURE):
        raise argparse.ArgumentTypeError(f"must be a number in [-{limits.MAX_EXPOSURE:g}, "
                                         f"{limits.MAX_EXPOSURE:g}], got {text!r}")
    return v


def _resolution(text):
    try:
        w, h = (int(x, 10) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 512x512, got {text!r}") \
            from None
    if not (1 <= w <= limits.MAX_DIMENSION and 1 <= h <= limits.MAX_DIMENSION):
        raise argparse.ArgumentTypeError(f"width and height must be in [1, "
                                         f"{limits.MAX_DIMENSION}], got {text!r}")
    if w * h > limits.MAX_PIXELS:
        raise argparse.ArgumentTypeError(f"at most {limits.MAX_PIXELS} pixels, got {w * h}")
    return w, h


def _camera(text):
    """--camera: 'auto', a glTF camera's index or name, or X,Y,Z[:X,Y,Z] (position and the
    point looked at)."""
    if re.fullmatch(r"\s*[-+.\deE]+\s*,\s*[-+.\deE]+\s*,\s*[-+.\deE]+\s*(:.*)?", text):
        parts = text.split(":")
        try:
            vecs = [[float(x) for x in part.split(",")] for part in parts]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected X,Y,Z or X,Y,Z:X,Y,Z, got {text!r}") \
                from None
        if len(vecs) > 2 or any(len(v) != 3 or not all(map(math.isfinite, v)) for v in vecs):
            raise argparse.ArgumentTypeError(f"expected X,Y,Z or X,Y,Z:X,Y,Z (finite), got "
                                             f"{text!r}")
        cam = {"position": vecs[0]}
        if len(vecs) == 2:
            cam["lookAt"] = vecs[1]
        return cam
    if not text.strip():
        raise argparse.ArgumentTypeError("empty camera")
    return text


def _define(text):
    """NAME=VALUE of -D, as a (name, value) pair."""
    name, eq, value = text.partition("=")
    if not eq or not name.strip().replace("_", "a").isalnum():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    return name.strip(), value


def build_parser():
    p = Parser(
        prog="pt-render",
        description="Physically based path tracer (Numba, CPU and CUDA). Renders SCENE "
                    "progressively: the image is rewritten at growing intervals, and Ctrl-C, "
                    "SIGTERM or SIGHUP stop the render and keep what is done. Exit codes: 0 "
                    "done, 2 bad input, 3 an output could not be written, 128+N stopped by "
                    "signal N (the image saved), 1 a bug.")
    p.add_argument("scene", nargs="+",
                   help="scene file (JSON, see docs/scene-format.md; a glTF 2.0 "
                   "model, .gltf or .glb; or a Mitsuba 3 XML scene, its common subset), or a "
                   "thesis renderer scene folder; several: a batch, rendered one after "
                   "another (each on every device or worker given)")
    p.add_argument("-o", "--output", default=None,
                   help="output image; the extension picks the format: .png (8-bit sRGB, "
                        "with a lossless float .exr beside it), .hdr, .exr or .npy (float linear RGB). "
                        "'{name}' in it is replaced by the scene's name (needed for a batch). "
                        "Default: the scene's name with .png, in the current folder")
    p.add_argument("--spp", type=_integer(1, limits.MAX_SPP),
                   help="samples per pixel (default: the scene's)")
    p.add_argument("--time", type=_seconds, metavar="SECONDS",
                   help="render until this much time is spent (with --spp: whichever first)")
    p.add_argument("--backend", choices=("auto", "cpu", "cuda", "python"), default="auto",
                   help="auto: CUDA when a GPU is present, else CPU; python: interpreted "
                        "(slow, for debugging)")
    p.add_argument("--devices", metavar="all|0,1,...",
                   help="render on several CUDA GPUs of this machine at once (one worker "
                        "each, the load balanced as they go); 'all' or device numbers")
    p.add_argument("--ray", metavar="ADDRESS",
                   help="render on a Ray cluster: its address (auto, HOST:6379, "
                        "ray://HOST:10001), or 'local' to start a Ray runtime on this "
                        "machine; needs pip install -e '.[cluster]'")
    p.add_argument("--ray-workers", type=_integer(1, 4096), metavar="N",
                   help="Ray workers (default: one per GPU of the cluster, else one); each "
                        "uses a GPU or, without one, an equal share of the CPUs")
    p.add_argument("--resume", metavar="OUTPUT",
                   help="continue the render saved as OUTPUT (its image, or the "
                        "OUTPUT_STEM.state.npz written beside it) to --spp or --time "
                        "(counted from the first start); the samples go on where it stopped")
    p.add_argument("--no-state", action="store_true",
                   help="do not write OUTPUT_STEM.state.npz (the accumulation --resume "
                        "continues)")
    p.add_argument("--seed", type=_integer(0, limits.MAX_SEED),
                   help="random seed (default: the scene's)")
    p.add_argument("--resolution", type=_resolution, metavar="WxH",
                   help="override the camera resolution")
    p.add_argument("--camera", type=_camera, metavar="CAMERA",
                   help="X,Y,Z or X,Y,Z:X,Y,Z: the camera's position (and the point it looks "
                        "at) for any scene; for a glTF model also one of its cameras by index "
                        "or name, or 'auto' (framing the model: the default when the file has "
                        "no camera)")
    p.add_argument("-D", "--define", action="append", type=_define, metavar="NAME=VALUE",
                   default=[],
                   help="a Mitsuba XML scene's parameter: sets $NAME over its <default> "
                        "(as Mitsuba's -D; repeat for several)")
    p.add_argument("--env", metavar="FILE",
                   help="light the scene with this environment map (.hdr, .exr, ...) instead "
                        "of its own environment ('none': no environment)")
    p.add_argument("--max-bounces", type=_integer(0, limits.MAX_BOUNCES),
                   help="override render.maxBounces")
    p.add_argument("--adaptive", type=_target, metavar="RELMSE",
                   help="adaptive sampling to an image relMSE of RELMSE (e.g. 1e-3): after "
                        "16 spp a pixel stops once its estimated relMSE is below its share "
                        "of RELMSE (noisier pixels get a larger share, so samples go where "
                        "they lower the image's error most); the render ends when all have, "
                        "or at --spp / --time")
    p.add_argument("--denoise", action="store_true",
                   help="denoise with Open Image Denoise, guided by albedo and normal "
                        "images: OUTPUT is the denoised image, OUTPUT_STEM-raw.EXT the raw one")
    p.add_argument("--denoise-device", choices=("auto", "cpu", "cuda"), default="auto",
                   help="where --denoise runs: auto (the default) on the GPU when rendering "
                        "with CUDA and Open Image Denoise's CUDA device runs here, else on "
                        "the CPU")
    p.add_argument("--aovs", action="store_true",
                   help="also write the albedo and normal images (OUTPUT_STEM-albedo.exr, "
                        "OUTPUT_STEM-normal.exr; .npy for a .npy output)")
    p.add_argument("--sampler", choices=SAMPLERS,
                   help="sobol (Owen-scrambled, low discrepancy) or independent; "
                        "default: the scene's render.sampler (sobol)")
    p.add_argument("--light-sampler", choices=LIGHT_SAMPLERS,
                   help="how next-event estimation picks a light: tree (by what it can send "
                        "to the shading point), power, or auto (the tree from 3 lights on, or 2 "
                        "with a point light); "
                        "default: the scene's render.lightSampler (auto)")
    p.add_argument("--exposure", type=_exposure, metavar="EV",
                   help="exposure of the PNG in stops (x 2^EV before the tone curve); "
                        "default: the scene's render.exposure (0). EXR/HDR/NPY stay linear")
    p.add_argument("--tonemap", choices=TONEMAPS,
                   help="tone curve of the PNG: clamp (none), aces (Narkowicz's ACES fit) or "
                        "agx (Blender's AgX); default: the scene's render.tonemap (clamp)")
    p.add_argument("--reference", metavar="IMAGE",
                   help="reference image (.npy, .hdr, .exr): print elapsed s, spp and relMSE "
                        "after each pass and write them as CSV (see --reference-csv)")
    p.add_argument("--reference-csv", metavar="PATH",
                   help="where the relMSE table goes (default: OUTPUT_STEM.relmse.csv)")
    p.add_argument("--pixel", metavar="X,Y", help="python backend: render only this pixel")
    p.add_argument("--preview", nargs="?", const=PREVIEW_PORT, type=_integer(0, 65535),
                   metavar="PORT",
                   help=f"serve a live preview page at http://127.0.0.1:PORT/ (default "
                        f"{PREVIEW_PORT}; 0: any free port): the image as it converges, "
                        "spp, samples/s, ETA, relMSE with --reference, a pass selector "
                        "and exposure and tone-curve controls. After the render the page "
                        "stays until Ctrl-C")
    p.add_argument("--preview-host", default="127.0.0.1", metavar="ADDRESS",
                   help="the address the preview listens on (default 127.0.0.1: this "
                        "machine only; 0.0.0.0 shows it to the network, without any "
                        "authentication)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--allow-missing", action="store_true",
                   help="thesis scene folders: render with defaults for missing files "
                        "(objects left out, textures at their default values, a grey "
                        "environment for a missing HDRI), with a warning")
    p.add_argument("--debug", action="store_true",
                   help="show the Python traceback of an error")
    return p


# ---------------------------------------------------------------------------------------
# Signals: SIGINT, SIGTERM and SIGHUP all stop the render after saving what is done.

class StopSignals:
    """While active, a stop signal raises :class:`Interrupted` (the render loop ends and
    saves); inside :meth:`deferred` (a save in progress) it is only recorded and raised
    when the save is complete, so no save is ever cut short."""

    def __init__(self):
        self.previous = {}
        self.defer = 0
        self.pending = None
        self.raised = None        # the last signal raised as Interrupted (see check)
        self.unraisable_hook = None
        self.stopping = False        # a stop signal has been raised in this run

    def __enter__(self):
        for s in STOP_SIGNALS:
            try:
                self.previous[s] = signal.signal(s, self._handler)
            except ValueError:       # not the main thread: leave the handlers alone
                break
        self.unraisable_hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        return self

    def __exit__(self, *exc):
        for s, h in self.previous.items():
            signal.signal(s, h)
        if not self.stopping:
            # (after a stop, finalisers that run as the process exits, such as the garbage
            # collector's, stay quiet too)
            sys.unraisablehook = self.unraisable_hook
        return False

    def _handler(self, signum, frame):
        if self.defer:
            self.pending = self.pending or signum
        else:
            self.raised = signum
            self.stopping = True
            raise Interrupted(signum)

    def _unraisable(self, info):
        """A signal that arrives while Python runs a finaliser (Numba's compiler disposes
        of LLVM objects in __del__) raises there, where Python swallows the exception and
        prints it: keep it quiet; check() raises it again. Once a stop signal has been
        raised, a finaliser's error is its consequence (an LLVM object whose constructor
        the signal cut short fails in __del__: llvmlite's 'PipelineTuningOptions' has no
        '_as_parameter_'), so it is kept quiet too: the stop is reported in one line."""
        if not (isinstance(info.exc_value, Interrupted) or self.stopping):
            self.unraisable_hook(info)

    def check(self):
        """Raise a stop signal that was raised inside a finaliser and swallowed there."""
        if self.raised:
            signum, self.raised = self.raised, None
            raise Interrupted(signum)

    @contextlib.contextmanager
    def deferred(self, raise_after=True):
        """A block no stop signal interrupts; one that arrived meanwhile is raised after
        it (if ``raise_after`` and the block succeeded), or left to the caller."""
        self.defer += 1
        try:
            yield
        finally:
            self.defer -= 1
        if self.pending and raise_after and not self.defer:
            pending, self.pending = self.pending, None
            self.stopping = True
            raise Interrupted(pending)


# ---------------------------------------------------------------------------------------
# Outputs

def _check_writable_folder(path, flag):
    """Fail before rendering if ``path`` cannot be written (a missing or read-only folder,
    a path that is a folder)."""
    if path == "":
        raise InputError(f"{flag}: empty path")
    if os.path.isdir(path):
        raise InputError(f"{flag} {path}: is a folder (give a file name)")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(f"{flag} {path}: folder {folder} does not exist")
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".pt-render-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise InputError(f"{flag} {path}: cannot write in {folder} "
                         f"({e.strerror or e})") from None


def _fallback_targets(targets):
    """The same file names in the first folder where they can be written: the temporary
    folder, then the current one, then home."""
    seen = {os.path.dirname(os.path.abspath(p)) for p in targets}
    for folder in (tempfile.gettempdir(), os.getcwd(), os.path.expanduser("~")):
        folder = os.path.abspath(folder)
        if folder in seen or not os.path.isdir(folder):
            continue
        seen.add(folder)
        stem = f"pt-render-{os.getpid()}-"
        yield [os.path.join(folder, stem + os.path.basename(p)) for p in targets]


class Saver:
    """Writes the image (and its float twin beside a PNG) as one unit; a periodic save that
    fails warns and is retried at the next refresh; the final save falls back to another
    folder and says where."""

    def __init__(self, targets, signals, warn, display=None, state=None):
        self.targets = targets
        self.signals = signals
        self.warn = warn
        self.display = display       # (exposure, tone curve) of 8-bit files
        self.last_error = None
        self.state = state           # (path, make(film) -> RenderState) or None

    def _write_state(self, film):
        if self.state is not None and film is not None:
            from .resume import save
            save(self.state[0], self.state[1](film))

    def periodic(self, image, film=None):
        try:
            with self.signals.deferred():
                write_images(self.targets, image, self.display)
                self._write_state(film)
            self.last_error = None
        except OSError as e:
            message = f"could not save {self.targets[0]} ({e.strerror or e})"
            if message != self.last_error:
                self.warn(f"{message}; rendering goes on and the next refresh retries")
            self.last_error = message

    def final(self, image, film=None):
        """The targets written, or raises OutputError after saving elsewhere if it can."""
        with self.signals.deferred(raise_after=False):
            try:
                write_images(self.targets, image, self.display)
                try:
                    self._write_state(film)
                except OSError as e:
                    self.warn(f"could not save the render state {self.state[0]} "
                              f"({e.strerror or e}); the image was written")
                return self.targets
            except OSError as e:
                first = e
            tried = []
            for alt in _fallback_targets(self.targets):
                try:
                    write_images(alt, image, self.display)
                except OSError:
                    tried.append(os.path.dirname(alt[0]))
                    continue
                raise OutputError(f"cannot write {self.targets[0]} ({first.strerror or first}); "
                                  f"the image was saved to {' and '.join(alt)} instead")
            raise OutputError(f"cannot write {self.targets[0]} ({first.strerror or first}); "
                              f"nothing could be saved (also tried {', '.join(tried) or 'no other folder'})")


# ---------------------------------------------------------------------------------------
# The command

def _one_line_warning(message, category, filename, lineno, line=None):
    """Library warnings as one line each (the source line is noise to a user)."""
    return f"pt-render: warning: {category.__name__}: {' '.join(str(message).split())}\n"


def main(argv=None):
    args = build_parser().parse_args(argv)
    import warnings
    format_warning = warnings.formatwarning
    if not args.debug:
        warnings.formatwarning = _one_line_warning
    try:
        code = _main(args)
    finally:
        warnings.formatwarning = format_warning
    if argv is None and _EARLY_INTERRUPT[0] and not getattr(args, "ray", None):
        # A signal that stopped Numba's compiler midway can leave LLVM's objects in a
        # state that the interpreter's teardown frees twice (seen under load: "double
        # free detected", exit -6 instead of 130). Nothing is left to write or clean up
        # before the first pass: leave without the teardown.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


# set when a render was interrupted before its first pass (during compilation)
_EARLY_INTERRUPT = [False]


def _main(args):
    scenes = args.scene
    if len(scenes) > 1:
        for flag, given in (("--resume", args.resume), ("--reference", args.reference),
                            ("--preview", args.preview is not None),
                            ("--pixel", args.pixel)):
            if given:
                print(f"pt-render: error: {flag} is for one scene, not a batch of "
                      f"{len(scenes)}", file=sys.stderr)
                return EXIT_INPUT
        if args.output is not None and "{name}" not in args.output:
            print("pt-render: error: --output for a batch of scenes needs '{name}' (e.g. "
                  "-o renders/{name}.png), or leave it out", file=sys.stderr)
            return EXIT_INPUT
    codes = []
    with StopSignals() as signals:
        try:
            for i, path in enumerate(scenes):
                if len(scenes) > 1:
                    print(f"pt-render: scene {i + 1} of {len(scenes)}: {path}",
                          file=sys.stderr)
                code = _one(args, path, signals)
                codes.append(code)
                if code >= 128:           # stopped by a signal: the batch ends
                    break
        finally:
            if args.ray:
                try:
                    from .cluster import shutdown
                    shutdown()
                except Exception:         # the runtime is gone already
                    pass
    if len(scenes) > 1:
        failed = [p for p, c in zip(scenes, codes) if c != EXIT_OK]
        print(f"pt-render: batch: {len(codes) - len(failed)} of {len(scenes)} scenes "
              f"rendered" + (f"; not: {', '.join(failed)}" if failed else ""),
              file=sys.stderr)
    return max(codes, key=lambda c: (c >= 128, c)) if codes else EXIT_OK


def _one(args, scene_path, signals):
    """Render one scene of the command line; its exit code."""
    try:
        return _render(args, scene_path, signals)
    except Interrupted as e:
        _EARLY_INTERRUPT[0] = True
        print(f"pt-render: interrupted ({signal.Signals(e.signum).name}) before the first "
              "pass; nothing written", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        _EARLY_INTERRUPT[0] = True
        print("pt-render: interrupted before the first pass; nothing written",
              file=sys.stderr)
        return 128 + signal.SIGINT
    except (SceneError, InputError) as e:
        return _fail(e, args, EXIT_INPUT)
    except OutputError as e:
        return _fail(e, args, EXIT_IO)
    except MemoryError as e:
        return _fail(f"out of memory ({e or 'allocation failed'}): lower the resolution "
                     "or the size of the scene's textures and meshes", args, EXIT_INPUT)
    except Exception as e:
        return _fail(f"internal error: {type(e).__name__}: {_one_line(e, 300)} (a bug in "
                     "pt-render: please report it with the scene; --debug shows the "
                     "traceback)", args, EXIT_INTERNAL)


def _one_line(e, limit=None):
    text = " ".join(str(e).split())
    if limit and len(text) > limit:     # a library's message may be a page long
        text = text[:limit] + "..."
    return text


def _fail(error, args, code):
    if getattr(args, "debug", False):
        traceback.print_exc()
    message = error if isinstance(error, str) else _one_line(error)
    print(f"pt-render: error: {message}", file=sys.stderr)
    return code


def _render(args, scene_path, signals):
    log = sys.stderr
    name = os.path.splitext(os.path.basename(scene_path.rstrip("/")))[0]
    state = None
    if args.resume:
        from .resume import StateError, load, state_path
        try:
            state = load(state_path(args.resume))
        except StateError as e:
            raise InputError(f"--resume: {e}") from None
    output = args.output
    if output is None:
        output = args.resume if args.resume and not args.resume.endswith(".state.npz") \
            else name + ".png"
    output = output.replace("{name}", name)
    ext = os.path.splitext(output)[1].lower()
    if output == "":
        raise InputError("--output: empty path")
    if ext not in ALL_FORMATS:
        raise InputError(f"--output {output}: unknown image format {ext!r} "
                         f"(use {', '.join(ALL_FORMATS)})")
    if args.denoise:
        from .denoise import check_available
        check_available()
    from .api import load_scene, output_files
    from .api import render as render_scene
    # what each file holds: "image" (denoised with --denoise), "raw", "albedo", "normal"
    targets, kinds = output_files(output, denoised=args.denoise, aovs=args.aovs)
    for t in targets:
        _check_writable_folder(t, "--output")
    csv_path = None
    if args.reference:
        csv_path = args.reference_csv or os.path.splitext(output)[0] + ".relmse.csv"
        _check_writable_folder(csv_path, "--reference-csv")

    from .memory import check_film
    t0 = time.perf_counter()
    scene = load_scene(scene_path, allow_missing=args.allow_missing, camera=args.camera,
                       environment=args.env, params=dict(args.define) or None,
                       _overrides={"resolution": args.resolution, "sampler": args.sampler,
                                   "light_sampler": args.light_sampler,
                                   "exposure": args.exposure, "tonemap": args.tonemap},
                       _check=lambda desc: check_film(*desc.camera.resolution, args.backend))
    signals.check()
    load_seconds = time.perf_counter() - t0
    for w in scene.warnings:
        print(f"pt-render: warning: {w}", file=log)

    reference = None
    if args.reference:
        reference = _read_reference(args.reference, scene)

    options = {}
    if args.pixel:
        if args.backend != "python":
            raise InputError("--pixel needs --backend python")
        try:
            x, y = (int(v, 10) for v in args.pixel.split(","))
        except ValueError:
            raise InputError(f"--pixel: expected X,Y, got {args.pixel!r}") from None
        if not (0 <= x < scene.width and 0 <= y < scene.height):
            raise InputError(f"--pixel {x},{y} is outside the {scene.width}x{scene.height} "
                             "image")
        options["pixels"] = ((x, y),)

    spp = args.spp if args.spp is not None else (None if args.time else scene.spp)
    time_limit = args.time
    from .backends import cuda_available
    backend_name = args.backend
    if args.devices and args.ray:
        raise InputError("--devices and --ray: give one of them (--ray uses the cluster's "
                         "GPUs)")
    devices = None
    if args.devices:
        if backend_name not in ("auto", "cuda"):
            raise InputError(f"--devices is for CUDA GPUs, not --backend {backend_name}")
        from .distribute import local_devices
        devices = local_devices(args.devices)
        backend_name = "cuda"
    if args.ray and backend_name == "python":
        raise InputError("--ray runs the compiled backends, not --backend python")
    if backend_name == "auto":
        backend_name = "cuda" if cuda_available() else "cpu"
    where = backend_name
    if devices:
        where = f"cuda on {len(devices)} GPUs ({','.join(map(str, devices))})"
    elif args.ray:
        where = f"Ray cluster {args.ray}"
    dn_device = "cpu"
    if args.denoise:
        from .denoise import resolve_device
        dn_device = resolve_device(args.denoise_device, backend_name)
    print(f"pt-render: {scene_path}: {scene.width}x{scene.height}, {scene.n_triangles} "
          f"triangles, loaded in {load_seconds:.2f} s (BVH "
          f"{scene.compiled.timings['bvh_build']:.2f} s); backend {where}; features "
          f"{', '.join(k for k, v in scene.features._asdict().items() if v) or 'none'}",
          file=log)

    # The saved accumulation (resume): checked against this scene, continued from
    max_bounces = (args.max_bounces if args.max_bounces is not None
                   else scene.compiled.max_bounces)
    seed = args.seed
    state_file = None
    saved_state = None           # (path, film -> RenderState) for the saver
    if state is not None or not args.no_state:
        from .resume import RenderState, scene_hash, state_path
        state_file = state_path(output)
        _check_writable_folder(state_file, "--output")
        digest = scene_hash(scene.compiled, max_bounces, scene.compiled.rr_depth)
        seconds_before = 0.0
        if state is not None:
            got = state.film
            if (got.width, got.height) != (scene.width, scene.height):
                raise InputError(f"--resume {args.resume}: the saved render is "
                                 f"{got.width}x{got.height}, this one {scene.width}x"
                                 f"{scene.height} (give the same --resolution)")
            if args.adaptive and got.spp > 0 and got.sum_b is None:
                raise InputError(f"--resume {args.resume}: the saved render was not "
                                 "adaptive, so it cannot go on with --adaptive (resume it "
                                 "without --adaptive)")
            if digest != state.scene_hash:
                raise InputError(f"--resume {args.resume}: the saved render is of another "
                                 "scene, or of other settings (resolution, sampler, "
                                 "--max-bounces, or a changed file the scene reads)")
            if seed is not None and seed != state.seed:
                raise InputError(f"--resume {args.resume}: it was rendered with seed "
                                 f"{state.seed}, not {seed} (leave --seed out)")
            seed = state.seed
            seconds_before = state.seconds
            if time_limit is not None:
                time_limit -= seconds_before      # --time counts from the first start
            footprint = state.footprint_spp
            print(f"pt-render: resuming {state.film.spp} spp ({seconds_before:.1f} s) from "
                  f"{state_path(args.resume)}", file=log)
        else:
            footprint = spp if spp is not None else scene.spp
        adaptive_target = args.adaptive or (state.adaptive if state is not None else 0.0)

        def make_state(film):
            return RenderState(film, scene.seed if seed is None else seed, digest,
                               footprint if scene.features.mipmaps else 0,
                               seconds_before + elapsed_now[0], adaptive_target or 0.0)
        if not args.no_state:
            saved_state = (state_file, make_state)
    elapsed_now = [0.0]

    from .progress import Progress
    compile_seconds = [0.0]

    # "compiling kernels" only when it takes a while: a run whose kernels come from the
    # disk cache is ready in well under a second and says nothing about compiling
    compile_notice = []

    def on_stage(stage, seconds):
        if stage == "compiling" and not args.quiet:
            notice = threading.Timer(COMPILE_NOTICE_SECONDS, lambda: print(
                "pt-render: compiling kernels for this scene's features (the first time "
                "only: cached on disk)...", file=log, flush=True))
            notice.daemon = True
            notice.start()
            compile_notice.append(notice)
        signals.check()
        if stage == "compiled":
            compile_seconds[0] = seconds
            for notice in compile_notice:
                notice.cancel()
            if not args.quiet and seconds >= COMPILE_NOTICE_SECONDS:
                print(f"pt-render: kernels ready in {seconds:.2f} s", file=log)
            progress.start_sampling()
        if stage == "aovs" and not args.quiet:
            from .denoise import AOV_SPP
            print(f"pt-render: albedo and normal images ({AOV_SPP} spp) in {seconds:.2f} s",
                  file=log)

    if state is not None and time_limit is not None and time_limit <= 0:
        # a resumed render already past its --time: nothing more to render
        spp, time_limit = state.film.spp, None
    progress = Progress(spp, time_limit, scene.width * scene.height, quiet=args.quiet,
                        stream=log, start_spp=0 if state is None else state.film.spp)
    saver = Saver(targets, signals, lambda m: progress.write(f"pt-render: warning: {m}"),
                  scene.display, saved_state)
    denoise_seconds = []
    preview = None
    if args.preview is not None:
        from .preview import PreviewServer
        preview = PreviewServer(args.preview_host, args.preview, scene.display,
                                target_spp=spp, time_limit=time_limit,
                                denoise=args.denoise)
        print(f"pt-render: preview at {preview.url} ({preview.reach}; the render never "
              "waits for it)", file=log)

    def outputs(image, aovs):
        """The image of each target (a periodic save): denoised, raw or auxiliary."""
        if kinds == ["image"] * len(kinds):
            return image
        shown = image
        if args.denoise:
            from .denoise import denoise
            t_dn = time.perf_counter()
            shown = denoise(image, aovs, dn_device)
            denoise_seconds.append(time.perf_counter() - t_dn)
        pick = dict(aovs or {}, image=shown, raw=image)
        return [pick[k] for k in kinds]
    rows = []
    next_write = [1.0]

    def on_pass(p):
        film, elapsed = p.film, p.elapsed
        elapsed_now[0] = elapsed
        signals.check()
        progress.update(film.spp, elapsed)
        err = None
        if reference is not None:
            err = relmse(film.image(), reference)
            rows.append((elapsed, film.spp, err))
            progress.write(f"{elapsed:10.3f} s {film.spp:8d} spp  relMSE {err:.6g}")
        if preview is not None:
            preview.publish(p, relmse=err)
        if elapsed >= next_write[0]:
            saver.periodic(outputs(film.image(), p.aovs), film)
            next_write[0] = elapsed * 2   # refresh at growing intervals

    if reference is not None:
        progress.write(f"{'elapsed':>12} {'spp':>12}  relMSE")
    try:
        result = render_scene(scene, spp=spp, time=time_limit, seed=seed,
                              backend=backend_name, callback=on_pass,
                              max_bounces=args.max_bounces, adaptive=args.adaptive,
                              aovs=args.aovs, denoise=args.denoise,
                              denoise_device=dn_device, devices=devices,
                              ray=args.ray, ray_workers=args.ray_workers, resume=state,
                              _backend_options=options, _on_stage=on_stage)
    except BaseException:
        if preview is not None:
            preview.close()
        raise
    finally:
        progress.close()
    film = result.film
    if film.spp == 0:
        if preview is not None:
            preview.close()
        if result.interrupted:
            print("pt-render: stopped before the first pass; no image written", file=log)
            return 128 + result.signal
        raise OutputError("no samples were rendered; no image written")
    if result.raw is not None:
        denoise_seconds.append(result.denoise_seconds)
    # the final images are the result's (denoised once, by render)
    elapsed_now[0] = result.seconds
    written = saver.final([image for _, image in result.outputs(output, aovs=args.aovs)],
                          film)
    if args.adaptive:
        done = float((film.count < film.spp).mean())
        print(f"pt-render: adaptive: {film.count.mean():.1f} spp per pixel on average "
              f"(min {film.count.min()}, max {film.count.max()}); {100 * done:.1f} % of the "
              f"pixels stopped (target image relMSE {args.adaptive:g})", file=log)
    if denoise_seconds:
        print(f"pt-render: denoised {len(denoise_seconds)} time(s), the last in "
              f"{denoise_seconds[-1]:.2f} s (Open Image Denoise, "
              f"{'GPU' if dn_device == 'cuda' else 'CPU'})", file=log)
    if reference is not None:
        try:
            with signals.deferred(raise_after=False), open(csv_path, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["elapsed_s", "spp", "relmse"])
                w.writerows(rows)
        except OSError as e:
            raise OutputError(f"--reference-csv {csv_path}: cannot write "
                              f"({e.strerror or e}); the image was written") from None
        print(f"pt-render: relMSE table written to {csv_path}", file=log)
    stats = result.stats
    # (adaptive: pixels stop at different counts; film.spp is the most any took)
    spp_text = (f"{film.count.mean():.1f} spp on average (at most {film.spp})"
                if args.adaptive else f"{film.spp} spp")
    print(f"pt-render: {spp_text} in {result.seconds:.2f} s (compile "
          f"{compile_seconds[0]:.2f} s): {stats['paths_per_second'] / 1e6:.3f} M camera "
          f"paths/s, {stats['rays_per_second'] / 1e6:.3f} M rays/s; wrote "
          f"{' and '.join(written)}", file=log)
    if result.shares:
        print("pt-render: samples per worker: " + ", ".join(
            f"{i}: {100 * share:.1f} %" for i, share in enumerate(result.shares)), file=log)
    if film.nonfinite:
        print(f"pt-render: warning: {film.nonfinite} of {film.camera_rays} samples were NaN "
              "or infinite and were left out of the image (please report this scene)",
              file=log)
    if result.interrupted:
        if preview is not None:
            preview.close()
        print(f"pt-render: interrupted ({signal.Signals(result.signal).name}); the image "
              "holds the samples done so far", file=log)
        return 128 + result.signal
    if preview is not None:
        preview.finish(film, result.seconds)
        print(f"pt-render: done; the preview stays at {preview.url} until Ctrl-C", file=log)
        try:
            preview.wait()
        except KeyboardInterrupt:
            pass
        finally:
            preview.close()
    return EXIT_OK


def _read_reference(path, scene):
    import numpy as np
    try:
        reference = read_image(path)
    except FileNotFoundError:
        raise InputError(f"--reference {path}: file not found") from None
    except Exception as e:    # each codec reports a damaged file with its own type
        raise InputError(f"--reference {path}: cannot read the image "
                         f"({type(e).__name__}: {_one_line(e, 300)})") from None
    if reference.shape[:2] != (scene.height, scene.width):
        raise InputError(f"--reference {path}: size {reference.shape[1]}x"
                         f"{reference.shape[0]} differs from the image's "
                         f"{scene.width}x{scene.height}")
    if not np.isfinite(reference).all():
        raise InputError(f"--reference {path}: contains NaN or infinite values")
    return reference


if __name__ == "__main__":
    sys.exit(main())
