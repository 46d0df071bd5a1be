"""The data contract between host and device (kernels/layout.py) and the code's shape.

- No module but the layout indexes a kernel array's columns with an integer literal.
- The bounce is written once (kernels/path.py) and the drivers are short loops around it:
  kernel functions <= 100 lines, factories <= 200, nesting <= 5.
- The one material-parameter table agrees with the loader, the compiler's arrays and
  docs/scene-format.md (names, defaults, ranges).
"""
import ast
import glob
import os
import re

import numpy as np
import pytest

from pathtracer.kernels import layout as L
from pathtracer.scene import SceneError, compile_scene
from pathtracer.scene.loader import PRINCIPLED_NUMBERS
from tests.conftest import ROOT
from tests.helpers import write_scene

# Arrays with named columns (the last index of a subscript is the column), and 1-D arrays
# and tuples whose every index is a named slot. `env` (an rgb colour) has no columns.
COLUMN_ARRAYS = {"tri_v", "tri_n", "tri_uv", "tri_t", "mat", "mat_tex", "point_lights",
                 "tex_int", "tex_f", "bvh_box", "bvh_child", "box", "child", "stats"}
SLOT_ARRAYS = {"cam", "env_info", "params"}
# device helpers that take a column as an argument: name -> position of that argument
COLUMN_ARGUMENTS = {"load3": 2, "load4": 2, "interpolate3": 2}


def _name(node):
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def _is_int_literal(node):
    return isinstance(node, ast.Constant) and type(node.value) is int


def _literal_columns(index):
    """The integer literals an index expression uses as a column: a literal, or a slice
    with literal bounds (an offset added to a named column, CAM_UP + 1, is fine)."""
    if _is_int_literal(index):
        return [index.value]
    if isinstance(index, ast.Slice):
        return [b.value for b in (index.lower, index.upper) if b is not None and
                _is_int_literal(b)]
    return []


def column_literals(source):
    """(line, text) of every integer-literal column index in Python source."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Subscript):
            name = _name(node.value)
            idx = node.slice
            if name in COLUMN_ARRAYS:
                # a single index selects rows; the column is the last of several
                bad = _literal_columns(idx.elts[-1]) if isinstance(idx, ast.Tuple) else []
            elif name in SLOT_ARRAYS:
                parts = idx.elts if isinstance(idx, ast.Tuple) else [idx]
                bad = [v for p in parts for v in _literal_columns(p)]
            else:
                continue
            if bad:
                found.append((node.lineno, ast.unparse(node)))
        elif isinstance(node, ast.Call) and _name(node.func) in COLUMN_ARGUMENTS:
            k = COLUMN_ARGUMENTS[_name(node.func)]
            if len(node.args) > k and _is_int_literal(node.args[k]):
                found.append((node.lineno, ast.unparse(node)))
    return found


def test_the_check_finds_column_literals():
    src = ("a = scene.mat[m, 3]\nb = cam[14]\nc = tri_v[:n, 0:3]\nd = load3(tri_v, i, 6)\n"
           "e = params[13]\nok1 = mat[m, M_ALBEDO + 1]\nok2 = out[py, px, 0]\n"
           "ok3 = cam[CAM_UP + 2]\nok4 = tri_v[:n, TRI_E1:TRI_E1 + 3]\n")
    lines = [line for line, _ in column_literals(src)]
    assert lines == [1, 2, 3, 4, 5]


def test_no_column_index_literal_outside_the_layout_module():
    files = [f for d in ("pathtracer", "bench", "tests")
             for f in glob.glob(os.path.join(ROOT, d, "**", "*.py"), recursive=True)]
    skip = {os.path.join(ROOT, "pathtracer", "kernels", "layout.py"), os.path.abspath(__file__)}
    offenders = []
    for f in sorted(set(files) - skip):
        with open(f, encoding="utf-8") as fh:
            for line, text in column_literals(fh.read()):
                offenders.append(f"{os.path.relpath(f, ROOT)}:{line}: {text}")
    assert not offenders, "column numbers outside kernels/layout.py:\n" + "\n".join(offenders)


KERNELS = os.path.join(ROOT, "pathtracer", "kernels")


def _kernel_functions():
    """(file, FunctionDef) of every function in pathtracer/kernels (nested ones too)."""
    for f in sorted(glob.glob(os.path.join(KERNELS, "**", "*.py"), recursive=True)):
        tree = ast.parse(open(f, encoding="utf-8").read())
        for n in ast.walk(tree):
            if isinstance(n, ast.FunctionDef):
                yield os.path.relpath(f, KERNELS), n


def _nesting(node, depth=0):
    blocks = (ast.If, ast.For, ast.While, ast.With, ast.Try)
    deepest = depth
    for child in ast.iter_child_nodes(node):
        d = depth + 1 if isinstance(child, blocks) else depth
        deepest = max(deepest, _nesting(child, d))
    return deepest


def _lines(fn):
    return fn.end_lineno - fn.lineno + 1


def _calls(fn):
    """Names of the functions that ``fn``'s own body calls (not its nested functions')."""
    names = []
    stack = list(ast.iter_child_nodes(fn))
    while stack:
        node = stack.pop()
        if isinstance(node, ast.FunctionDef):
            continue
        if isinstance(node, ast.Call):
            names.append(_name(node.func))
        stack.extend(ast.iter_child_nodes(node))
    return names


# Over the limits and not split yet (README, "Missing"): the principled BSDF's evaluation (one
# device function that the GPU keeps as a call: backends.cuda.NOINLINE), its factory, the
# surface factory and the binary BVH's any-hit loop (nesting 6). The list may only shrink.
STILL_LONG = {"principled.py:principled_eval", "principled.py:make_principled",
              "surface.py:make_surface", "traverse.py:any_hit"}
# The entries the backends' kernels call with their arrays (their signatures are the
# backends' protocol: a pass's arguments as the GPU launches take them).
ENTRY_POINTS = {"render_pixel", "render_pixel_nested", "render_pixel_deferred",
                "render_sample", "next_camera_lane", "camera_packet", "wave_start",
                "wave_shade", "wave_finish", "wave_film", "wave_trace", "store_hit",
                "aov_pixel", "drain_escapes", "finish_record", "queue_record"}


def test_kernel_functions_are_short_and_shallow():
    """Every kernel function <= 100 lines and nesting <= 5; a factory (``make_*``, whose
    nested functions are the kernels) <= 200 lines; the bounce's steps and the drivers'
    loops take <= 8 arguments."""
    long, deep, wide = [], [], []
    for f, fn in _kernel_functions():
        limit = 200 if fn.name.startswith("make_") else 100
        if _lines(fn) > limit and f"{f}:{fn.name}" not in STILL_LONG:
            long.append(f"{f}:{fn.name} {_lines(fn)}")
        if _nesting(fn) > 5 and f"{f}:{fn.name}" not in STILL_LONG:
            deep.append(f"{f}:{fn.name}")
        if (f == "path.py" or f.startswith("drivers")) and len(fn.args.args) > 8 \
                and fn.name not in ENTRY_POINTS:
            wide.append(f"{f}:{fn.name} {len(fn.args.args)}")
    assert not long and not deep and not wide, (long, deep, wide)


def test_the_bounce_is_written_once():
    """The bounce is written once (kernels/path.py) and every driver calls it: each of its
    steps is called from one place in the kernels (the material, the shading frame, the
    emitters' sampling and hit, BSDF sampling, Russian roulette), and every driver's module
    calls the bounce (shade_surface or path_vertex) or its first-hit steps (the AOVs)."""
    once = {"material_at": 0, "shading_frame": 0, "sample_emitter": 0, "hit_emission": 0,
            "sample_world": 0, "russian_roulette": 0}
    where = {name: [] for name in once}
    drivers = {}
    for f, fn in _kernel_functions():
        calls = _calls(fn)
        for name in once:
            n = calls.count(name)
            if n:
                where[name].append(f"{f}:{fn.name}")
                once[name] += n
        if f.startswith("drivers"):
            drivers.setdefault(f, set()).update(calls)
    assert all(n == 1 for n in once.values()), where
    assert all(w[0].startswith("path.py:") for w in where.values()), where
    assert {"drivers/megakernel.py", "drivers/deferred.py", "drivers/wavefront.py",
            "drivers/aov.py"} <= set(drivers)
    for f, calls in drivers.items():
        if f.endswith("__init__.py"):
            continue
        assert calls & {"shade_surface", "path_vertex", "render_sample", "surface_shading"}, f


def test_layout_is_consistent():
    assert len(L.P_FIELDS) == L.P_SIZE
    for name, index in (("roughness", L.P_ROUGHNESS), ("eta", L.P_ETA),
                        ("flatness", L.P_FLATNESS), ("transmission", L.P_TRANSMISSION)):
        assert L.P_FIELDS[index] == name
    columns = [p.column for p in L.MATERIAL_PARAMS]
    slots = [p.slot for p in L.MATERIAL_PARAMS] + [L.T_NORMAL]
    assert len(set(columns)) == len(columns) and max(columns) < L.MAT_WIDTH
    assert len(set(slots)) == len(slots) and max(slots) < L.N_SLOTS
    fields = [p.field for p in L.MATERIAL_PARAMS if p.field >= 0]
    assert len(set(fields)) == len(fields)
    assert L.BOX_CHILD1 == L.BOX_CHILD0 + L.BOX_STRIDE
    assert L.CHILD1_INDEX == L.CHILD0_INDEX + L.CHILD_STRIDE
    assert L.point_light_index(L.point_light_ref(3)) == 3 and L.point_light_ref(0) < 0


def test_compiled_arrays_have_the_layout_widths(tmp_path):
    scene = {"camera": {"resolution": [4, 3], "position": [0, 0, 3], "lookAt": [0, 0, 0]},
             "materials": [{"name": "m", "albedo": 0.5, "emission": 1.0}],
             "objects": [{"name": "t", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                          "faces": [[0, 1, 2]], "material": "m", "smooth": True}],
             "lights": [{"position": [0, 1, 1], "intensity": 2.0}]}
    a = compile_scene(_describe(tmp_path, scene)).arrays
    assert a.cam.shape == (L.CAM_SIZE,)
    assert a.tri_v.shape[1] == L.TRI_V_WIDTH and a.tri_n.shape[1] == L.TRI_N_WIDTH
    assert a.tri_uv.shape[1] == L.TRI_UV_WIDTH and a.tri_t.shape[1] == L.TRI_T_WIDTH
    assert a.mat.shape[1] == L.MAT_WIDTH and a.mat_tex.shape[1] == L.N_SLOTS
    assert a.point_lights.shape[1] == L.PL_WIDTH and a.env_info.shape == (L.ENV_INFO_SIZE,)
    assert a.tex_int.shape[1] == L.TEX_INT_WIDTH and a.tex_f.shape[1] == L.TEX_F_WIDTH
    assert a.bvh_box.shape[1] == L.BOX_WIDTH and a.bvh_child.shape[1] == L.CHILD_WIDTH
    # the principled defaults land in their columns
    for p in L.MATERIAL_PARAMS:
        if p.kind == "number" and p.default is not None:
            assert a.mat[0, p.column] == np.float32(p.default), p.key
    assert a.mat[0, L.M_ETA] == 0.0          # eta absent: derived from specular
    np.testing.assert_array_equal(a.mat[0, L.M_EMISSION:L.M_EMISSION + 3], 1.0)
    np.testing.assert_array_equal(a.point_lights[0, L.PL_INTENSITY:L.PL_INTENSITY + 3], 2.0)


def _describe(tmp_path, scene):
    from pathtracer.scene import load_scene_description
    return load_scene_description(write_scene(tmp_path, scene))


def _doc_principled_table():
    """{key: (default text, meaning)} of the principled table in docs/scene-format.md."""
    text = open(os.path.join(ROOT, "docs", "scene-format.md"), encoding="utf-8").read()
    start = text.index("`principled`: the Disney principled BSDF")
    rows = {}
    for line in text[start:].splitlines()[4:]:
        if not line.startswith("|"):
            if rows:
                break
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[0] in ("key", "---"):
            continue
        keys = re.findall(r"`(\w+)`", cells[0].split("(alias")[0])
        defaults = [d.strip() for d in cells[1].split(",")]
        if len(defaults) == 1:
            defaults *= len(keys)
        for k, d in zip(keys, defaults):
            rows[k] = (d, cells[2])
    return rows


def test_docs_loader_and_layout_agree_on_material_parameters(tmp_path):
    doc = _doc_principled_table()
    for p in L.MATERIAL_PARAMS:
        assert p.key in doc, f"docs/scene-format.md has no row for {p.key!r}"
        default, meaning = doc[p.key]
        expected = L.DEFAULT_ETA if p.default is None else p.default
        assert float(default) == expected, (p.key, default)
        if p.kind == "number" and (p.lo, p.hi) == (0.0, 1.0):
            assert meaning.startswith("[0, 1]"), (p.key, meaning)
    documented_params = set(doc) - {"normalMap", "twoSided", "oneSided", "alpha", "alphaMode",
                                    "alphaCutoff"}
    assert documented_params == {p.key for p in L.MATERIAL_PARAMS}
    # the loader validates with the same table
    assert PRINCIPLED_NUMBERS == {p.key: (p.default, p.lo, p.hi) for p in L.MATERIAL_PARAMS
                                  if p.kind == "number"}
    base = {"camera": {"resolution": [2, 2]}}
    desc = _describe(tmp_path, dict(base, materials=[{"name": "m"}]))
    m = desc.materials["m"]
    assert m.albedo == (L.PARAM_BY_KEY["albedo"].default,) * 3
    for p in L.MATERIAL_PARAMS:
        if p.kind == "number" and p.default is not None:
            assert m.numbers[p.key] == p.default
        if p.kind == "number" and p.hi is not None:
            bad = dict(base, materials=[{"name": "m", p.key: p.hi + 0.5}])
            with pytest.raises(SceneError, match=f"/materials/0/{p.key}"):
                _describe(tmp_path, bad)


def _import_graph(package):
    """{module: modules of ``package`` it imports} for every module of ``package`` (under
    ROOT), imports inside functions included (a cycle hidden behind a function-level import
    is still a cycle)."""
    files = {}
    for f in glob.glob(os.path.join(ROOT, package, "**", "*.py"), recursive=True):
        name = os.path.relpath(f, ROOT)[:-3].replace(os.sep, ".")
        files[name[:-len(".__init__")] if name.endswith(".__init__") else name] = f
    graph = {}
    for name, f in files.items():
        graph[name] = set()
        base = name.split(".") if f.endswith("__init__.py") else name.split(".")[:-1]
        for node in ast.walk(ast.parse(open(f, encoding="utf-8").read())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                module = ".".join((base[:len(base) - node.level + 1] if node.level else []) +
                                  ([node.module] if node.module else []))
                targets = [module + "." + a.name if module + "." + a.name in files else module
                           for a in node.names]
            else:
                continue
            graph[name].update(t for t in targets if t in files and t != name)
    return graph


def _cycles(graph):
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


@pytest.mark.parametrize("package", ["pathtracer", "bench"])
def test_no_import_cycles(package):
    graph = _import_graph(package)
    assert len(graph) > 10 and any(graph.values())
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
