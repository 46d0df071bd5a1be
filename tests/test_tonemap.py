"""Exposure and tone curves (pathtracer.tonemap): exposure is linear and comes before the
curve, every curve is monotone and maps black to black, the curves match their published
definitions at a few points, and only 8-bit outputs are tone mapped."""

import imageio.v3 as iio
import numpy as np
import pytest

from pathtracer.film import linear_to_srgb, read_image, to_display
from pathtracer.scene import load_scene_description
from pathtracer.scene.errors import SceneError
from pathtracer.tonemap import (ACES_PRE_EXPOSURE, AGX_MAX_EV, AGX_MIN_EV, TONEMAPS,
                                aces_curve, agx, agx_log_encode, display_linear)
from tests.helpers import furnace_scene, write_scene
from tests.test_cli import pt_render


def grey(values):
    v = np.asarray(values, float)
    return np.repeat(v[..., None], 3, axis=-1)


@pytest.mark.parametrize("curve", TONEMAPS)
def test_exposure_is_linear_and_before_the_curve(curve):
    rng = np.random.default_rng(1)
    img = rng.random((8, 8, 3)) * 4
    for ev in (-3.0, -0.5, 1.0, 2.5):
        assert np.allclose(display_linear(img, ev, curve), display_linear(img * 2 ** ev, 0, curve),
                           rtol=1e-12, atol=1e-12)
    # without a curve, exposure is a plain factor until values clip
    assert np.allclose(display_linear(img / 8, 2.0, "clamp"), np.clip(img / 2, 0, 1))


@pytest.mark.parametrize("curve", TONEMAPS)
def test_curves_are_monotone_and_map_black_to_black(curve):
    x = np.concatenate([[0.0], np.logspace(-6, 6, 2000)])
    y = display_linear(grey(x)[None], 0.0, curve)[0]
    assert np.all(y[0] == 0.0)
    assert np.all(np.diff(y, axis=0) >= -1e-12)
    assert np.all((y >= 0) & (y <= 1))
    # clamp and aces act per channel: monotone in each channel alone too. (AgX is not:
    # its matrices mix channels on purpose, so that brightening red raises green and blue
    # and, through the outset matrix, may lower red's display value a little.)
    for c in range(3 if curve != "agx" else 0):
        rgb = np.full((len(x), 3), 0.3)
        rgb[:, c] = x
        yc = display_linear(rgb[None], 0.0, curve)[0][:, c]
        assert np.all(np.diff(yc) >= -1e-12), (curve, c)
    # NaN and infinities (which never reach a file, but a preview may see) stay finite
    bad = np.array([[[np.nan, np.inf, -np.inf]]])
    assert np.all(np.isfinite(display_linear(bad, 0.0, curve)))


def test_aces_matches_narkowiczs_fit():
    """Narkowicz 2015: f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), after his
    0.6 pre-exposure; values of the published formula, computed by hand."""
    assert aces_curve(1.0) == pytest.approx(2.54 / 3.16)                 # 0.80380
    assert aces_curve(0.18) == pytest.approx(0.086724 / 0.324932, rel=1e-6)
    assert aces_curve(1e6) == 1.0                                          # 2.51/2.43 > 1: clamps
    y = display_linear(grey([[1.0 / ACES_PRE_EXPOSURE]]), 0.0, "aces")
    assert np.allclose(y, 2.54 / 3.16)


def test_agx_matches_its_design_points():
    """AgX (Blender 4 "AgX Base sRGB"): its log encoding spans 10 stops below to 6.5
    above middle grey; middle grey leaves as sRGB 0.500; a bright saturated primary is
    desaturated (the other channels rise) instead of clipping to the same hue."""
    assert AGX_MIN_EV == pytest.approx(-12.47393, abs=1e-5)
    assert AGX_MAX_EV == pytest.approx(4.026069, abs=1e-5)
    e = agx_log_encode(grey([0.18 * 2 ** -10, 0.18, 0.18 * 2 ** 6.5]))
    assert np.allclose(e[:, 0], [0.0, 10 / 16.5, 1.0], atol=1e-4)
    mid = linear_to_srgb(agx(grey([[0.18]])))
    assert np.allclose(mid, 0.500, atol=2e-3)
    red = agx(np.array([[[20.0, 0.0, 0.0]]]))[0, 0]
    assert red[0] > 0.95 and 0.1 < red[1] < red[0] and 0.1 < red[2] < red[0]
    assert np.all(agx(np.zeros((1, 1, 3))) == 0)


def test_png_is_tone_mapped_and_floats_stay_linear(tmp_path):
    scene = write_scene(tmp_path, furnace_scene(0.5, 2.0, 3, res=(16, 12)))
    plain, mapped = str(tmp_path / "plain.png"), str(tmp_path / "mapped.png")
    for out, extra in ((plain, []), (mapped, ["--exposure", "-1.5", "--tonemap", "agx"])):
        r = pt_render(scene, "-o", out, "--spp", 8, "--backend", "cpu", "--quiet", *extra)
        assert r.returncode == 0, r.stderr
    lin_plain = read_image(plain[:-4] + ".exr")
    lin_mapped = read_image(mapped[:-4] + ".exr")
    assert np.array_equal(lin_plain, lin_mapped)            # the float twin is untouched
    png = iio.imread(mapped)
    assert np.array_equal(png, to_display(lin_mapped, (-1.5, "agx")))
    assert not np.array_equal(png, iio.imread(plain))
    assert lin_plain.max() > 1.0 and iio.imread(plain).max() == 255   # clamp clips


def test_scene_keys_and_errors(tmp_path):
    desc = furnace_scene(0.5, 0.5, 2)
    desc["render"].update(exposure=1.25, tonemap="aces")
    d = load_scene_description(write_scene(tmp_path, desc))
    assert (d.render.exposure, d.render.tonemap) == (1.25, "aces")
    d = load_scene_description(write_scene(tmp_path, furnace_scene(0.5, 0.5, 2), "b.json"))
    assert (d.render.exposure, d.render.tonemap) == (0.0, "clamp")
    for bad, word in (({"tonemap": "filmic"}, "tonemap"), ({"exposure": "bright"}, "exposure"),
                      ({"exposure": 1e9}, "exposure")):
        desc = furnace_scene(0.5, 0.5, 2)
        desc["render"].update(bad)
        with pytest.raises(SceneError, match=word):
            load_scene_description(write_scene(tmp_path, desc, "c.json"))
    r = pt_render(write_scene(tmp_path, furnace_scene(0.5, 0.5, 2), "d.json"), "--tonemap",
                  "filmic", "--backend", "cpu")
    assert r.returncode == 2 and "tonemap" in r.stderr


def test_exr_files_with_alpha_or_one_channel_are_read(tmp_path):
    """The one image reader takes EXR files as other tools write them: RGBA (Blender's
    renders; OpenEXR's reader merges the channels into one "RGBA" entry), RGB, separate
    R, G, B channels beside other layers, and grey (Y); as a texture, an RGBA file's alpha
    is its fourth channel."""
    import OpenEXR

    from pathtracer.film import read_image, read_raw
    rgba = np.random.default_rng(0).random((4, 5, 4)).astype(np.float32)
    c = np.ascontiguousarray           # (OpenEXR's writer takes contiguous arrays)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    cases = {"rgba.exr": ({"RGBA": rgba}, rgba),
             "rgb.exr": ({"RGB": c(rgba[..., :3])}, rgba[..., :3]),
             "layers.exr": ({"R": c(rgba[..., 0]), "G": c(rgba[..., 1]), "B": c(rgba[..., 2]),
                             "depth.Z": c(rgba[..., 3])}, rgba[..., :3]),
             "grey.exr": ({"Y": c(rgba[..., 0])}, rgba[..., :1])}
    for name, (channels, expect) in cases.items():
        path = str(tmp_path / name)
        OpenEXR.File(header, channels).write(path)
        got, is_float = read_raw(path)
        assert is_float and np.array_equal(got, expect), name
        if expect.shape[-1] >= 3:
            assert np.array_equal(read_image(path), expect[..., :3]), name
