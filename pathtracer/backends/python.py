"""Interpreted backend: the kernel source run as plain Python (slow; for debugging)."""
import numpy as np

from ..kernels.constants import STACK_SIZE
from ..kernels.layout import AOV_WIDTH
from ..kernels.integrator import make_aov_pixel, make_render_pixel
from .base import Backend


class PythonBackend(Backend):
    name = "python"

    def __init__(self, scene, pixels=None):
        """``pixels``: optional list of (x, y) to render; other pixels stay black."""
        self.scene = scene
        self.render_pixel = make_render_pixel(scene.features, "python")
        self.pixels = pixels
        self.out = np.zeros((scene.height, scene.width, 3), np.float32)
        self.stats = np.zeros((scene.height, scene.width, 3), np.int32)

    def update(self, scene):
        """Render ``scene`` from now on (same features and image size)."""
        self.scene = scene

    def compile(self):
        pass

    def render_pass(self, sample_start, n_samples, seed, max_bounces, rr_depth, active=None):
        stack = np.empty(STACK_SIZE, np.int32)
        pixels = self.pixels or [(x, y) for y in range(self.scene.height)
                                 for x in range(self.scene.width)]
        self.out[:] = 0
        self.stats[:] = 0
        with np.errstate(all="ignore"):
            for px, py in pixels:
                if active is not None and not active[py, px]:
                    continue
                self.render_pixel(px, py, sample_start, n_samples, seed, max_bounces, rr_depth,
                                  self.scene.arrays, stack, self.out, self.stats)
        return self.out, self.stats

    def aovs(self, n_samples, seed):
        """The denoiser's albedo and normal images (float32 H x W x AOV_WIDTH, see aov_pixel)."""
        aov_pixel = make_aov_pixel(self.scene.features, "python")
        out = np.zeros((self.scene.height, self.scene.width, AOV_WIDTH), np.float32)
        stack = np.empty(STACK_SIZE, np.int32)
        pixels = self.pixels or [(x, y) for y in range(self.scene.height)
                                 for x in range(self.scene.width)]
        with np.errstate(all="ignore"):
            for px, py in pixels:
                aov_pixel(px, py, n_samples, seed, self.scene.arrays, stack, out)
        return out
