"""CUDA backend: one thread per pixel, the scene arrays uploaded once."""
import functools

import numpy as np
from numba import cuda

from ..kernels.constants import STACK_SIZE
from ..kernels.integrator import SceneArrays, make_render_pixel

BLOCK = (16, 8)


@functools.lru_cache(maxsize=None)
def pass_kernel(features):
    render_pixel = make_render_pixel(features, "cuda")

    @cuda.jit(cache=True)
    def render_pass(out, stats, sample_start, n_samples, seed, max_bounces, rr_depth, scene):
        px, py = cuda.grid(2)
        if px < out.shape[1] and py < out.shape[0]:
            stack = cuda.local.array(STACK_SIZE, np.int32)
            render_pixel(px, py, sample_start, n_samples, seed, max_bounces, rr_depth, scene,
                         stack, out, stats)

    return render_pass


class CUDABackend:
    name = "cuda"

    def __init__(self, scene, block=BLOCK):
        self.scene = scene
        self.block = tuple(block)
        self.kernel = pass_kernel(scene.features)
        self.d_scene = SceneArrays(*[cuda.to_device(a) for a in scene.arrays])
        self.d_out = cuda.device_array((scene.height, scene.width, 3), np.float32)
        self.d_stats = cuda.device_array((scene.height, scene.width, 3), np.int32)
        self.out = cuda.pinned_array((scene.height, scene.width, 3), np.float32)
        self.stats = cuda.pinned_array((scene.height, scene.width, 3), np.int32)
        self.grid = ((scene.width + self.block[0] - 1) // self.block[0],
                     (scene.height + self.block[1] - 1) // self.block[1])

    def compile(self):
        self.render_pass(0, 0, 0, 0, 0)

    def launch(self, sample_start, n_samples, seed, max_bounces, rr_depth):
        """Start a pass without waiting (for timing the kernel alone)."""
        self.kernel[self.grid, self.block](self.d_out, self.d_stats, sample_start, n_samples,
                                           seed, max_bounces, rr_depth, self.d_scene)

    def render_pass(self, sample_start, n_samples, seed, max_bounces, rr_depth):
        self.launch(sample_start, n_samples, seed, max_bounces, rr_depth)
        self.d_out.copy_to_host(self.out)
        self.d_stats.copy_to_host(self.stats)
        return self.out, self.stats

    def ptx(self):
        """PTX of the compiled pass kernel (to check for float64 instructions)."""
        return "\n".join(self.kernel.inspect_asm().values())
