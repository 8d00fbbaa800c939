"""The benchmark scripts parse their command lines (``--help`` works for each)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"


@pytest.mark.parametrize("script", sorted(p.name for p in BENCH.glob("bench_*.py")))
def test_benchmark_help(script):
    r = subprocess.run([sys.executable, str(BENCH / script), "--help"], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "usage:" in r.stdout


def _box(lo, hi, flip: bool = False):
    """A closed box mesh ``(vertices (8, 3), faces (12, 3))`` facing outwards, each
    square split along one diagonal (the other one with ``flip``)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[(hi if i >> k & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2),
             (1, 3, 7, 5)]  # -z, +z, -y, +y, -x, +x, counter-clockwise from outside
    faces = []
    for a, b, c, d in quads:
        faces += [(b, c, d), (b, d, a)] if flip else [(a, b, c), (a, c, d)]
    return v, np.array(faces)


def test_openscad_examples_drops_only_zero_thickness_sheets():
    """Two boxes touching along a face, both faces kept (OpenSCAD's export of touching
    parts): the doubly covered square is removed, leaving the closed union with the
    same volume; where the faces overlap only in part, nothing is removed."""
    trimesh = pytest.importorskip("trimesh")
    pytest.importorskip("shapely")
    spec = importlib.util.spec_from_file_location("openscad_examples",
                                                  BENCH / "openscad_examples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for shift, removed in ((0.0, 4), (0.5, 0)):
        va, fa = _box([0, 0, 0], [1, 1, 1])
        vb, fb = _box([1, shift, 0], [2, 1 + shift, 1], flip=True)
        both = trimesh.Trimesh(np.vstack([va, vb]), np.vstack([fa, fb + 8]))
        out, n = mod.drop_double_sheets(both)
        assert n == removed
        if removed:  # (four triangles met at each side of the shared square)
            assert not both.is_watertight and out.is_volume and len(out.faces) == 20
            assert out.volume == pytest.approx(2.0, abs=1e-12)
            assert out.area == pytest.approx(10.0, abs=1e-12)
        else:
            assert out is both


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_infer_structure_counts_only_rewritings_of_the_true_solid():
    """``bench_infer.structure``: a cut moved across a union it does not reach is the
    true structure (the same solid for the true primitives); moved across one it does
    reach, or with a kind changed, it is not."""
    bi = _load("bench_infer")
    eye = np.eye(3)
    leaves = [("box", eye, np.zeros(3), {"size_x": 1.0, "size_y": 1.0, "size_z": 1.0}),
              ("sphere", eye, np.array([0.0, 0.0, 0.8]), {"radius": 0.4}),
              ("cylinder", eye, np.array([0.55, 0.0, 0.0]), {"radius": 0.12, "height": 2.0}),
              ("sphere", eye, np.array([-0.5, 0.0, 0.0]), {"radius": 0.2})]
    truth = ("difference", ("union", 0, 1), 2)  # the cut misses the sphere on top

    class Res:
        primitives = [{"name": n, "kind": k, "translation": list(t)} for n, (k, _, t, _)
                      in zip(("box_1", "sphere_1", "cylinder_1"), leaves[:3])]

    box = bi.csdf.as_field(bi._shape_of(truth, leaves)).bounds
    res = Res()
    for text, same in (("((box_1 | sphere_1) - cylinder_1)", True),
                       ("((box_1 - cylinder_1) | sphere_1)", True),
                       ("((box_1 | cylinder_1) | sphere_1)", False),
                       ("(box_1 | sphere_1)", False)):
        assert bi.structure(res, truth, leaves[:3], box, text) is same, text
    # the cut reaches the second part: moving it across the union changes the solid
    leaves2 = [leaves[0], leaves[3], ("cylinder", eye, np.array([-0.5, 0.0, 0.0]),
                                      {"radius": 0.15, "height": 2.0})]
    res.primitives = [{"name": n, "kind": k, "translation": list(t)} for n, (k, _, t, _)
                      in zip(("box_1", "sphere_1", "cylinder_1"), leaves2)]
    truth2 = ("difference", ("union", 0, 1), 2)
    assert bi.structure(res, truth2, leaves2, box, "((box_1 | sphere_1) - cylinder_1)")
    assert not bi.structure(res, truth2, leaves2, box, "((box_1 - cylinder_1) | sphere_1)")


def test_infer_one_view_measures_see_only_what_the_sensor_sees():
    """``bench_infer.seen_leaves`` and ``view_structure``: a hole drilled into the back
    of a box is not seen from the front, where the box with a peg there looks the
    same; from behind both the hole and the difference are seen."""
    bi = _load("bench_infer")
    eye = np.eye(3)
    to_x = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # z -> x
    leaves = [("box", eye, np.zeros(3), {"size_x": 1.0, "size_y": 1.0, "size_z": 1.0}),
              ("cylinder", to_x, np.array([-0.6, 0.0, 0.0]), {"radius": 0.2,
                                                                "height": 0.8})]
    truth = ("difference", 0, 1)
    shape = bi._shape_of(truth, leaves)
    box = bi.csdf.as_field(shape).bounds

    class Res:
        primitives = [{"name": n, "kind": k, "translation": list(t)} for n, (k, _, t, _)
                      in zip(("box_1", "cylinder_1"), leaves)]

    front = bi.view_camera(np.array([5.0, 0.8, 0.6]), box)
    back = bi.view_camera(np.array([-5.0, 0.8, 0.6]), box)
    assert bi.seen_leaves(leaves, shape, front).tolist() == [True, False]
    assert bi.seen_leaves(leaves, shape, back).tolist() == [True, True]
    tol = 0.002 * float(np.linalg.norm(box[1] - box[0]))
    for text, from_front, from_back in (("(box_1 - cylinder_1)", True, True),
                                        ("(box_1 | cylinder_1)", True, False),
                                        ("(box_1 & cylinder_1)", False, False)):
        assert bi.view_structure(Res(), truth, leaves, front, tol, text) is from_front
        assert bi.view_structure(Res(), truth, leaves, back, tol, text) is from_back


def test_detect_counts_a_false_positive_turned_about_its_axis_as_a_turned_miss():
    """``bench_detect._turned``: a lamp detected in the right place with its spokes
    turned 60 degrees (half its symmetry's period) matches nothing, and is reported as
    a missed lamp turned wrong; moved 0.3 m it is not; a matched detection is not a
    false positive at all."""
    bd = _load("bench_detect")
    params = {p.name: p.default for p in bd.csdf.zoo.load("lamp").params}
    pose = bd.csdf.Pose(np.eye(3), np.array([0.5, 0.2, 3.0]))
    truth = [{"model": "lamp", "pose": pose, "params": params, "diameter": 0.5,
              "symmetries": bd.csdf.metrics.symmetries(bd.csdf.zoo.load("lamp")),
              "_points": bd._model_points("lamp", params)}]
    turned = bd.csdf.Pose(bd._rz(np.radians(60.0)), pose.translation)
    moved = bd.csdf.Pose(turned.rotation, pose.translation + [0.3, 0.0, 0.0])
    assert bd._matches([("lamp", turned)], truth) == []
    assert bd._turned([("lamp", turned)], truth, []) == ["lamp"]
    assert bd._turned([("lamp", moved)], truth, []) == []
    right = [("lamp", pose), ("lamp", turned)]
    m = bd._matches(right, truth)
    assert [i for _, i, _ in m] == [0]
    assert bd._turned(right, truth, m) == []  # the object is found: no turned miss
