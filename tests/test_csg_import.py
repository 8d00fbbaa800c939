"""OpenSCAD ``.csg`` import (issue 20, first increment): the reader, each node's
mapping, located errors, the ``transform`` domain op, polygons with holes, and the
``csdf import`` command. Tests that need the ``openscad`` program skip without it."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
from pathlib import Path

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
    oval = loads_csg("linear_extrude(height = 1, scale = [1, 2]) { circle(r = 1); }")
    assert _f(oval, [[0, 1.9, 0.99]])[0] < 0 < _f(oval, [[1.1, 0, 0.99]])[0]


#: an L-shaped prism (non-convex), as OpenSCAD prints it
_L_POLYHEDRON = (
    "polyhedron(points = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0], "
    "[0, 0, 1], [2, 0, 1], [2, 1, 1], [1, 1, 1], [1, 2, 1], [0, 2, 1]], faces = [[5, 4, 3, "
    "2, 1, 0], [6, 7, 8, 9, 10, 11], [0, 1, 7, 6], [1, 2, 8, 7], [2, 3, 9, 8], [3, 4, 10, 9], "
    "[4, 5, 11, 10], [5, 0, 6, 11]], convexity = 1);")


def test_non_convex_polyhedron_is_the_exact_distance_to_its_surface():
    from csdf.io import loads_csg

    shape = loads_csg(_L_POLYHEDRON)  # an L-shaped prism: 2 x 2 x 1 less a 1 x 1 corner
    assert shape.name == "polyhedron" and shape.exactness == "exact"
    p = np.array([[1.5, 1.5, 1.5], [0.5, 0.5, 0.5], [1.2, 1.1, 0.5], [0.5, 1.5, 0.5]])
    # above the notch (nearest: an edge), inside, in the notch, inside the arm
    np.testing.assert_allclose(shape(p), [np.hypot(0.5, 0.5), -0.5, 0.1, -0.5],
                               atol=1e-12)
    m = csdf.mesh(shape, resolution=64)
    assert m.is_watertight and abs(m.volume - 3.0) < 0.03


@pytest.mark.parametrize("text, where, match", [
    ("cube(size = [1, 1, 1]);\nsphere(r = 1", (2, 12), "syntax"),
    ("group() {\n  text(text = \"a\");\n}", (2, 3), "text: not supported"),
    ("group() {\n  polyhedron(points = [[0, 0, 0]], faces = [[0]]);\n}", (2, 3),
     "polyhedron: points must be at least 4"),
    (f"group() {{\n  {_L_POLYHEDRON.replace(', [5, 0, 6, 11]', '')}\n}}", (2, 3),
     "polyhedron: the mesh is not closed: edge"),
    ("hull() { polygon(points = [[0, 0], [1, 0], [2, 0]]); }", (1, 1),
     "hull: .*on one line"),
    ("frobnicate();", (1, 1), "frobnicate: unknown node"),
    ("sphere(r = -1);", (1, 1), "r must be > 0"),
    ("cube(size = [1, 1]);", (1, 1), "size must be 3 finite numbers"),
    ("multmatrix([[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) { cube(); }",
     (1, 1), "singular"),
    ("group() { cube(); circle(r = 1); }", (1, 11), "mixes 2D and 3D"),
    ("rotate_extrude(angle = 0) { square(size = 1); }", (1, 1), "non-zero"),
    ("hull() { cube(); circle(r = 1); }", (1, 1), "hull: mixes 2D and 3D"),
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
    assert loads_csg("sphere(r = 1);", facets="openscad").name == "convex_polyhedron"


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
    # OpenSCAD's facets: the cylinder's hole becomes a prism (the default $fn: 5 sides)
    faceted = tmp_path / "faceted.csdf"
    res = CliRunner().invoke(app, ["import", str(src), "-o", str(faceted), "--facets",
                                   "openscad"])
    assert res.exit_code == 0, res.output
    assert np.allclose(_f(csdf.load(faceted), p), _f(load_csg(src, "openscad"), p),
                       atol=1e-12)
    res = CliRunner().invoke(app, ["import", str(src), "-o", str(faceted), "--facets", "x"])
    assert res.exit_code != 0 and "facets" in res.output
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


# -------------------------------------------------------------- facets='openscad', hull
def _need_openscad() -> None:
    if shutil.which("openscad") is None:
        if os.environ.get("CSDF_REQUIRE_TOOLS") == "1":
            pytest.fail("CSDF_REQUIRE_TOOLS=1 but the openscad program is not on PATH")
        pytest.skip("needs the openscad program (apt-get install openscad)")


def _stl(tmp_path, scad: str):
    """OpenSCAD's own mesh of ``scad`` (a trimesh)."""
    import trimesh

    src = tmp_path / "m.scad"
    src.write_text(scad)
    out = tmp_path / "m.stl"
    subprocess.run(["openscad", "-o", str(out), str(src)], check=True, capture_output=True,
                   timeout=120)
    return trimesh.load(out, force="mesh")


def _planes_of(mesh) -> int:
    """Distinct face planes of a triangle mesh (coplanar triangles merged)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = mesh.face_normals
    d = np.einsum("ij,ij->i", n, mesh.triangles[:, 0])
    pairs = cKDTree(np.column_stack([n, d / mesh.scale])).query_pairs(1e-4,
                                                                      output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(n), len(n)))
    return connected_components(graph, directed=False)[0]


def test_fragments_follow_openscad_rules():
    from csdf.lang.csg import circle_points, fragments, sphere_points

    assert fragments(10) == 30 and fragments(1) == 5 and fragments(3) == 10
    assert fragments(3, fs=0.5, fa=5) == 38 and fragments(3, fn=2) == 3
    assert fragments(3, fn=12.7) == 12 and fragments(1e-7) == 3
    assert fragments(100, fs=0.0, fa=0.0) == 36000  # $fa, $fs raised to 0.01
    c = circle_points(2.0, 6)
    assert np.array_equal(c[0], [2, 0]) and c[3, 1] == 0.0  # exact on the axes
    s = sphere_points(10.0, 12)  # 6 rings of 12 at polar angles 15, 45, ... 165
    assert s.shape == (72, 3)
    assert np.allclose(np.unique(np.round(s[:, 2], 9)),
                       np.round(10 * np.cos(np.radians([165, 135, 105, 75, 45, 15])), 9))
    with pytest.raises(ModelError, match="sphere: 2000 segments make more than") as ei:
        loads_csg("sphere($fn = 2000, r = 1);", file="m.csg", facets="openscad")
    assert (ei.value.line, ei.value.column) == (1, 1)


@pytest.mark.parametrize("scad", [
    "sphere(r = 10, $fn = 12);", "sphere(r = 3);", "sphere(r = 2, $fn = 7);",
    "cylinder(r1 = 3, r2 = 1, h = 5, center = true);",
    "cylinder(r1 = 3, r2 = 0, h = 5, $fn = 7);",
    "circle(r = 4, $fn = 9);",
])
def test_faceted_curves_match_openscads_stl(scad, tmp_path):
    _need_openscad()
    from scipy.spatial import cKDTree

    csg = tmp_path / "m.csg"
    (tmp_path / "m.scad").write_text(scad)
    subprocess.run(["openscad", "-o", str(csg), str(tmp_path / "m.scad")], check=True,
                   capture_output=True, timeout=120)
    shape = load_csg(csg, facets="openscad")
    if shape.dim == 2:  # a circle: a polygon with OpenSCAD's vertices
        ref = _stl(tmp_path, f"linear_extrude(height = 1) {scad}")
        ours = np.asarray(shape.args[0])
        theirs = np.unique(np.round(ref.vertices[:, :2], 5), axis=0)
        assert len(ours) == len(theirs)
        assert cKDTree(ours).query(theirs)[0].max() < 2e-5
        return
    ref = _stl(tmp_path, scad)
    ours = np.unique(np.asarray(shape.args[0]), axis=0)
    theirs = np.unique(np.round(ref.vertices, 5), axis=0)
    assert len(ours) == len(theirs)  # the same vertices ...
    assert cKDTree(ours).query(theirs)[0].max() < 2e-5  # (STL prints 6 digits)
    assert abs(_f(shape, ref.vertices)).max() < 2e-5  # ... on the field's zero set
    # ... and the same faces (OpenSCAD's triangles merged into planes)
    from csdf.shapes.convex import hull_planes

    assert len(hull_planes(ours)[0]) == _planes_of(ref)
    assert shape.exactness == "bound"


def test_faceted_rotate_extrude_passes_through_openscads_vertices(tmp_path):
    _need_openscad()
    for scad in ("rotate_extrude() translate([5, 0]) circle(r = 1, $fn = 6);",
                 "rotate_extrude($fn = 8) translate([1, 0]) square([4, 1]);"):
        ref = _stl(tmp_path, scad)
        src = tmp_path / "m.scad"
        src.write_text(scad)
        shape = csdf.io.load_scad(src, facets="openscad")
        assert shape.exactness == "bound"
        assert abs(_f(shape, ref.vertices)).max() < 2e-5
        centres = ref.triangles.mean(axis=1)  # the faces are flat: their centres too
        assert abs(_f(shape, centres)).max() < 2e-5


def test_partial_rotate_extrude_resize_and_cut_projection_match_openscad(tmp_path):
    """The nodes read as documented bounds: partial turns (faceted as OpenSCAD does
    where a whole faceting of the turn fits, else the true curve), resize (a scale by
    the children's box) and projection with cut (the section at z = 0)."""
    _need_openscad()
    cases = [  # (scad, all of OpenSCAD's vertices and face centres on the zero set?)
        ("rotate_extrude(angle = 90) translate([10, 0]) square([3, 5]);", True),
        ("rotate_extrude(angle = -200) translate([10, 0]) circle(r = 3, $fn = 40);",
         False),
        ("resize([30, 0, 10], auto = [false, true, false]) "
         "cylinder(r1 = 4, r2 = 2, h = 6, $fn = 24);", True),
        ("linear_extrude(height = 2) projection(cut = true) translate([0, 0, -1]) "
         "rotate([30, 20, 0]) cube([10, 8, 6], center = true);", True),
    ]
    for scad, flat in cases:
        ref = _stl(tmp_path, scad)
        src = tmp_path / "m.scad"
        src.write_text(scad)
        shape = csdf.io.load_scad(src, facets="openscad")
        assert shape.exactness == "bound", scad
        diag = float(np.linalg.norm(ref.bounds[1] - ref.bounds[0]))
        assert abs(_f(shape, ref.vertices)).max() < 1e-5 * diag, scad
        centres = ref.triangles.mean(axis=1)
        err = abs(_f(shape, centres)).max() / diag
        assert err < 1e-5 if flat else err < 5e-3, (scad, err)  # (curve vs facets)
        m = csdf.mesh(shape, resolution=128, method="dc", progress=False)
        assert abs(m.volume / ref.volume - 1) < (0.01 if flat else 0.02), scad


@pytest.mark.parametrize("scad", [
    "linear_extrude(height = 20, twist = 90) square([20, 10], center = true);",
    "linear_extrude(height = 40, center = true, twist = -360, slices = 200, scale = 0) "
    "square([20, 10], center = true);",
    "linear_extrude(height = 30, twist = 150, scale = [1.5, 0.5]) difference() { "
    "circle(r = 10); translate([3, 0]) square([4, 3], center = true); }",
    "linear_extrude(height = 10, scale = [2, 0.5]) polygon([[0, 0], [10, 0], [10, 5], "
    "[5, 2], [0, 5]]);",
    "linear_extrude(height = 25, twist = -250, scale = 0.6, $fn = 17) difference() { "
    "circle(r = 8); translate([2, 1]) circle(r = 3); square([1, 12], center = true); }",
    "linear_extrude(height = 12, twist = 45, scale = [0.3, 1.7]) polygon(points = [[0, 0], "
    "[10, 0], [10, 10], [0, 10], [3, 3], [7, 3], [7, 7], [3, 7]], paths = [[0, 1, 2, 3], "
    "[4, 5, 6, 7]]);",
])
def test_twisted_and_unevenly_scaled_extrusions_are_openscads_surface(scad, tmp_path):
    """facets='openscad': the same slices, vertices and triangles as OpenSCAD's export
    (every vertex and every face centre of its STL on csdf's zero set), as a polyhedron;
    the ideal mode keeps the smooth twist."""
    _need_openscad()
    pytest.importorskip("shapely")
    ref = _stl(tmp_path, scad)
    src = tmp_path / "m.scad"
    src.write_text(scad)
    shape = csdf.io.load_scad(src, facets="openscad")
    assert shape.name == "polyhedron" and shape.exactness == "exact"
    tol = 1e-5 * float(np.abs(ref.bounds).max())  # (the STL prints 6 digits)
    assert abs(_f(shape, ref.vertices)).max() < tol
    assert abs(_f(shape, ref.triangles.mean(axis=1))).max() < tol
    data = shape.compile().data[0]
    assert len(data.faces) == len(ref.faces)
    assert data.volume == pytest.approx(ref.volume, rel=1e-5)
    if "scale = [" not in scad:  # the ideal mode: a smooth twist (no uneven scale)
        assert csdf.io.load_scad(src).name != "polyhedron"


def test_uneven_scale_in_the_ideal_mode_is_a_taper_of_x_and_y_apart(tmp_path):
    scad = ("linear_extrude(height = 10, scale = [2, 0.5]) polygon([[0, 0], [10, 0], "
            "[10, 5], [5, 2], [0, 5]]);")
    src = tmp_path / "m.scad"
    src.write_text(scad)
    shape = loads_csg(scad.replace("polygon([", "polygon(points = ["))
    assert shape.exactness == "neither" and np.isfinite(shape.lipschitz)
    # the section at height z is the polygon scaled by (1 + z / 10, 1 - z / 20)
    p = np.array([[14.0, 1.0, 5.0], [16.0, 1.0, 5.0], [7.5, 0.5, 10.0]])
    v = _f(shape, p)
    assert v[0] < 0 < v[1] and abs(v[2]) < 1e-12  # (the last on the top face)
    taper = csdf.box(1).taper((0.5, -0.25))
    assert csdf.loads(csdf.dumps(taper)).compile() == taper.compile()
    with pytest.raises(csdf.ShapeError, match="pair"):
        csdf.box(1).taper((0.1, 0.2, 0.3))
    if shutil.which("openscad") is not None:  # OpenSCAD's slices lie on the taper
        ref = _stl(tmp_path, scad)
        assert abs(_f(csdf.io.load_scad(src), ref.vertices)).max() < 1e-4


def test_twisted_uneven_scale_in_the_ideal_mode_turns_then_scales(tmp_path):
    """As OpenSCAD places its slices: each section turned by the twist, then scaled
    along x and y (an uneven scale does not commute with the turn), so every vertex of
    OpenSCAD's STL lies on the smooth surface of the ideal mode."""
    _need_openscad()
    scad = ("linear_extrude(height = 30, twist = 150, scale = [1.5, 0.5]) polygon([[0, 0], "
            "[10, 0], [10, 5], [5, 2], [0, 5]]);")
    ref = _stl(tmp_path, scad)
    src = tmp_path / "m.scad"
    src.write_text(scad)
    shape = csdf.io.load_scad(src)
    assert shape.name != "polyhedron"
    assert abs(_f(shape, ref.vertices)).max() < 1e-4


def test_colours_are_kept_on_the_shape():
    from csdf.shapes.appearance import colors

    s = loads_csg("color([1, 0, 0, 1]) { cube(size = [2, 2, 2]); }\n"
                  "color([0.2, 0.4, 0.6, 0.5]) { sphere(r = 1); }\n"
                  "color([-1, -1, -1, 1]) { cylinder(h = 1, r1 = 1, r2 = 1); }")
    assert sorted(c for _, c in colors(s)) == [(0.2, 0.4, 0.6, 0.5), (1.0, 0.0, 0.0, 1.0)]
    plain = loads_csg("cube(size = [2, 2, 2]); sphere(r = 1); cylinder(h = 1, r1 = 1, "
                      "r2 = 1);")
    np.testing.assert_array_equal(s.compile().code, plain.compile().code)  # the geometry
    back = csdf.loads(csdf.dumps(s))
    assert sorted(c for _, c in colors(back)) == sorted(c for _, c in colors(s))
    with pytest.raises(csdf.ShapeError, match=r"color\[1\] = 2 is outside"):
        csdf.box(1).color((0.5, 2, 0))
    with pytest.raises(csdf.ShapeError, match="3 or 4 numbers"):
        csdf.box(1).color("red")


def test_openscad_slice_counts():
    from csdf.lang.csg import diagonal_slices, helix_slices

    # measured on openscad 2021.01's STL exports (distinct z levels - 1)
    assert helix_slices(125.0, 20.0, 90.0) == 8
    assert helix_slices(125.0, 20.0, 90.0, fn=8) == 2
    assert helix_slices(1.25, 20.0, 200.0) == 11
    assert helix_slices(125.0, 50.0, 90.0) == 8
    assert diagonal_slices(106.25, 10.0) == 8
    assert diagonal_slices(106.25, 40.0) == 21
    assert diagonal_slices(400.0, 1.0) == 11
    assert diagonal_slices(400.0, 1.0, fn=5) == 5


_TWISTED = [
    "linear_extrude(height = 20, twist = 90) square(size = [20, 10], center = true);",
    "linear_extrude(height = 30, twist = 150, scale = [1.5, 0.5]) difference() { "
    "circle(r = 10); multmatrix([[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 0], "
    "[0, 0, 0, 1]]) square(size = [4, 3], center = true); }",
    "linear_extrude(height = 12, scale = [0.3, 1.7], center = true) polygon(points = "
    "[[0, 0], [10, 0], [10, 10], [0, 10]]);",
]


@pytest.mark.parametrize("scad", _TWISTED)
def test_hull_of_a_twisted_extrusion_has_the_surfaces_slices(scad):
    """facets='openscad': a hull around a twisted or unevenly scaled extrusion takes
    the points of OpenSCAD's slices, as the ruled surface has them (one slice count,
    the same turn-then-scale placement): each hull vertex is a vertex of the surface,
    and every vertex of the surface lies in the hull."""
    pytest.importorskip("shapely")
    surface = loads_csg(scad, facets="openscad")
    verts = surface.compile().data[0].vertices
    hull = loads_csg(f"hull() {{ {scad} }}", facets="openscad")
    corners = np.asarray(hull.args[0])
    gap = np.linalg.norm(corners[:, None, :] - verts[None, :, :], axis=2).min(axis=1)
    assert gap.max() < 1e-12
    assert _f(hull, verts).max() < 1e-9


def test_resize_of_a_twisted_extrusion_matches_openscad(tmp_path):
    """resize scales by the box of OpenSCAD's slices (not of the first and last
    slices alone): every vertex of OpenSCAD's STL on csdf's zero set."""
    _need_openscad()
    pytest.importorskip("shapely")
    scad = f"resize([30, 0, 10], auto = [false, true, false]) {_TWISTED[0]}"
    ref = _stl(tmp_path, scad)
    src = tmp_path / "m.scad"
    src.write_text(scad)
    shape = csdf.io.load_scad(src, facets="openscad")
    diag = float(np.linalg.norm(ref.bounds[1] - ref.bounds[0]))
    assert abs(_f(shape, ref.vertices)).max() < 1e-5 * diag
    np.testing.assert_allclose(shape.bounds, ref.bounds, atol=1e-4)


def test_partial_revolve_and_cross_section_fields():
    ring = csdf.revolve(csdf.circle(0.2).translate((0.6, 0)), angle=math.pi / 2)
    p = np.array([[0.6, -0.3, 0], [-0.6, 0, 0], [0, 0.6, 0.3], [0.42, 0.42, 0]])
    # outside past the start face, behind the axis (a bound: the wedge's apex is 0.6
    # away, the end face 0.72), above the end face, inside the sweep
    np.testing.assert_allclose(ring(p), [0.3, 0.6, 0.1, 0.6 - np.hypot(0.42, 0.42) - 0.2],
                               atol=1e-12)
    back = csdf.revolve(csdf.circle(0.2).translate((0.6, 0)), angle=-1.5 * math.pi)
    assert back([[0.6, 0.01, 0]])[0] == pytest.approx(0.01)  # clockwise: +y is cut off
    assert back([[0.6, -0.01, 0]])[0] < 0
    assert ring.exactness == "bound" and csdf.revolve(csdf.circle(0.2).translate(
        (0.6, 0))).exactness == "exact"
    with pytest.raises(csdf.ShapeError, match="within"):
        csdf.revolve(csdf.circle(0.2), angle=7.0)
    with pytest.raises(csdf.ShapeError, match="a number"):
        csdf.revolve(csdf.circle(0.2), angle=csdf.param("a", 1.0))
    sec = csdf.cross_section(csdf.sphere(1.0), 0.6)
    assert sec.dim == 2 and sec.exactness == "bound"
    np.testing.assert_allclose(sec([[0, 0], [0.8, 0], [2, 0]]), [-0.4, 0.0, np.sqrt(4.36) - 1])
    for s in (ring, csdf.extrude(sec, 1.0)):
        assert csdf.loads(csdf.dumps(s)).compile() == s.compile()
    with pytest.raises(ModelError, match="cut = false"):
        loads_csg("projection(cut = false) { sphere(r = 2); }")


def test_convex_polyhedron_distances():
    import trimesh

    pts = RNG.normal(size=(40, 3)) * [1.0, 0.7, 0.5]
    shape = csdf.convex_polyhedron(pts)
    assert shape.exactness == "bound" and shape.lipschitz == 1.0
    hull = trimesh.convex.convex_hull(pts)
    q = RNG.uniform(-2.5, 2.5, (1500, 3))
    f = _f(shape, q)
    d = trimesh.proximity.closest_point(hull, q)[1]
    inside = hull.contains(q)
    assert inside.sum() > 50 and (~inside).sum() > 50
    assert np.allclose(f[inside], -d[inside], atol=1e-9)  # exact inside
    assert np.all(f[~inside] > 0) and np.all(f[~inside] <= d[~inside] + 1e-9)  # a bound
    near_face = ~inside & (f > d - 1e-9)  # and exact where the nearest point is on a face
    assert near_face.sum() > 10
    assert np.allclose(np.asarray(shape.bounds), hull.bounds)
    # the same solid given as planes, and through the language
    n = hull.face_normals
    planes = np.column_stack([n, np.einsum("ij,ij->i", n, hull.triangles[:, 0])])
    assert np.allclose(_f(csdf.convex_polyhedron(planes=planes * 3.0), q), f, atol=1e-9)
    back = csdf.loads(csdf.dumps(shape))
    assert back.compile().to_bytes() == shape.compile().to_bytes()
    # coplanar facets merged: a cube's 12 triangles are 6 planes (a balanced max tree)
    cube = csdf.convex_polyhedron([[x, y, z] for x in (0, 1) for y in (0, 2) for z in (0, 3)])
    inner = q[np.all((q > 0) & (q < [1, 2, 3]), axis=1)]
    assert np.allclose(_f(cube, inner), _brute_box(inner, np.zeros(3), np.array([1, 2, 3])))
    assert len(cube.compile().code) == 11  # 6 planes (x - 1, -x, ...) and 5 max
    with pytest.raises(ShapeError, match="one plane"):
        csdf.convex_polyhedron([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    with pytest.raises(ShapeError, match="finite region"):
        csdf.convex_polyhedron(planes=[[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1],
                                       [1, 1, 1, 1]])
    with pytest.raises(ShapeError, match="not both"):
        csdf.convex_polyhedron(pts, planes=planes)
    with pytest.raises(ShapeError, match="parameters cannot"):
        csdf.convex_polyhedron([[csdf.param("a", 1.0), 0, 0], [0, 1, 0], [0, 0, 1],
                                [0, 0, 0]])


def test_convex_polyhedron_node_and_hull_of_cube_and_sphere():
    import trimesh

    # a convex polyhedron node (OpenSCAD's example011 is one) is read exactly
    pyr = loads_csg("polyhedron(points = [[10, 10, 0], [10, -10, 0], [-10, -10, 0], "
                    "[-10, 10, 0], [0, 0, 10]], faces = [[0, 1, 4], [1, 2, 4], [2, 3, 4], "
                    "[3, 0, 4], [1, 0, 3], [2, 1, 3]], convexity = 1);")
    assert _f(pyr, [[0, 0, 5], [0, 0, 10], [0, 0, -1]]).round(9).tolist() == \
        [round(-5 / math.sqrt(2), 9), 0.0, 1.0]
    text = ("hull() { cube(size = [2, 2, 2], center = true); multmatrix([[1, 0, 0, 3], "
            "[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) { sphere(r = 1); } }")
    # the true hull: the cube's corners and a dense sampling of the sphere
    u = RNG.normal(size=(20000, 3))
    dense = np.concatenate([u / np.linalg.norm(u, axis=1, keepdims=True) + [3, 0, 0],
                            [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]])
    true = trimesh.convex.convex_hull(dense)
    for facets in ("ideal", "openscad"):
        s = loads_csg(text, facets=facets)
        assert s.name == "convex_polyhedron" and s.exactness == "bound"
        f = _f(s, [[-1, -1, -1], [0, 0, 0], [4, 0, 0], [3, 0, 1], [4.1, 0, 0]])
        assert abs(f[0]) < 1e-12 and f[1] < -0.9 and f[4] > 0
        if facets == "ideal":  # inscribed, within HULL_TOLERANCE of the radius
            assert 0 <= f[2] <= 2e-3 and 0 <= f[3] <= 2e-3  # true surface: outside
            vol = trimesh.convex.convex_hull(np.asarray(s.args[0])).volume
            assert abs(vol / true.volume - 1) < 2e-3
        else:  # OpenSCAD's 5-segment sphere: 3 rings, the middle one through (4, 0, 0)
            assert abs(f[2]) < 1e-12 and f[3] > 0.1
    flat = loads_csg("hull() { square(size = [2, 2], center = true); multmatrix([[1, 0, "
                     "0, 3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) { circle(r = 1); } }")
    assert flat.dim == 2 and flat.name == "polygon" and flat.exactness == "exact"
    assert abs(_f(flat, [[4, 0]])[0]) < 1e-12 and _f(flat, [[-1, -1]])[0] == pytest.approx(0)
    caps = loads_csg("hull() { circle(r = 1); multmatrix([[1, 0, 0, 3], [0, 1, 0, 0], "
                     "[0, 0, 1, 0], [0, 0, 0, 1]]) { circle(r = 1); } }")
    assert caps.name == "segment" and _f(caps, [[1.5, 1]])[0] == pytest.approx(0)
    # a child read through its field: a cube with a spherical bite, and a sphere
    bite = loads_csg("hull() { difference() { cube(size = [2, 2, 2], center = true); "
                     "sphere(r = 1.2); } multmatrix([[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, "
                     "0], [0, 0, 0, 1]]) { sphere(r = 1); } }", facets="openscad")
    assert abs(_f(bite, [[-1, -1, -1]])[0]) < 1e-12  # the cube's corners are exact
    assert -0.03 < _f(bite, [[-1, 0, 0]])[0] < 0.03  # sampled faces: about a cell


def test_ideal_curved_volumes_within_a_thousandth():
    """Sphere, cylinder and cone in ideal mode, meshed at resolution 160 (marching cubes
    under-fills curved surfaces by about (h / R)^2; the mesh's volume is then within
    0.1 % of the analytic one)."""
    cases = [("sphere(r = 2);", 4 / 3 * math.pi * 8),
             ("cylinder(h = 3, r1 = 1.5, r2 = 1.5, center = true);", math.pi * 2.25 * 3),
             ("cylinder(h = 3, r1 = 1.5, r2 = 0.5);", math.pi * 3 / 3 * (2.25 + 0.75 + 0.25)),
             ("cylinder(h = 3, r1 = 0, r2 = 1.5);", math.pi * 2.25 * 3 / 3)]
    for text, vol in cases:
        m = csdf.mesh(loads_csg(text), resolution=160, progress=False, check_thin=False)
        assert abs(m.volume / vol - 1) < 1e-3, (text, m.volume / vol - 1)


def test_facets_openscad_reads_every_example_ideal_reads(tmp_path):
    """Every example of Debian's openscad package that loads with facets='ideal' loads
    with facets='openscad' too (the CSG export is fast; no meshing here)."""
    _need_openscad()
    from concurrent.futures import ThreadPoolExecutor

    examples = sorted(Path("/usr/share/openscad/examples").rglob("*.scad"))
    if not examples:
        pytest.skip("openscad's examples are not installed")

    def export(f):
        out = tmp_path / f"{f.parent.name}_{f.stem}.csg"
        subprocess.run(["openscad", "-o", str(out), str(f)], capture_output=True,
                       timeout=120, cwd=f.parent, stdin=subprocess.DEVNULL)
        return out

    with ThreadPoolExecutor(4) as pool:
        files = [f for f in pool.map(export, examples) if f.exists()]
    read = 0
    for f in files:
        try:
            ideal = load_csg(f)
        except csdf.CsdfError:
            continue
        faceted = load_csg(f, facets="openscad")
        assert faceted.dim == ideal.dim, f.name
        read += 1
    assert read >= 20


@pytest.mark.parametrize("child", [
    "linear_extrude(height = 2, twist = 90, slices = 5) square(size = [2, 1], center = true);",
    "linear_extrude(height = 2, scale = 0.5, center = true) polygon(points = [[0, 0], "
    "[2, 0], [1, 1], [2, 2], [0, 2]]);",
    "rotate_extrude($fn = 9) multmatrix([[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 0], "
    "[0, 0, 0, 1]]) square(size = [1, 1]);",
    "minkowski() { cube(size = [2, 1, 1]); sphere(r = 0.3, $fn = 8); }",
    "linear_extrude(height = 1) offset(r = 0.5, $fn = 8) polygon(points = [[0, 0], "
    "[2, 0], [1, 1], [2, 2], [0, 2]]);",
])
def test_hull_points_of_each_node_lie_on_the_child(child):
    """``facets='openscad'``: the hull's vertices are the child's own (on its surface),
    and the hull holds the child (but for the round offset and Minkowski sum, which
    stay round in this mode while the hull takes OpenSCAD's facets: 0.04 deep)."""
    c = loads_csg(child, facets="openscad")
    h = loads_csg(f"hull() {{ {child} }}", facets="openscad")
    verts = np.asarray(h.args[0])
    assert abs(_f(c, verts)).max() < 1e-9
    b = np.asarray(c.bounds)
    p = RNG.uniform(b[0] - 0.5, b[1] + 0.5, (3000, 3))
    inside = _f(c, p) < -0.05
    assert inside.sum() > 30 and np.all(_f(h, p[inside]) < 1e-9)
