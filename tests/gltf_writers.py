"""glTF files for the reader's tests, written by pygltflib's serialiser (GLTF2.from_dict +
save) from known geometry, so that what is tested is our reading of what another writer
wrote. (trimesh's exporter is the other writer, used in tests/test_gltf.py directly.)

    python -m tests.gltf_writers scenes/cornell-box.glb     # the committed glTF box
"""
import math
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class Builder:
    """The JSON of a glTF file and its one binary buffer, grown item by item."""

    def __init__(self):
        self.blob = bytearray()
        self.doc = {"asset": {"version": "2.0", "generator": "pt-render tests (pygltflib)"},
                    "scene": 0, "scenes": [{"nodes": []}], "nodes": [], "meshes": [],
                    "materials": [], "accessors": [], "bufferViews": [], "buffers": [],
                    "textures": [], "images": [], "samplers": [], "cameras": []}
        self.used = set()

    def view(self, data):
        while len(self.blob) % 4:
            self.blob.append(0)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob),
                                        "byteLength": len(data)})
        self.blob += data
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, array, component=5126, normalized=False):
        array = np.ascontiguousarray(array)
        width = 1 if array.ndim == 1 else array.shape[1]
        acc = {"bufferView": self.view(array.tobytes()), "componentType": component,
               "count": len(array), "type": {1: "SCALAR", 2: "VEC2", 3: "VEC3",
                                             4: "VEC4"}[width]}
        if normalized:
            acc["normalized"] = True
        if width == 3 and component == 5126:     # POSITION needs its bounds
            acc["min"] = array.min(0).tolist()
            acc["max"] = array.max(0).tolist()
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def mesh(self, positions, indices=None, normals=None, uvs=None, material=None, mode=None,
             colors=None):
        attrs = {"POSITION": self.accessor(np.asarray(positions, np.float32))}
        if colors is not None:      # COLOR_0 as normalised unsigned bytes (VEC3 or VEC4)
            attrs["COLOR_0"] = self.accessor(np.asarray(colors, np.uint8), 5121, True)
        if normals is not None:
            attrs["NORMAL"] = self.accessor(np.asarray(normals, np.float32))
        if uvs is not None:
            attrs["TEXCOORD_0"] = self.accessor(np.asarray(uvs, np.float32))
        prim = {"attributes": attrs}
        if indices is not None:
            prim["indices"] = self.accessor(np.asarray(indices, np.uint32).reshape(-1), 5125)
        if material is not None:
            prim["material"] = material
        if mode is not None:
            prim["mode"] = mode
        self.doc["meshes"].append({"primitives": [prim]})
        return len(self.doc["meshes"]) - 1

    def material(self, m):
        for k in (m.get("extensions") or {}):
            self.used.add(k)
        self.doc["materials"].append(m)
        return len(self.doc["materials"]) - 1

    def image(self, png_bytes, sampler=None):
        self.doc["images"].append({"bufferView": self.view(png_bytes),
                                   "mimeType": "image/png"})
        tex = {"source": len(self.doc["images"]) - 1}
        if sampler is not None:
            self.doc["samplers"].append(sampler)
            tex["sampler"] = len(self.doc["samplers"]) - 1
        self.doc["textures"].append(tex)
        return len(self.doc["textures"]) - 1

    def node(self, root=True, **kw):
        self.doc["nodes"].append(kw)
        i = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(i)
        return i

    def light(self, light):
        self.used.add("KHR_lights_punctual")
        lights = self.doc.setdefault("extensions", {}).setdefault(
            "KHR_lights_punctual", {"lights": []})["lights"]
        lights.append(light)
        return len(lights) - 1

    def save(self, path):
        from pygltflib import GLTF2
        doc = {k: v for k, v in self.doc.items() if v != []}
        if self.used:
            doc["extensionsUsed"] = sorted(self.used)
        doc["buffers"] = [{"byteLength": len(self.blob)}]
        g = GLTF2.from_dict(doc)
        g.set_binary_blob(bytes(self.blob))
        g.save_binary(str(path))
        return str(path)


def look_at_rotation(position, target, up=(0.0, 1.0, 0.0)):
    """The quaternion (x, y, z, w) of a node whose -Z looks from position at target."""
    f = np.subtract(target, position).astype(float)
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.stack([r, u, -f], axis=1)            # columns: local x, y, z in world space
    w = math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2])) / 2, m[2, 1] - m[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] + m[1, 1] - m[2, 2])) / 2, m[0, 2] - m[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] - m[1, 1] + m[2, 2])) / 2, m[1, 0] - m[0, 1])
    return [x, y, z, w]


def write_cornell_box(path):
    """The Cornell box of scenes/cornell-box.json as glTF: its quads (cbox.obj) as one
    primitive per material, Lambertian materials (metallic 0 and KHR_materials_specular
    factor 0: glTF's diffuse lobe alone), the light as emissive with
    KHR_materials_emissive_strength, and the JSON scene's camera (vertical field of view
    from its horizontal one on the square image)."""
    import json
    from pathtracer.scene.meshes import load_obj
    box = json.load(open(os.path.join(ROOT, "scenes", "cornell-box.json")))
    mesh = load_obj(os.path.join(ROOT, "scenes", "cornell-box", "cbox.obj"), use_cache=False)
    b = Builder()
    for k, mm in enumerate(mesh.materials):
        faces = mesh.positions[mesh.face_material == k].reshape(-1, 3)
        if not len(faces):
            continue
        m = {"name": mm["name"],
             "pbrMetallicRoughness": {"baseColorFactor": list(mm["Kd"]) + [1.0],
                                      "metallicFactor": 0.0, "roughnessFactor": 1.0},
             "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}}}
        ke = list(mm.get("Ke") or [0, 0, 0])
        if max(ke) > 0:
            top = max(ke)
            m["emissiveFactor"] = [c / top for c in ke]
            m["extensions"]["KHR_materials_emissive_strength"] = {"emissiveStrength": top}
        mi = b.material(m)
        b.node(mesh=b.mesh(faces, np.arange(len(faces)).reshape(-1, 3), material=mi),
               name=mm["name"])
    cam = box["camera"]
    w, h = cam["resolution"]
    yfov = 2 * math.atan(math.tan(math.radians(cam["fov"]) / 2) * h / w)
    b.doc["cameras"].append({"type": "perspective", "name": "front",
                             "perspective": {"yfov": yfov, "aspectRatio": w / h,
                                             "znear": 0.01}})
    b.node(camera=0, name="camera", translation=cam["position"],
           rotation=look_at_rotation(cam["position"], cam["lookAt"], cam["up"]))
    return b.save(path)


if __name__ == "__main__":
    sys.path.insert(0, ROOT)
    print(write_cornell_box(sys.argv[1] if len(sys.argv) > 1 else
                            os.path.join(ROOT, "scenes", "cornell-box.glb")))
