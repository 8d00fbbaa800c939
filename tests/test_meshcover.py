"""Spheres holding a triangle mesh's surface (``csdf.plan.meshcover``), and robots
whose collision geometry is a mesh."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from csdf.errors import CsdfError
from csdf.plan.meshcover import sphere_set, surface_samples, winding_number

RNG = np.random.default_rng(3)


def _uncovered(mesh: trimesh.Trimesh, c: np.ndarray, r: np.ndarray, n: int = 20000):
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=1)
    edges = mesh.vertices[mesh.edges_unique]  # and points on the edges and corners
    t = RNG.uniform(0, 1, (len(edges), 1))
    pts = np.concatenate([pts, mesh.vertices, edges[:, 0] + t * (edges[:, 1] - edges[:, 0])])
    gap = (np.linalg.norm(pts[:, None] - c[None], axis=2) - r).min(axis=1)
    return gap.max()


@pytest.mark.parametrize("mesh", [
    trimesh.creation.box((0.3, 0.2, 0.1)),
    trimesh.creation.icosphere(2, 0.15),
    trimesh.creation.cylinder(0.05, 0.4, sections=24),
    trimesh.creation.box((0.3, 0.2, 0.002)),  # thinner than the candidates' grid
    trimesh.creation.torus(0.2, 0.03),
], ids=["box", "sphere", "cylinder", "plate", "torus"])
def test_every_surface_point_is_inside_a_sphere_and_none_reaches_far(mesh):
    c, r = sphere_set(mesh.vertices, mesh.faces, spacing=0.04)
    assert 0 < len(r) < 400
    assert _uncovered(mesh, c, r) <= 1e-12
    # how far the spheres reach beyond the surface: a sample of their own surfaces
    u = RNG.normal(size=(len(r), 64, 3))
    u /= np.linalg.norm(u, axis=2, keepdims=True)
    shell = (c[:, None] + r[:, None, None] * u).reshape(-1, 3)
    reach = trimesh.proximity.ProximityQuery(mesh).signed_distance(shell)  # + inside
    assert -reach.min() < 0.04 + 1e-9


def test_samples_and_winding_numbers():
    mesh = trimesh.creation.icosphere(3, 1.0)
    pts, eps = surface_samples(mesh.vertices, mesh.faces, 0.05)
    assert eps <= 0.05 + 1e-12 and np.allclose(np.linalg.norm(pts, axis=1), 1, atol=0.01)
    probe = np.array([[0, 0, 0], [0.5, 0.2, -0.3], [1.5, 0, 0], [0, 3, 0]])
    np.testing.assert_allclose(winding_number(probe, mesh.vertices, mesh.faces),
                               [1, 1, 0, 0], atol=1e-9)
    flipped = mesh.faces[:, ::-1]  # an inward-facing mesh counts -1: still inside
    assert winding_number(probe[:1], mesh.vertices, flipped)[0] == pytest.approx(-1)


def test_bad_meshes_are_refused():
    with pytest.raises(CsdfError, match=r"vertices \(V, 3\) and faces"):
        sphere_set(np.zeros((3, 2)), [[0, 1, 2]])
    with pytest.raises(CsdfError, match="must index"):
        sphere_set(np.zeros((3, 3)), [[0, 1, 5]])
    with pytest.raises(CsdfError, match="positive spacing"):
        sphere_set(np.zeros((3, 3)), [[0, 1, 2]])


def test_a_robot_link_given_as_a_mesh(tmp_path):
    pytest.importorskip("yourdfpy")
    from csdf.plan import Robot

    block = trimesh.creation.box((0.1, 0.1, 0.4))
    block.apply_translation([0, 0, 0.2])
    block.export(tmp_path / "block.stl")
    (tmp_path / "urdf").mkdir()
    text = """<robot name="m"><link name="base"/>
      <link name="arm"><collision><origin xyz="0 0 0.05"/>
        <geometry><mesh filename="../block.stl" scale="1 1 0.5"/></geometry></collision></link>
      <joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
        <axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
    </robot>"""
    path = tmp_path / "urdf" / "m.urdf"
    path.write_text(text)
    robot = Robot.from_urdf(path, mesh_spacing=0.03)
    assert all(p.kind == "sphere" for p in robot.primitives) and len(robot.primitives) > 3
    scaled = block.copy()
    scaled.apply_scale([1, 1, 0.5])
    for q in (0.0, 0.7):
        T = robot.fk([q])["arm"]
        placed = scaled.copy()
        placed.apply_translation([0, 0, 0.05])
        placed.apply_transform(T)
        c, r, _ = robot.spheres([q])
        assert _uncovered(placed, c, r) <= 1e-9
        pts = placed.vertices  # the model (spheres' union) is <= 0 on the mesh's corners
        assert np.all(robot.shape()(pts, robot.params([q])) <= 1e-9)
    with pytest.raises(CsdfError, match=r"link 'arm': cannot find its collision mesh"):
        Robot.from_urdf(text.replace("../block.stl", "nowhere.stl"))
    (tmp_path / "bad.stl").write_text("solid x\nendsolid x\n")
    with pytest.raises(CsdfError, match="link 'arm'"):
        Robot.from_urdf(path.read_text().replace("../block.stl", str(tmp_path / "bad.stl")))
