"""Helpers shared by the tests: small scenes made in code, statistics, render shortcuts."""
import json
import math
import os

import numpy as np

from pathtracer.backends import make_backend
from pathtracer.kernels.layout import P_FIELDS
from pathtracer.kernels.rng import path_key, sample_1d, sample_sobol
from pathtracer.progressive import render
from pathtracer.scene.geometry import uv_sphere


def write_scene(tmp_path, scene, name="scene.json"):
    path = os.path.join(str(tmp_path), name)
    with open(path, "w") as f:
        json.dump(scene, f)
    return path


def _orient_outward(verts, faces):
    """Reorder each triangle of a mesh that is star-shaped about the origin so that its
    counter-clockwise front faces away from the origin."""
    v = np.array(verts, float)
    f = np.array(faces)
    for k, (a, b, c) in enumerate(f):
        n = np.cross(v[b] - v[a], v[c] - v[a])
        if np.dot(n, v[a] + v[b] + v[c]) < 0:
            f[k] = [a, c, b]
    return v.tolist(), f.tolist()


def box_mesh(half=1.0):
    """A closed cube [-half, half]^3: 8 vertices, 12 triangles facing outward."""
    v = [[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)]
    # vertex index = 4*ix + 2*iy + iz
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = []
    for a, b, c, d in quads:
        faces += [[a, b, c], [a, c, d]]
    return _orient_outward(v, faces)


def sphere_mesh(n_theta=12, n_phi=24, radius=1.0):
    """A closed UV sphere, triangles facing outward, as JSON-ready lists."""
    v, f = uv_sphere(n_theta, n_phi, radius)
    return v.tolist(), f.tolist()


def furnace_scene(albedo, emission, max_bounces, res=(16, 16), mesh="sphere", spp=64):
    """Inside a closed object that emits Le (both sides) and reflects albedo a: every
    camera path sees L = Le * sum_{k=0}^{max_bounces} a^k exactly in expectation."""
    v, f = sphere_mesh() if mesh == "sphere" else box_mesh()
    return {
        "camera": {"resolution": list(res), "position": [0.1, -0.05, 0.02],
                   "lookAt": [0.3, 0.2, -1], "fov": 90},
        "render": {"spp": spp, "maxBounces": max_bounces},
        "materials": [{"name": "m", "type": "diffuse", "albedo": albedo,
                       "emission": emission, "twoSided": True}],
        "objects": [{"name": "shell", "vertices": v, "faces": f, "material": "m"}],
    }


def chi2_sf(x, k):
    """P(X > x) for X ~ chi-square with k degrees of freedom (Wilson-Hilferty; accurate to
    a few percent of the p-value for k >= 10, enough for thresholds like 1e-4)."""
    if x <= 0:
        return 1.0
    z = ((x / k) ** (1 / 3) - (1 - 2 / (9 * k))) / math.sqrt(2 / (9 * k))
    return 0.5 * math.erfc(z / math.sqrt(2))


def normal_two_sided_p(z):
    return math.erfc(abs(z) / math.sqrt(2))


def chi2_test(observed, expected, min_expected=5.0, alpha=1e-4):
    o = np.asarray(observed, float).ravel()
    e = np.asarray(expected, float).ravel()
    assert not np.any((e == 0) & (o > 0)), "samples where the pdf is zero"
    order = np.argsort(e)
    o, e = o[order], e[order]
    # pool the smallest cells until each pooled cell expects >= min_expected
    pooled_o, pooled_e, acc_o, acc_e = [], [], 0.0, 0.0
    for oi, ei in zip(o, e):
        acc_o += oi
        acc_e += ei
        if acc_e >= min_expected:
            pooled_o.append(acc_o)
            pooled_e.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0 and pooled_e:
        pooled_o[-1] += acc_o
        pooled_e[-1] += acc_e
    po, pe = np.array(pooled_o), np.array(pooled_e)
    stat = ((po - pe) ** 2 / pe).sum()
    p = chi2_sf(stat, len(pe) - 1)
    assert p > alpha, f"chi2 = {stat:.1f} with {len(pe) - 1} dof, p = {p:.2e}"


def run(scene, backend="cpu", spp=None, **kw):
    result = render(scene, make_backend(backend, scene), spp=spp, **kw)
    assert result.film.nonfinite == 0, "NaN or Inf samples"
    return result


def mean_and_se(img):
    """Image mean per channel and its standard error (pixels are independent)."""
    px = img.reshape(-1, 3).astype(np.float64)
    return px.mean(0), px.std(0, ddof=1) / np.sqrt(len(px))


def principled_params(**kw):
    """A principled parameter tuple (layout P_FIELDS) with defaults, by field name."""
    d = dict(r=0.8, g=0.5, b=0.3, roughness=0.5, metallic=0.0, eta=1.5, spec_tint=0.0,
             anisotropic=0.0, sheen=0.0, sheen_tint=0.0, clearcoat=0.0, clearcoat_gloss=0.0,
             flatness=0.0, transmission=0.0)
    for k, v in kw.items():
        assert k in d, k
        d[k] = v
    return tuple(np.float32(d[k]) for k in P_FIELDS)


GOLDEN = [(0, 0, 0, 0), (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1),
          (65535, 1023, 17, 123456789)]


def golden_python_values():
    """The GOLDEN stream values computed by the interpreted kernel code."""
    return [float(sample_1d(path_key(p, s, seed), d)) for p, s, d, seed in GOLDEN]


# (pixel key, sample, dimension) of the sobol sampler's golden values
GOLDEN_SOBOL = [(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 2, 2), (0, 3, 3), (12345, 0, 4),
                (12345, 7, 5), (2**32 - 1, 1000, 31), (987654321, 2**31 - 1, 4001)]


def golden_sobol_python_values():
    """The GOLDEN_SOBOL values computed by the interpreted kernel code."""
    return [float(sample_sobol(np.uint64(k), i, d)) for k, i, d in GOLDEN_SOBOL]
