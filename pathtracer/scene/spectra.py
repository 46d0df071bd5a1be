"""Spectra given by wavelengths, turned into the linear sRGB colours Mitsuba 3's RGB variants
make of them (its XML parser's ``spectrum_list_to_srgb``): the piecewise-linear spectrum
integrated against the CIE 1931 colour matching functions on 1,000 evenly spaced
wavelengths over 360-830 nm (zero outside the given range), weighted by the D65 illuminant
for reflectances (so that a flat reflectance stays grey), then XYZ -> linear sRGB;
reflectances are clipped to [0, 1], emission to >= 0. A uniform spectrum is grey for a
reflectance and ``value x xyz_to_srgb(1, 1, 1)`` (a purplish white) for an emitter, as in
Mitsuba. The tables: data/cie1931_d65.csv (the CIE's, as Mitsuba holds them)."""
import functools
import os

import numpy as np

CIE_MIN, CIE_MAX = 360.0, 830.0
STEPS = 1000
# Mitsuba's normalisations: 1 / (integral of y) and 1 / (integral of y x D65)
CIE_Y_NORMALIZATION = 1.0 / 106.7502593994140625
CIE_D65_NORMALIZATION = 1.0 / 98.99741751876255
# XYZ -> linear sRGB (D65 white), the matrix Mitsuba's xyz_to_srgb uses
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])


@functools.lru_cache(maxsize=1)
def tables():
    """(wavelengths, x, y, z, d65) of the CIE tables, 1 nm apart."""
    path = os.path.join(os.path.dirname(__file__), "data", "cie1931_d65.csv")
    t = np.loadtxt(path, delimiter=",", comments="#")
    return t[:, 0], t[:, 1], t[:, 2], t[:, 3], t[:, 4]


def spectrum_to_rgb(wavelengths, values, emitter=False):
    """Linear sRGB of the spectrum ``values`` at ``wavelengths`` (nm, increasing)."""
    w = np.asarray(wavelengths, np.float64)
    v = np.asarray(values, np.float64)
    lam, x, y, z, d65 = tables()
    s = CIE_MIN + np.arange(STEPS) / (STEPS - 1) * (CIE_MAX - CIE_MIN)
    s = s[(s >= w[0]) & (s <= w[-1])]
    spd = np.interp(s, w, v)
    if not emitter:
        spd = spd * np.interp(s, lam, d65) * CIE_D65_NORMALIZATION
    xyz = np.stack([np.interp(s, lam, c) for c in (x, y, z)], -1)
    color = (xyz * spd[:, None]).sum(0) * ((CIE_MAX - CIE_MIN) / STEPS)
    rgb = XYZ_TO_SRGB @ (color * CIE_Y_NORMALIZATION)
    return np.clip(rgb, 0.0, None if emitter else 1.0)


def uniform_to_rgb(value, emitter=False):
    """A uniform spectrum: grey for a reflectance, value x xyz_to_srgb(1, 1, 1) for an
    emitter (Mitsuba: 'a purplish colour ... so that RGB variants match spectral ones')."""
    if not emitter:
        return np.full(3, float(value))
    return float(value) * XYZ_TO_SRGB.sum(axis=1)
