"""Mitsuba 3's own ``roughconductor`` evaluated at fixed directions, the table that
tests/test_conductor.py compares pt-render's conductor against (BSDF value and, for GGX,
whose sampler both share, the pdf).

    python -m tests.mitsuba_conductor_ref      # needs `pip install mitsuba==3.9.1`

Writes tests/references/conductor_mitsuba.npz: per case its parameters, 64 pairs of
directions (wo, wi in the local frame, wi below the horizon included) and Mitsuba's
``eval`` (rgb) and ``pdf``.
"""
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "references", "conductor_mitsuba.npz")
TINT = (0.9, 0.8, 0.7)
# (distribution, alpha_u, alpha_v, eta rgb, k rgb): Mitsuba's gold and aluminium (its RGB
# values), a perfect mirror's index, anisotropy both ways
CASES = [
    ("ggx", 0.1, 0.1, (0.1431, 0.3749, 1.4425), (3.9831, 2.3857, 1.6032)),
    ("ggx", 0.3, 0.05, (1.6574, 0.8803, 0.5212), (9.2238, 6.2695, 4.837)),
    ("ggx", 0.05, 0.4, (0.2, 0.9, 1.1), (3.9, 2.4, 2.2)),
    ("ggx", 0.8, 0.8, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
    ("beckmann", 0.1, 0.1, (0.1431, 0.3749, 1.4425), (3.9831, 2.3857, 1.6032)),
    ("beckmann", 0.3, 0.05, (1.6574, 0.8803, 0.5212), (9.2238, 6.2695, 4.837)),
    ("beckmann", 0.05, 0.4, (0.2, 0.9, 1.1), (3.9, 2.4, 2.2)),
    ("beckmann", 0.8, 0.8, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
]
N_DIRS = 64


def directions(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(N_DIRS, 3))
    a[:, 2] = np.abs(a[:, 2])
    b = rng.normal(size=(N_DIRS, 3))
    b[: N_DIRS * 7 // 8, 2] = np.abs(b[: N_DIRS * 7 // 8, 2])   # a few below the horizon
    return (a / np.linalg.norm(a, axis=1, keepdims=True),
            b / np.linalg.norm(b, axis=1, keepdims=True))


def main():
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    wo, wi = directions(7)
    values = np.zeros((len(CASES), N_DIRS, 3))
    pdfs = np.zeros((len(CASES), N_DIRS))
    for c, (dist, au, av, eta, k) in enumerate(CASES):
        bsdf = mi.load_dict({
            "type": "roughconductor", "distribution": dist, "alpha_u": au, "alpha_v": av,
            "eta": {"type": "rgb", "value": list(eta)}, "k": {"type": "rgb", "value": list(k)},
            "specular_reflectance": {"type": "rgb", "value": list(TINT)}})
        ctx = mi.BSDFContext()
        for j in range(N_DIRS):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wo[j])     # Mitsuba's wi: towards the viewer (our wo)
            si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
            values[c, j] = np.array(bsdf.eval(ctx, si, mi.Vector3f(*wi[j])))
            pdfs[c, j] = bsdf.pdf(ctx, si, mi.Vector3f(*wi[j]))
    np.savez_compressed(
        OUT, wo=wo, wi=wi, values=values, pdfs=pdfs, tint=np.array(TINT),
        distribution=np.array([c[0] == "beckmann" for c in CASES]),
        alpha=np.array([c[1:3] for c in CASES]), eta=np.array([c[3] for c in CASES]),
        k=np.array([c[4] for c in CASES]), mitsuba=mi.__version__)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
