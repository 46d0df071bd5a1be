"""Live preview: a small HTTP server (the standard library's) that shows a render as it
converges, like the thesis renderer's window.

The render thread only *publishes* a snapshot after each pass (a copy of the mean image and
the per-pixel sample counts, under a lock held for a reference swap); everything else,
tone mapping, PNG encoding and denoising for the page, happens in the server's threads
when the browser asks. So the render never waits for the browser, and a browser that is
slow or gone costs nothing.

Endpoints: ``/`` the page; ``/status.json`` spp, samples/s, ETA, relMSE (with
``--reference``) and the passes on offer; ``/image.png?pass=P&exposure=EV&tonemap=T`` the
image of pass P: ``beauty``, ``denoised`` and ``albedo`` / ``normal`` (when the render makes
the auxiliary images), ``samples`` (per-pixel sample count, white = the most).
"""
import ipaddress
import json
import math
import socket
import threading
import time
import urllib.parse
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

from . import limits
from .film import encode, to_display
from .tonemap import TONEMAPS


class _Snapshot:
    def __init__(self, image, count, spp, elapsed, rate, relmse, aovs):
        self.image, self.count, self.spp = image, count, spp
        self.elapsed, self.rate, self.relmse, self.aovs = elapsed, rate, relmse, aovs


class PreviewServer:
    """Serves the preview of one render on ``host``:``port`` (0: a free port) from a
    background thread; ``url`` is where to point a browser."""

    def __init__(self, host="127.0.0.1", port=0, display=(0.0, "clamp"), target_spp=None,
                 time_limit=None, denoise=False):
        self.display = display
        self.target_spp = target_spp
        self.time_limit = time_limit
        self.denoise = denoise
        self.lock = threading.Lock()
        self.snapshot = None
        self.done = False
        self.started = time.time()
        self._denoised = (None, None)     # (spp, image): one denoise per published pass
        handler = type("Handler", (_Handler,), {"preview": self})
        try:
            family = socket.AF_INET6 if ":" in host else socket.AF_INET
            server_class = type("Server", (ThreadingHTTPServer,),
                                {"address_family": family, "daemon_threads": True})
            self.server = server_class((host, port), handler)
        except OSError as e:
            from .errors import InputError
            raise InputError(f"--preview: cannot listen on {host}:{port} "
                             f"({e.strerror or e})") from None
        self.host, self.port = host, self.server.server_address[1]
        shown = f"[{host}]" if ":" in host else host
        self.url = f"http://{shown}:{self.port}/"
        self.reach = "this machine only" if _is_loopback(host) else \
            "open to other machines, without authentication"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True,
                                       name="pt-render-preview")
        self.thread.start()

    # -- the render's side: cheap
    def publish(self, progress, relmse=None):
        """After a pass (``progress``: api.Progress): keep a copy of the image."""
        film = progress.film
        snap = _Snapshot(film.image(), film.count.copy(), film.spp, progress.elapsed,
                         progress.samples_per_second, relmse, progress.aovs)
        with self.lock:
            self.snapshot = snap

    def finish(self, film, seconds):
        with self.lock:
            self.done = True

    def wait(self):
        """Block until interrupted (Ctrl-C) while the page stays served."""
        while self.thread.is_alive():
            self.thread.join(0.5)

    def close(self):
        self.server.shutdown()
        self.server.server_close()

    # -- the server's side
    def status(self):
        with self.lock:
            s, done = self.snapshot, self.done
        out = {"spp": 0, "target_spp": self.target_spp, "time_limit": self.time_limit,
               "elapsed": 0.0, "samples_per_second": 0.0, "eta": None, "relmse": None,
               "done": done, "passes": self.passes(s), "exposure": self.display[0],
               "tonemap": self.display[1], "tonemaps": list(TONEMAPS)}
        if s is not None:
            out.update(spp=s.spp, elapsed=s.elapsed, samples_per_second=s.rate,
                       relmse=s.relmse, width=s.image.shape[1], height=s.image.shape[0])
            fractions = []
            if self.target_spp:
                fractions.append(s.spp / self.target_spp)
            if self.time_limit:
                fractions.append(s.elapsed / self.time_limit)
            f = min(1.0, max(fractions)) if fractions else 0.0
            out["eta"] = 0.0 if done else (s.elapsed * (1 - f) / f if f > 0 else None)
        return out

    def passes(self, snap=None):
        names = ["beauty"]
        if snap is not None and snap.aovs is not None:
            if self.denoise or _have_denoiser():
                names.append("denoised")
            names += ["albedo", "normal"]
        return names + ["samples"]

    def image(self, name, exposure, tonemap):
        """PNG bytes of pass ``name``, or None before the first pass."""
        with self.lock:
            s = self.snapshot
        if s is None:
            return None
        if name == "beauty":
            return encode(s.image, ".png", (exposure, tonemap))
        if name == "denoised" and s.aovs is not None:
            spp, img = self._denoised
            if spp != s.spp:
                from .denoise import denoise
                img = denoise(s.image, s.aovs)
                self._denoised = (s.spp, img)
            return encode(img, ".png", (exposure, tonemap))
        if name == "albedo" and s.aovs is not None:
            return encode(s.aovs["albedo"], ".png")
        if name == "normal" and s.aovs is not None:   # [-1, 1] shown as [0, 1], not tone mapped
            return _png(np.clip(s.aovs["normal"] * 0.5 + 0.5, 0, 1))
        if name == "samples":
            count = s.count.astype(np.float32)
            return _png(count / max(float(count.max()), 1.0))
        raise KeyError(name)


def _png(values):
    """PNG of display values in [0, 1] (grey H x W or H x W x 3), without a curve."""
    import imageio.v3 as iio
    v = np.round(np.clip(values, 0, 1) * 255).astype(np.uint8)
    return iio.imwrite("<bytes>", v, extension=".png")


def _have_denoiser():
    try:
        import pyoidn  # noqa: F401
        return True
    except Exception:
        return False


def _is_loopback(host):
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Handler(BaseHTTPRequestHandler):
    preview = None          # the PreviewServer (set on a subclass per server)
    server_version = "pt-render-preview"

    def log_message(self, format, *args):     # no access log on the render's terminal
        pass

    def _send(self, code, body, ctype):
        self.send_response(code)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def do_GET(self):
        url = urllib.parse.urlsplit(self.path)
        query = urllib.parse.parse_qs(url.query)
        try:
            if url.path in ("/", "/index.html"):
                return self._send(200, PAGE.encode(), "text/html; charset=utf-8")
            if url.path == "/status.json":
                return self._send(200, json.dumps(self.preview.status()).encode(),
                                  "application/json")
            if url.path == "/image.png":
                name = query.get("pass", ["beauty"])[0]
                try:
                    exposure = float(query.get("exposure", [self.preview.display[0]])[0])
                except ValueError:
                    exposure = float("nan")
                tonemap = query.get("tonemap", [self.preview.display[1]])[0]
                if not (math.isfinite(exposure) and abs(exposure) <= limits.MAX_EXPOSURE):
                    return self._send(400, b"exposure: a number of stops in [-64, 64]",
                                      "text/plain")
                if tonemap not in TONEMAPS:
                    return self._send(400, f"tonemap: one of {', '.join(TONEMAPS)}".encode(),
                                      "text/plain")
                try:
                    png = self.preview.image(name, exposure, tonemap)
                except KeyError:
                    return self._send(404, f"no pass {name!r}".encode(), "text/plain")
                if png is None:
                    return self._send(503, b"no pass rendered yet", "text/plain")
                return self._send(200, png, "image/png")
            return self._send(404, b"not found", "text/plain")
        except (BrokenPipeError, ConnectionResetError):
            pass          # the browser went away
        except Exception as e:     # a bug: one line to the browser, no traceback on the
            try:                   # render's terminal (socketserver would print one)
                self._send(500, f"pt-render preview: {type(e).__name__}: {e}".encode(),
                           "text/plain")
            except OSError:
                pass


PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>pt-render preview</title>
<style>
 body { background:#1d1f21; color:#ddd; font:14px system-ui,sans-serif; margin:0; }
 header { padding:8px 12px; background:#2b2d30; display:flex; gap:18px; align-items:center;
          flex-wrap:wrap; }
 header b { color:#fff; }
 label { display:flex; gap:6px; align-items:center; }
 #stats { font-variant-numeric:tabular-nums; }
 main { display:flex; justify-content:center; padding:12px; }
 img { height:calc(100vh - 84px); max-width:100%; object-fit:contain;
       image-rendering:pixelated; }
 #bar { height:3px; background:#5fa8ff; width:0; transition:width .3s; }
</style></head>
<body>
<header>
 <b>pt-render</b>
 <label>pass <select id="pass"></select></label>
 <label>exposure <input id="exposure" type="range" min="-8" max="8" step="0.25" value="0">
   <span id="ev">0</span> EV</label>
 <label>tone curve <select id="tonemap"></select></label>
 <span id="stats">waiting for the first pass...</span>
</header>
<div id="bar"></div>
<main><img id="image" alt="the render"></main>
<script>
const $ = (id) => document.getElementById(id);
let shown = "", loading = false, ready = false;
function fmt(s) {
  if (s === null || s === undefined) return "?";
  if (s < 60) return s.toFixed(1) + " s";
  return Math.floor(s / 60) + " min " + Math.round(s % 60) + " s";
}
function options(select, names) {
  const have = Array.from(select.options).map(o => o.value).join();
  if (have === names.join()) return;
  const keep = select.value;
  select.innerHTML = "";
  for (const n of names) select.add(new Option(n, n));
  if (names.includes(keep)) select.value = keep;
}
function refresh(st) {
  const key = [st.spp, $("pass").value, $("exposure").value, $("tonemap").value].join("/");
  if (key === shown || loading || st.spp === 0) return;
  loading = true;
  const img = new Image();
  img.onload = () => { $("image").src = img.src; shown = key; loading = false; };
  img.onerror = () => { loading = false; };
  img.src = "image.png?pass=" + $("pass").value + "&exposure=" + $("exposure").value +
            "&tonemap=" + $("tonemap").value + "&spp=" + st.spp;
}
let last = null;
async function poll() {
  try {
    const st = await (await fetch("status.json", {cache: "no-store"})).json();
    options($("pass"), st.passes);
    options($("tonemap"), st.tonemaps);
    if (!ready) { $("exposure").value = st.exposure; $("tonemap").value = st.tonemap;
                  ready = true; }
    $("ev").textContent = $("exposure").value;
    let text = st.spp + (st.target_spp ? " / " + st.target_spp : "") + " spp";
    if (st.spp > 0) text += " \u00b7 " + (st.samples_per_second / 1e6).toFixed(2) +
                           " M samples/s \u00b7 " + fmt(st.elapsed);
    if (st.done) text += " \u00b7 done";
    else if (st.eta !== null && st.spp > 0) text += " \u00b7 ETA " + fmt(st.eta);
    if (st.relmse !== null) text += " \u00b7 relMSE " + st.relmse.toPrecision(3);
    $("stats").textContent = text;
    const f = st.done ? 1 : (st.target_spp ? st.spp / st.target_spp :
              (st.time_limit ? st.elapsed / st.time_limit : 0));
    $("bar").style.width = (100 * Math.min(1, f)) + "%";
    last = st;
    refresh(st);
  } catch (e) {
    $("stats").textContent = "the render has ended (no answer from pt-render)";
  }
  setTimeout(poll, 500);
}
for (const id of ["pass", "exposure", "tonemap"])
  $(id).addEventListener("input", () => { $("ev").textContent = $("exposure").value;
                                          if (last) refresh(last); });
poll();
</script>
</body></html>
"""
