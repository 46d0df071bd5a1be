"""Exposure and tone curves for 8-bit images (PNG) and previews. Float outputs (EXR, HDR,
NPY) stay linear and untouched.

Display values come from scene-linear Rec. 709 radiance in three steps: exposure (a
multiplication by 2^EV, before any curve, so it is linear), a tone curve, and the sRGB
encoding (IEC 61966-2-1) to 8 bits.

Curves (``TONEMAPS``):
- ``clamp``: none; values above 1 clip (the only behaviour before issue 17, the default).
- ``aces``: Krzysztof Narkowicz's 2015 fit of the ACES reference rendering transform plus
  the sRGB output transform ("ACES Filmic Tone Mapping Curve"),
  f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), clamped to [0, 1], per channel
  on linear values; its output is display-linear and then sRGB-encoded. Narkowicz's fit
  expects the input pre-exposed by 0.6 to match the reference's brightness; that is
  applied here (ACES_PRE_EXPOSURE), so --exposure 0 means the same scene brightness for
  every curve.
- ``agx``: Troy Sobotka's AgX as in Blender 4's "AgX Base sRGB" view, in the widely used
  closed form (the "minimal AgX" of Benjamin Wrensch, 2023): an inset matrix that pulls
  primaries towards the achromatic axis (so that bright saturated colours desaturate
  instead of clipping to a hue shift), a log2 encoding over 16.5 stops, from 10 below to 6.5
  above middle grey 0.18, a 6th-order polynomial fit of AgX's sigmoid, and the inverse
  matrix; the sigmoid's output is a 2.2-power encoding, decoded here before the sRGB
  encoding. The polynomial is a fit of AgX's sigmoid, not Blender's LUT itself (small
  differences remain). Middle grey 0.18 lands at 10/16.5 of the log range and leaves as
  sRGB 0.500, AgX's design point.
"""
import numpy as np

TONEMAPS = ("clamp", "aces", "agx")

ACES_PRE_EXPOSURE = 0.6
ACES_A, ACES_B, ACES_C, ACES_D, ACES_E = 2.51, 0.03, 2.43, 0.59, 0.14

# AgX (Blender 4 "AgX Base", closed form): inset matrix applied to row vectors (rgb @ M)
AGX_INSET = np.array([[0.842479062253094, 0.0423282422610123, 0.0423756549057051],
                      [0.0784335999999992, 0.878468636469772, 0.0784336],
                      [0.0792237451477643, 0.0791661274605434, 0.879142973793104]])
AGX_OUTSET = np.linalg.inv(AGX_INSET)
AGX_MIDDLE_GREY = 0.18
AGX_MIN_EV = np.log2(AGX_MIDDLE_GREY) - 10.0      # -12.47393
AGX_MAX_EV = np.log2(AGX_MIDDLE_GREY) + 6.5       # 4.026069
# the sigmoid's polynomial, highest power first (np.polyval order)
AGX_SIGMOID = (15.5, -40.14, 31.96, -6.868, 0.4298, 0.1191, -0.00232)
AGX_DISPLAY_GAMMA = 2.2


def aces_curve(x):
    """Narkowicz's ACES fit on linear values (already pre-exposed), clamped to [0, 1]."""
    x = np.maximum(x, 0.0)
    return np.clip(x * (ACES_A * x + ACES_B) / (x * (ACES_C * x + ACES_D) + ACES_E), 0.0, 1.0)


def agx_sigmoid(x):
    """AgX's sigmoid (polynomial fit) on log-encoded values in [0, 1], clamped to [0, 1]."""
    return np.clip(np.polyval(AGX_SIGMOID, x), 0.0, 1.0)


def agx_log_encode(rgb):
    """log2 of the inset colour, mapped from [AGX_MIN_EV, AGX_MAX_EV] onto [0, 1]."""
    v = np.maximum(rgb @ AGX_INSET, 1e-10)
    return (np.clip(np.log2(v), AGX_MIN_EV, AGX_MAX_EV) - AGX_MIN_EV) / (AGX_MAX_EV - AGX_MIN_EV)


def agx(rgb):
    """AgX: display-linear RGB in [0, 1] of scene-linear rgb (..., 3)."""
    rgb = np.maximum(np.nan_to_num(rgb, nan=0.0, posinf=1e10, neginf=0.0), 0.0)
    encoded = agx_sigmoid(agx_log_encode(rgb)) @ AGX_OUTSET
    display = np.power(np.clip(encoded, 0.0, 1.0), AGX_DISPLAY_GAMMA)
    # exact black stays black: the log encoding's floor (10 stops under middle grey)
    # lies just below where the polynomial crosses zero, but rounding could lift it
    return np.where(np.max(rgb, axis=-1, keepdims=True) > 0.0, display, 0.0)


def display_linear(image, exposure=0.0, tonemap="clamp"):
    """Display-linear values in [0, 1] of a linear HxWx3 image: exposure (EV), then the
    curve (see the module docstring)."""
    if tonemap not in TONEMAPS:
        raise ValueError(f"unknown tone map {tonemap!r} (use one of {', '.join(TONEMAPS)})")
    x = np.asarray(image, np.float64) * 2.0 ** float(exposure)
    x = np.nan_to_num(x, nan=0.0, posinf=1e10, neginf=0.0)
    if tonemap == "aces":
        return aces_curve(ACES_PRE_EXPOSURE * x)
    if tonemap == "agx":
        return agx(x)
    return np.clip(x, 0.0, 1.0)
