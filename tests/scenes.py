"""Small scenes made in code for tests."""
import json
import os

import numpy as np


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
    """A closed UV sphere, triangles facing outward."""
    verts = [[0, radius, 0]]
    for i in range(1, n_theta):
        th = np.pi * i / n_theta
        for j in range(n_phi):
            ph = 2 * np.pi * j / n_phi
            verts.append([radius * np.sin(th) * np.cos(ph), radius * np.cos(th),
                          radius * np.sin(th) * np.sin(ph)])
    verts.append([0, -radius, 0])
    bottom = len(verts) - 1

    def ring(i, j):
        return 1 + (i - 1) * n_phi + (j % n_phi)

    faces = []
    for j in range(n_phi):
        faces.append([0, ring(1, j + 1), ring(1, j)])
        faces.append([bottom, ring(n_theta - 1, j), ring(n_theta - 1, j + 1)])
    for i in range(1, n_theta - 1):
        for j in range(n_phi):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)
            faces += [[a, b, c], [a, c, d]]
    return _orient_outward(verts, faces)


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
