"""csdf.infer: CSG trees of csdf primitives from point clouds."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

import csdf
from csdf.errors import CsdfError
from csdf.infer import infer
from csdf.infer import tree as T

PART = (csdf.box((2.0, 1.2, 0.6)) - csdf.cylinder(0.3, 1.0).translate((0.4, 0.0, 0.0))) \
    | csdf.sphere(0.5).translate((-1.0, 0.0, 0.3))


@pytest.fixture(scope="module")
def cloud():
    p, n = csdf.sample_surface(PART, 12_000, seed=0)
    return p + np.random.default_rng(1).normal(0.0, 0.004, p.shape), n


def test_tree_canonical_forms():
    # commutative operands, and a chain of differences as one union of subtrahends
    assert T.canonical(("union", 0, ("union", 2, 1))) == T.canonical(("union", ("union", 1, 0), 2))
    a = ("difference", ("difference", ("difference", 0, 1), 2), 3)
    b = ("difference", ("difference", 0, ("union", 3, 1)), 2)
    assert T.canonical(a) == T.canonical(b) == "D(0,U(1,2,3))"
    assert T.canonical(("difference", 0, 1)) != T.canonical(("difference", 1, 0))
    assert T.canonical(("intersection", 0, 1)) != T.canonical(("union", 0, 1))
    t = ("union", ("difference", 0, 1), 2)
    assert T.remove(t, 1) == ("union", 0, 2) and T.remove(t, 2) == ("difference", 0, 1)
    assert T.remove(0, 0) is None
    vals = np.array([[1.0, -1.0], [0.5, 0.5], [-2.0, 3.0]])
    assert T.evaluate(t, vals).tolist() == [-2.0, -0.5]


def test_recovers_structure_and_parameters(cloud):
    pts, nrm = cloud
    res = infer(pts, nrm, seed=0)
    kinds = sorted(p["kind"] for p in res.primitives)
    assert kinds == ["box", "cylinder", "sphere"]
    # the hole does not reach the sphere: cutting before or after the union is the same
    assert res.tree.replace(" ", "") in ("((box_1-cylinder_1)|sphere_1)",
                                         "(sphere_1|(box_1-cylinder_1))",
                                         "((box_1|sphere_1)-cylinder_1)",
                                         "((sphere_1|box_1)-cylinder_1)")
    by = {p["kind"]: p for p in res.primitives}
    assert abs(by["sphere"]["radius"] - 0.5) < 0.01
    assert np.allclose(by["sphere"]["translation"], [-1.0, 0.0, 0.3], atol=0.01)
    assert abs(by["cylinder"]["radius"] - 0.3) < 0.01
    assert sorted([by["box"]["size_x"], by["box"]["size_y"], by["box"]["size_z"]]) == \
        pytest.approx([0.6, 1.2, 2.0], abs=0.02)
    assert res.inlier_fraction > 0.95 and res.rmse < 0.01
    # the text is a model with named parameters that compiles to the same field
    m = csdf.loads(res.text)
    names = {p.name for p in csdf.as_field(m).program.params}
    assert {"cylinder_1_radius", "sphere_1_x", "box_1_size_x"} <= names
    q = np.random.default_rng(2).uniform(-1.5, 1.5, (500, 3))
    assert np.allclose(csdf.as_field(m).value(q), csdf.as_field(res.shape).value(q))
    # deterministic for a seed
    again = infer(pts, nrm, seed=0)
    assert again.text == res.text and again.history[-1][2] == res.history[-1][2]


def test_single_view_scan_with_viewpoint():
    shape = csdf.box((1.0, 1.0, 0.5)) | csdf.cylinder(0.3, 1.2).translate((0.0, 0.0, 0.5))
    cam = csdf.Camera.look_at((2.5, -2.0, 2.0), (0.0, 0.0, 0.3), width=320, height=240)
    pc, _ = csdf.scan(shape, cam, noise=0.002, seed=0)
    M = cam.pose
    pts = pc @ M[:3, :3].T + M[:3, 3]
    res = infer(pts, viewpoint=cam.pose[:3, 3], seed=0, time_limit=10)
    assert sorted(p["kind"] for p in res.primitives) == ["box", "cylinder"]
    assert "|" in res.tree and res.inlier_fraction > 0.9


def test_bad_input(cloud):
    pts, nrm = cloud
    with pytest.raises(CsdfError, match="at least 50"):
        infer(pts[:10])
    with pytest.raises(CsdfError, match="kinds"):
        infer(pts, kinds="box,blob")
    with pytest.raises(CsdfError, match="max_primitives"):
        infer(pts, max_primitives=0)
    with pytest.raises(CsdfError, match="time_limit"):
        infer(pts, time_limit=-1)
    with pytest.raises(CsdfError, match="normals"):
        infer(pts, nrm[:5])
    with pytest.raises(CsdfError, match="no primitive"):
        infer(np.random.default_rng(0).uniform(-1, 1, (400, 3)), kinds="torus")


def test_cli(tmp_path, cloud):
    from csdf.cli import app

    pts, nrm = cloud
    csdf.io.write_points(tmp_path / "part.ply", pts, nrm)
    runner = CliRunner()
    r = runner.invoke(app, ["infer", str(tmp_path / "part.ply"), "-o",
                            str(tmp_path / "part.csdf"), "--time-limit", "10"])
    assert r.exit_code == 0, r.output
    text = (tmp_path / "part.csdf").read_text()
    assert text.startswith("# inferred by csdf infer") and "sphere_1_radius" in text
    r = runner.invoke(app, ["info", str(tmp_path / "part.csdf")])
    assert r.exit_code == 0 and "parameter" in r.output
    r = runner.invoke(app, ["infer", str(tmp_path / "part.ply"), "-o", str(tmp_path / "x.stl")])
    assert r.exit_code != 0 and ".csdf" in r.output


def test_a_hole_seen_from_one_side_goes_through():
    """The scan sees the wall of a hole but not its bottom: the cut goes through instead
    of leaving a skin over the opening that no point shows."""
    shape = csdf.box((1.0, 0.8, 0.5)) - csdf.cylinder(0.2, 1.0)
    cam = csdf.Camera.look_at((1.2, -1.0, 2.2), (0.0, 0.0, 0.0), width=320, height=240)
    pc, _ = csdf.scan(shape, cam, noise=0.002, seed=1)
    M = cam.pose
    res = infer(pc @ M[:3, :3].T + M[:3, 3], viewpoint=M[:3, 3], seed=0, time_limit=10)
    assert res.tree.replace(" ", "") == "(box_1-cylinder_1)"
    cyl = next(p for p in res.primitives if p["kind"] == "cylinder")
    assert cyl["height"] >= 0.5  # at least through the box
    # the opening is open: points on the axis just inside the top face are outside
    f = csdf.as_field(res.shape).value(np.array([[0.0, 0.0, 0.24], [0.0, 0.0, -0.2]]))
    assert (f > 0).all()
