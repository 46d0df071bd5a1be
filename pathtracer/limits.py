"""The ranges every number must stay within to reach the kernels intact.

The kernels compute in float32 and index pixels, samples and seeds with 32-bit integers;
a value outside these ranges would overflow there (an infinite or NaN image, a repeated
random stream) rather than fail, so the loader and the command line refuse it with a
message that names the range.
"""
import numpy as np

FLOAT32_MAX = float(np.finfo(np.float32).max)     # 3.4e38
# Scene coordinates after transforms (positions, camera): products of two coordinates
# (ray-triangle tests) stay inside float32.
MAX_COORDINATE = 1e18
# Emitted radiance (emission x texture x scale, point-light intensity, environment):
# path weights, light-sampling densities and per-pass sums multiply it by up to ~1e20
# before it reaches the float64 film; this keeps those products finite in float32.
MAX_RADIANCE = 1e16
# Reflectance-like colours (albedo and texture scales other than emission): up to 1 is
# physical; larger values are allowed (artistic gain) up to this bound.
MAX_REFLECTANCE = 1e3
# A conductor's complex index of refraction (eta, k per channel): measured metals stay
# below ~20; the bound keeps the Fresnel terms' squares and products finite in float32.
MAX_IOR = 1e4
MAX_SEED = 2 ** 32 - 1            # the RNG hashes 32-bit seeds, pixels and sample indices
MAX_SPP = 2 ** 31 - 1             # sample indices of one render stay below 2^31
MAX_BOUNCES = 1000
MAX_DIMENSION = 65536             # pixels per image side
MAX_PIXELS = 2 ** 30              # pixel indices are 32-bit on the GPU
MAX_PASS_SAMPLES = 2 ** 16        # samples per pixel in one pass (the progressive loop)
# The field of view: tan(fov / 2) within [1e-6, 1e6] (a few microdegrees to 179.9999
# degrees) keeps the camera's ray directions accurate in float32.
MIN_TAN_HALF_FOV = 1e-6
MAX_TAN_HALF_FOV = 1e6
MAX_UV = 1e6                       # |tile| and |offset| of textures
# Exposure (EV) of 8-bit outputs: 2^+-64 stays far inside float64 and float32 radiance.
MAX_EXPOSURE = 64.0
