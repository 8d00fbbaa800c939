"""OpenSCAD ``.csg`` import (issue 20, first increment): the reader, each node's
mapping, located errors, the ``transform`` domain op, polygons with holes, and the
``csdf import`` command. Tests that need the ``openscad`` program skip without it."""

from __future__ import annotations

import math
import os
import shutil
import subprocess

import numpy as np
import pytest
from typer.testing import CliRunner

import csdf
from csdf.cli import app
from csdf.errors import ModelError, ShapeError
from csdf.lang.csg import load_csg, loads_csg

RNG = np.random.default_rng(7)


def _f(shape, pts):
    return np.asarray(csdf.as_field(shape).value(np.asarray(pts, float)), float)


def _brute_box(p, lo, hi):
    """Exact signed distance to an axis-aligned box (reference)."""
    c, h = (lo + hi) / 2, (hi - lo) / 2
    q = np.abs(p - c) - h
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def test_cube_sphere_cylinder_and_centering():
    s = loads_csg("cube(size = [2, 4, 6], center = false);")
    p = RNG.uniform(-3, 8, (400, 3))
    assert np.allclose(_f(s, p), _brute_box(p, np.zeros(3), np.array([2, 4, 6])), atol=1e-12)
    s = loads_csg("sphere($fn = 0, $fa = 12, $fs = 2, r = 3);")
    assert np.allclose(_f(s, p), np.linalg.norm(p, axis=1) - 3, atol=1e-12)
    # cylinder: not centred spans z in [0, h]; r1 at the bottom
    s = loads_csg("cylinder($fn = 0, $fa = 12, $fs = 2, h = 4, r1 = 2, r2 = 2, "
                  "center = false);")
    assert np.allclose(_f(s, [[0, 0, 2], [0, 0, 5], [3, 0, 2]]), [-2, 1, 1], atol=1e-12)
    cone = loads_csg("cylinder(h = 4, r1 = 2, r2 = 0, center = true);")
    assert np.allclose(_f(cone, [[0, 0, -2.5], [0, 0, 2.5]]), [0.5, 0.5], atol=1e-12)
    down = loads_csg("cylinder(h = 4, r1 = 0, r2 = 2, center = false);")  # apex at z = 0
    assert _f(down, [[0, 0, -0.5]])[0] == pytest.approx(0.5)
    assert _f(down, [[1.9, 0, 3.9]])[0] < 0 and _f(down, [[1.9, 0, 0.1]])[0] > 0


def test_boolean_nodes_modifiers_and_groups():
    text = """
    // a comment
    group() {
        difference() {
            cube(size = [10, 10, 10], center = true);
            sphere(r = 6);
            %cube(size = 100);          /* background: not part of the model */
        }
        *sphere(r = 50);               // disabled
        intersection() { sphere(r = 2); cube(size = 3, center = true); }
    }
    """
    s = loads_csg(text)
    assert _f(s, [[0, 0, 5.5]])[0] == pytest.approx(0.5)  # the sphere cut the box
    assert _f(s, [[0, 0, 0]])[0] == pytest.approx(-1.5)  # inside the intersection
    root = loads_csg("sphere(r = 1); !cube(size = 2, center = true);")
    assert _f(root, [[0, 0, 0]])[0] == pytest.approx(-1)  # only the ! statement


def test_multmatrix_rigid_scaled_mirrored_and_sheared():
    child = "cube(size = [2, 2, 2], center = true);"
    c, s_ = math.cos(0.3), math.sin(0.3)
    rigid = loads_csg(f"multmatrix([[{c}, {-s_}, 0, 1], [{s_}, {c}, 0, 2], [0, 0, 1, 3], "
                      f"[0, 0, 0, 1]]) {{ {child} }}")
    assert rigid.exactness == "exact"
    p = RNG.uniform(-4, 6, (300, 3))
    R = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
    q = (p - [1, 2, 3]) @ R
    assert np.allclose(_f(rigid, p), _brute_box(q, -np.ones(3), np.ones(3)), atol=1e-12)
    mirrored = loads_csg("multmatrix([[-2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], "
                         "[0, 0, 0, 1]]) { cube(size = [1, 1, 1]); }")
    assert mirrored.exactness == "exact"
    ref = _brute_box(p, np.array([-2, 0, 0]), np.array([0, 2, 2]))
    assert np.allclose(_f(mirrored, p), ref, atol=1e-12)
    sheared = loads_csg(f"multmatrix([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 3, 0], "
                        f"[0, 0, 0, 1]]) {{ {child} }}")
    assert sheared.exactness != "exact"
    # a bound: never more than the distance to the sheared box's surface samples
    surf = np.concatenate([RNG.uniform(-1, 1, (2000, 3))])
    surf[np.arange(2000), RNG.integers(0, 3, 2000)] = RNG.choice([-1.0, 1.0], 2000)
    A = np.array([[1, 0.5, 0], [0, 1, 0], [0, 0, 3]])
    world = surf @ A.T
    far = RNG.uniform(-5, 5, (200, 3))
    d_true_upper = np.min(np.linalg.norm(far[:, None] - world[None], axis=2), axis=1)
    got = _f(sheared, far)
    outside = got > 0
    assert np.all(got[outside] <= d_true_upper[outside] + 1e-9)


def test_transform_method_checks_its_matrix():
    b = csdf.box(1.0)
    with pytest.raises(ShapeError, match="singular"):
        b.transform([[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    with pytest.raises(ShapeError, match="4x4"):
        b.transform([[1, 0], [0, 1]])
    with pytest.raises(ShapeError, match="last row"):
        b.transform([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]])
    sq = csdf.rectangle(1.0).transform([[2, 0, 1], [0, 2, 0], [0, 0, 1]])
    assert sq.exactness == "exact"
    assert np.allclose(np.asarray(sq.bounds), [[0, -1], [2, 1]])


def test_polygon_with_holes_is_exact_even_odd():
    text = ("linear_extrude(height = 2, center = true) { polygon(points = [[0, 0], [10, 0], "
            "[10, 10], [0, 10], [3, 3], [7, 3], [7, 7], [3, 7]], paths = [[0, 1, 2, 3], "
            "[4, 5, 6, 7]], convexity = 2); }")
    s = loads_csg(text)
    assert s.exactness == "exact"
    vals = _f(s, [[5, 5, 0], [1.5, 5, 0], [5, 5, 3]])
    assert np.allclose(vals, [2.0, -1.0, math.hypot(2.0, 2.0)], atol=1e-12)
    poly = csdf.polygon([[0, 0], [4, 0], [4, 4], [0, 4], [1, 1], [3, 1], [3, 3], [1, 3]],
                        paths=[[0, 1, 2, 3], [4, 5, 6, 7]])
    solid = csdf.extrude(poly, 1.0)
    back = csdf.loads(csdf.dumps(solid))
    p = RNG.uniform(-1, 5, (200, 3))
    assert np.allclose(_f(back, p), _f(solid, p), atol=1e-12)
    with pytest.raises(ShapeError, match=r"paths\[0\]"):
        csdf.polygon([[0, 0], [1, 0], [0, 1]], paths=[[0, 1, 5]])


def test_extrusions_offset_minkowski_and_hull():
    ring = loads_csg("rotate_extrude(angle = 360, convexity = 2) { multmatrix([[1, 0, 0, 5], "
                     "[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) { circle(r = 1); } }")
    assert ring.exactness == "exact"
    assert np.allclose(_f(ring, [[5, 0, 0], [0, 6, 0], [0, 0, 0]]), [-1, 0, 4], atol=1e-12)
    off = loads_csg("linear_extrude(height = 1) { offset(r = 1) { square(size = [2, 2]); } }")
    assert _f(off, [[-1, 1, 0.5]])[0] == pytest.approx(0, abs=1e-12)
    mink = loads_csg("minkowski() { cube(size = [2, 2, 2], center = true); "
                     "multmatrix([[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) "
                     "{ sphere(r = 0.5); } }")
    assert _f(mink, [[3, 0, 1.5]])[0] == pytest.approx(0, abs=1e-12)
    assert _f(mink, [[3, 0, 0]])[0] == pytest.approx(-1.5, abs=1e-12)
    hull = loads_csg("hull() { sphere(r = 1); multmatrix([[1, 0, 0, 4], [0, 1, 0, 0], "
                     "[0, 0, 1, 0], [0, 0, 0, 1]]) { sphere(r = 2); } }")
    assert hull.exactness == "exact"
    assert np.allclose(_f(hull, [[-1, 0, 0], [6, 0, 0], [4, 0, 0]]), [0, 0, -2], atol=1e-9)
    tw = loads_csg("linear_extrude(height = 10, twist = 90) { square(size = [4, 1], "
                   "center = true); }")
    assert tw.exactness == "neither"
    # OpenSCAD turns clockwise seen from +z: at the top the long side lies along y
    assert _f(tw, [[0, 1.8, 9.9]])[0] < 0 and _f(tw, [[1.8, 0, 9.9]])[0] > 0
    assert _f(tw, [[1.8, 0, 0.1]])[0] < 0
    cone = loads_csg("linear_extrude(height = 10, scale = 0.5) { circle(r = 2); }")
    assert cone.exactness == "neither"
    assert _f(cone, [[1.9, 0, 0.1]])[0] < 0 and _f(cone, [[1.9, 0, 9.9]])[0] > 0
    assert _f(cone, [[0.9, 0, 9.9]])[0] < 0
    with pytest.raises(ModelError, match="non-uniform scale"):
        loads_csg("linear_extrude(height = 1, scale = [1, 2]) { circle(r = 1); }")


@pytest.mark.parametrize("text, where, match", [
    ("cube(size = [1, 1, 1]);\nsphere(r = 1", (2, 12), "syntax"),
    ("group() {\n  text(text = \"a\");\n}", (2, 3), "text: not supported"),
    ("group() {\n  polyhedron(points = [[0, 0, 0]], faces = [[0]]);\n}", (2, 3),
     "polyhedron: not read yet"),
    ("frobnicate();", (1, 1), "frobnicate: unknown node"),
    ("sphere(r = -1);", (1, 1), "r must be > 0"),
    ("cube(size = [1, 1]);", (1, 1), "size must be 3 finite numbers"),
    ("multmatrix([[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) { cube(); }",
     (1, 1), "singular"),
    ("group() { cube(); circle(r = 1); }", (1, 11), "mixes 2D and 3D"),
    ("rotate_extrude(angle = 90) { square(size = 1); }", (1, 1), "partial turn"),
    ("hull() { cube(); sphere(r = 1); }", (1, 1), "hull of two spheres"),
])
def test_errors_are_located(text, where, match):
    with pytest.raises(ModelError, match=match) as ei:
        loads_csg(text, file="m.csg")
    assert (ei.value.line, ei.value.column) == where
    assert ei.value.file == "m.csg"


def test_empty_model_facets_and_limits():
    with pytest.raises(ModelError, match="no geometry"):
        loads_csg("group() { %sphere(r = 1); }")
    with pytest.raises(csdf.CsdfError, match="facets"):
        loads_csg("sphere(r = 1);", facets="round")
    with pytest.raises(ModelError, match="facets='openscad'"):
        loads_csg("sphere(r = 1);", facets="openscad")


def test_load_and_cli_import(tmp_path):
    src = tmp_path / "part.csg"
    src.write_text("difference() { cube(size = [4, 4, 4], center = true); "
                   "cylinder(h = 10, r1 = 1, r2 = 1, center = true); }\n")
    s = csdf.load(src)
    assert _f(s, [[0, 0, 0]])[0] == pytest.approx(1.0)
    assert np.allclose(_f(load_csg(src), [[1.5, 0, 0]]), _f(s, [[1.5, 0, 0]]))
    out = tmp_path / "part.csdf"
    res = CliRunner().invoke(app, ["import", str(src), "-o", str(out)])
    assert res.exit_code == 0, res.output
    back = csdf.load(out)
    p = RNG.uniform(-3, 3, (200, 3))
    assert np.allclose(_f(back, p), _f(s, p), atol=1e-12)
    res = CliRunner().invoke(app, ["info", str(src)])
    assert res.exit_code == 0 and "instructions" in res.output
    bad = tmp_path / "bad.csg"
    bad.write_text("group() {\n  import(file = \"x.stl\");\n}\n")
    res = CliRunner().invoke(app, ["import", str(bad), "-o", str(tmp_path / "bad.csdf")])
    assert res.exit_code != 0 and "bad.csg:2:3" in res.output
    assert not (tmp_path / "bad.csdf").exists()


def test_scad_through_openscad(tmp_path):
    if shutil.which("openscad") is None:
        if os.environ.get("CSDF_REQUIRE_TOOLS") == "1":
            pytest.fail("CSDF_REQUIRE_TOOLS=1 but the openscad program is not on PATH")
        pytest.skip("needs the openscad program (apt-get install openscad)")
    scad = tmp_path / "m.scad"
    scad.write_text("r = 2;\nmodule peg(h) { cylinder(h = h, r = r / 2); }\n"
                    "difference() { cube([8, 8, 3]); translate([4, 4, -1]) peg(5); }\n"
                    "for (i = [0:1]) translate([10 + 5 * i, 0, 0]) sphere(r = r);\n")
    s = csdf.load(scad)
    assert _f(s, [[4, 4, 1.5]])[0] == pytest.approx(1.0)  # in the hole, 1 from its wall
    assert _f(s, [[15, 0, 0]])[0] == pytest.approx(-2.0)
    # the same model through OpenSCAD's own CSG export
    csg = tmp_path / "m.csg"
    subprocess.run(["openscad", "-o", str(csg), str(scad)], check=True, capture_output=True,
                   timeout=120)
    p = RNG.uniform(-2, 18, (300, 3))
    assert np.allclose(_f(load_csg(csg), p), _f(s, p), atol=1e-12)
    broken = tmp_path / "broken.scad"
    broken.write_text("cube([1, 1, 1]\n")
    with pytest.raises(csdf.CsdfError, match="openscad failed"):
        csdf.load(broken)
