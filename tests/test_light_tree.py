"""The light tree (render.lightSampler): its build, its pick's probabilities against the
picks it makes, the bounds' conservativeness, and unbiased images with it."""
import numpy as np
import pytest

from pathtracer.accel.light_tree import LightBounds, build_light_tree
from pathtracer.kernels.layout import LT_LEFT, LT_PARENT, LT_RIGHT, leaf_light_ref
from pathtracer.kernels.lights import light_importance, light_tree_pmf, sample_light_tree
from pathtracer.scene import SceneError, load_scene
from tests.conftest import BACKENDS
from tests.helpers import chi2_test, furnace_scene, mean_and_se, run, write_scene

F32 = np.float32


def random_lights(rng, n_tri=40, n_point=6, n_spot=6):
    """LightBounds of random one- and two-sided triangles, point and spot lights."""
    lo, hi, axis, cos_o, cos_e, power, two = [], [], [], [], [], [], []
    for _ in range(n_tri):
        c = rng.uniform(-3, 3, 3)
        v = c + rng.normal(0, 0.2, (3, 3))
        n = np.cross(v[1] - v[0], v[2] - v[0])
        lo.append(v.min(0))
        hi.append(v.max(0))
        axis.append(n / np.linalg.norm(n))
        cos_o.append(1.0)
        cos_e.append(0.0)
        power.append(rng.uniform(0.1, 5))
        two.append(rng.random() < 0.3)
    for i in range(n_point + n_spot):
        p = rng.uniform(-3, 3, 3)
        lo.append(p)
        hi.append(p)
        power.append(rng.uniform(0.1, 5))
        two.append(False)
        if i < n_point:
            axis.append([0.0, 0.0, 1.0])
            cos_o.append(-1.0)
            cos_e.append(0.0)
        else:
            a = rng.normal(size=3)
            axis.append(a / np.linalg.norm(a))
            inner, outer = np.radians(rng.uniform(0, 20)), np.radians(rng.uniform(25, 60))
            cos_o.append(np.cos(inner))
            cos_e.append(np.cos(outer - inner))
    return LightBounds(*(np.asarray(x, float) for x in (lo, hi, axis, cos_o, cos_e, power)),
                       np.asarray(two))


def test_tree_structure():
    bounds = random_lights(np.random.default_rng(0))
    tree = build_light_tree(bounds)
    k = len(bounds.power)
    assert tree.node.shape[0] == 2 * k - 1
    # every light in exactly one leaf, every leaf's parent pointing back at it
    assert sorted(-tree.link[tree.leaf, LT_LEFT] - 1) == list(range(k))
    assert (tree.link[tree.leaf, LT_LEFT] == [leaf_light_ref(i) for i in range(k)]).all()
    for n in range(1, tree.node.shape[0]):
        parent = tree.link[n, LT_PARENT]
        assert n in (tree.link[parent, LT_LEFT], tree.link[parent, LT_RIGHT])
    assert tree.link[0, LT_PARENT] == -1
    assert tree.depth < k      # binned splits, not a list


@pytest.mark.parametrize("seed", [1, 2])
def test_pick_frequencies_match_the_pmf(seed):
    """Lights picked by sample_light_tree at a point occur with light_tree_pmf's
    probabilities (chi-square), and the pick returns that probability. They sum to 1 but
    for the chance of a walk into a node whose children cannot reach the point (its own
    looser bound could): then no light is picked, which only those lights could have lit."""
    rng = np.random.default_rng(seed)
    bounds = random_lights(rng)
    tree = build_light_tree(bounds)
    k = len(bounds.power)
    for _ in range(3):
        p = tuple(F32(x) for x in rng.uniform(-4, 4, 3))
        pmf = np.array([light_tree_pmf(tree.node, tree.link, tree.leaf[i], p)
                        for i in range(k)], float)
        assert 0.5 < pmf.sum() <= 1 + 1e-5
        n = 20000
        counts = np.zeros(k + 1)
        for u in rng.random(n):
            light, pick_pmf = sample_light_tree(tree.node, tree.link, p, F32(min(u, 0.9999999)))
            counts[light] += 1      # (no light: the last cell)
            if light >= 0:
                assert pick_pmf == pytest.approx(pmf[light], rel=1e-5)
        chi2_test(counts, np.append(pmf, max(0.0, 1 - pmf.sum())) * n)


def test_importance_is_a_bound():
    """A node's importance is positive wherever one of its lights' is (the pick never
    skips a light that can reach the point), and a light's is zero only where it cannot
    light the point: behind a one-sided triangle, outside a spot light's outer cone."""
    rng = np.random.default_rng(3)
    bounds = random_lights(rng)
    tree = build_light_tree(bounds)
    leaves_below = {}
    for n in range(tree.node.shape[0] - 1, -1, -1):
        first = tree.link[n, LT_LEFT]
        leaves_below[n] = ([n] if first < 0 else
                           leaves_below[first] + leaves_below[tree.link[n, LT_RIGHT]])
    for _ in range(200):
        p = tuple(F32(x) for x in rng.uniform(-5, 5, 3))
        imp = np.array([light_importance(tree.node, n, p) for n in range(tree.node.shape[0])])
        for n, below in leaves_below.items():
            if (imp[below] > 0).any():
                assert imp[n] > 0
        for i in range(len(bounds.power)):
            if imp[tree.leaf[i]] > 0:
                continue
            c = (bounds.lo[i] + bounds.hi[i]) / 2
            to_p = np.asarray(p, float) - c
            cos = np.dot(to_p, bounds.axis[i]) / np.linalg.norm(to_p)
            if bounds.cos_o[i] == 1.0:     # a triangle: p is behind (or in) its plane
                assert not bounds.two_sided[i]
                assert np.all([np.dot(np.asarray(p) - v, bounds.axis[i]) <= 1e-5
                               for v in (bounds.lo[i], bounds.hi[i], c)]) or cos <= 1e-5
            elif bounds.cos_o[i] > -1.0:   # a spot light: outside its outer cone
                assert cos <= np.cos(np.arccos(bounds.cos_o[i]) +
                                     np.arccos(bounds.cos_e[i])) + 1e-5


def lamps_scene(sampler, res=(24, 24), spp=64):
    """A floor lit by a 4 x 4 grid of small lamps (one-sided quads facing down, varied
    colours), a spot and a point light."""
    rng = np.random.default_rng(5)
    mats = [{"name": "floor", "type": "diffuse", "albedo": 0.7}]
    objects = [{"name": "floor", "vertices": [[-6, 0, -6], [6, 0, -6], [6, 0, 6], [-6, 0, 6]],
                "faces": [[0, 2, 1], [0, 3, 2]], "material": "floor"}]
    for i in range(4):
        for j in range(4):
            x, z, s = -4.5 + 3 * i, -4.5 + 3 * j, 0.2
            mats.append({"name": f"lamp{i}{j}", "type": "diffuse", "albedo": 0.0,
                         "emission": (rng.random(3) * 4 + 0.5).tolist()})
            objects.append({"name": f"lamp{i}{j}", "material": f"lamp{i}{j}",
                            "vertices": [[x - s, 0.5, z - s], [x + s, 0.5, z - s],
                                         [x + s, 0.5, z + s], [x - s, 0.5, z + s]],
                            "faces": [[0, 1, 2], [0, 2, 3]]})
    return {"camera": {"resolution": list(res), "position": [0, 9, 7], "lookAt": [0, 0, 0],
                       "up": [0, 1, 0], "fov": 60},
            "render": {"spp": spp, "maxBounces": 2, "lightSampler": sampler},
            "materials": mats, "objects": objects,
            "lights": [{"type": "spot", "position": [0, 3, 0], "intensity": 20,
                        "direction": [0, -1, 0], "innerAngle": 10, "outerAngle": 30},
                       {"type": "point", "position": [4, 2, 4], "intensity": 3}]}


@pytest.mark.parametrize("backend", BACKENDS)
def test_tree_and_power_render_the_same_image_with_less_noise(tmp_path, backend):
    """The same expected image with either light sampler (the mean of each quadrant,
    z-tests), and less noise with the tree on many small lamps: at equal spp its relMSE
    against a long render is under half the power sampler's."""
    scenes = {s: load_scene(write_scene(tmp_path, lamps_scene(s), f"{s}.json"))
              for s in ("tree", "power")}
    assert scenes["tree"].features.light_tree and not scenes["power"].features.light_tree
    imgs = {s: [run(sc, backend, spp=64, seed=seed).film.image().astype(np.float64)
                for seed in range(4)] for s, sc in scenes.items()}
    # per quadrant and channel: the mean of the pixels' differences over its standard error
    # (pixels are independent; under equal expectations E[d^2] is each difference's variance)
    d = np.array(imgs["tree"]) - np.array(imgs["power"])          # (seed, y, x, rgb)
    quads = d.reshape(4, 2, 12, 2, 12, 3).transpose(1, 3, 5, 0, 2, 4).reshape(2, 2, 3, -1)
    z = quads.mean(-1) / (np.sqrt((quads ** 2).sum(-1)) / quads.shape[-1])
    assert np.abs(z).max() < 4.5, z
    ref = run(scenes["tree"], backend, spp=2048, seed=99).film.image().astype(np.float64)

    def rel(x):
        return float(np.mean((x - ref) ** 2 / (ref ** 2 + 1e-2)))
    err = {s: np.mean([rel(x) for x in v]) for s, v in imgs.items()}
    assert err["tree"] < 0.5 * err["power"], err


@pytest.mark.parametrize("backend", BACKENDS)
def test_furnace_with_the_light_tree(tmp_path, backend):
    """Inside a closed sphere of 288 emitting triangles (both sides) picked by the tree:
    L = Le * sum a^k (every pick's probability and its MIS density agree)."""
    scene_dict = furnace_scene([0.8, 0.5, 0.3], [1.0, 2.0, 0.5], 4, res=(16, 16))
    scene_dict["render"]["lightSampler"] = "tree"
    scene = load_scene(write_scene(tmp_path, scene_dict))
    assert scene.features.light_tree
    img = run(scene, backend, spp=64).film.image()
    a = np.array([0.8, 0.5, 0.3])
    expected = np.array([1.0, 2.0, 0.5]) * sum(a ** k for k in range(5))
    mean, se = mean_and_se(img)
    assert np.all(np.abs(mean - expected) <= 5 * se + 1e-6 * expected), (mean, expected, se)


def test_light_sampler_key(tmp_path):
    d = lamps_scene("auto")
    assert load_scene(write_scene(tmp_path, d)).features.light_tree      # 34 lights
    d["objects"] = d["objects"][:2]
    d["lights"] = []
    assert not load_scene(write_scene(tmp_path, d)).features.light_tree  # one quad lamp
    spot_and_sun = [{"type": "spot", "position": [0, 3, 0], "intensity": 1,
                     "direction": [0, -1, 0]},
                    {"type": "directional", "direction": [1, -1, 0], "irradiance": 1}]
    assert load_scene(write_scene(tmp_path, dict(d, objects=d["objects"][:1],
                                                 lights=spot_and_sun))).features.light_tree
    d["render"]["lightSampler"] = "tree"
    assert load_scene(write_scene(tmp_path, d)).features.light_tree
    d["render"]["lightSampler"] = "bvh"
    with pytest.raises(SceneError, match="lightSampler"):
        load_scene(write_scene(tmp_path, d))


def test_coincident_lights_and_a_point_on_a_light():
    """Ten point lights at one position: the tree still splits them (equal centres), and at
    that very position, where their importance would be infinite, the picks' probabilities
    stay finite and sum to 1."""
    k = 10
    pos = np.tile([1.0, 2.0, 3.0], (k, 1))
    tree = build_light_tree(LightBounds(pos, pos, np.tile([0.0, 0.0, 1.0], (k, 1)),
                                        -np.ones(k), np.zeros(k), np.arange(1.0, k + 1),
                                        np.zeros(k, bool)))
    assert tree.depth <= 5
    for p in ((F32(0), F32(0), F32(0)), (F32(1), F32(2), F32(3))):
        pmf = [light_tree_pmf(tree.node, tree.link, tree.leaf[i], p) for i in range(k)]
        assert np.isfinite(pmf).all() and sum(pmf) == pytest.approx(1.0, abs=1e-5)
        light, pick_pmf = sample_light_tree(tree.node, tree.link, p, F32(0.5))
        assert 0 <= light < k and np.isfinite(pick_pmf)
