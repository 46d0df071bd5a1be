"""One warm-up pass and one measured pass of a benchmark scene: a target for profilers.

    ncu --kernel-name regex:render_pass --launch-skip 1 --launch-count 1 \\
        python -m bench.one_pass bunny-studio 256x192 64 [--backend cuda]
"""
import argparse

from bench.ab import _describe


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("resolution")
    p.add_argument("spp", type=int)
    p.add_argument("--backend", default="cuda")
    a = p.parse_args(argv)
    from pathtracer.backends import make_backend
    from pathtracer.scene import compile_scene
    res = tuple(int(x) for x in a.resolution.split("x"))
    scene = compile_scene(_describe(a.scene, res))
    b = make_backend(a.backend, scene)
    for start in (0, a.spp):
        b.render_pass(start, a.spp, 0, scene.max_bounces, scene.rr_depth)


if __name__ == "__main__":
    main()
