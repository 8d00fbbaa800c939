"""Meshing: watertight 2-manifold meshes with the right topology, vertices on the zero set,
sharp edges kept by dual contouring, atomic export, and clear errors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import csdf
from csdf.mesh.cases import COMPONENT_TABLE, TRI_TABLE, cube_components


def csg_example():
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


SHAPES = {
    # name: (factory, Euler characteristic, exact volume or None)
    "sphere": (lambda: csdf.sphere(1.0), 2, 4 / 3 * np.pi),
    "box": (lambda: csdf.box((1.0, 0.8, 0.6)), 2, 0.48),
    "cylinder": (lambda: csdf.cylinder(0.5, 1.2), 2, np.pi * 0.25 * 1.2),
    "torus": (lambda: csdf.torus(0.6, 0.2), 0, 2 * np.pi**2 * 0.6 * 0.04),
    "csg": (csg_example, -8, None),  # three crossing tunnels: genus 5
    "twisted box": (lambda: csdf.box((1.0, 0.4, 2.0)).twist(1.2), 2, 0.8),
    "bent bar": (lambda: csdf.box((2.0, 0.3, 0.3)).bend(0.6), 2, None),
    "squashed sphere": (lambda: csdf.sphere(0.5).scale((1.0, 2.0, 0.5)), 2, 4 / 3 * np.pi / 8),
}


def _check_mesh(m, shape, euler, volume, h, tol_f):
    assert m.is_watertight, "mesh is not watertight"
    assert m.is_winding_consistent, "winding is not consistent"
    edges = np.sort(m.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2), "an edge is not shared by exactly two triangles"
    assert m.euler_number == euler
    assert m.volume > 0, "normals point inwards"
    if volume is not None:
        assert m.volume == pytest.approx(volume, rel=0.02)
    f = shape(np.asarray(m.vertices))
    assert np.max(np.abs(f)) <= tol_f * h


@pytest.mark.parametrize("name", sorted(SHAPES))
@pytest.mark.parametrize("method", ["mc", "dc"])
def test_meshes_are_watertight_manifold_with_right_topology(name, method):
    make, euler, volume = SHAPES[name]
    shape = make()
    m = csdf.mesh(shape, resolution=64, method=method, progress=False)
    h = m.metadata["csdf"]["voxel_size"]
    # vertices on the zero set: within 1e-3 voxel (|f| of a bound/non-distance field is
    # compared after scaling by its Lipschitz bound)
    _check_mesh(m, shape, euler, volume, h, 1e-3 * max(shape.lipschitz, 1.0))


def _box_edges(half, n=400):
    pts = []
    t = np.linspace(-1, 1, n)
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for su in (-1, 1):
            for sv in (-1, 1):
                p = np.zeros((n, 3))
                p[:, axis] = t * half[axis]
                p[:, u] = su * half[u]
                p[:, v] = sv * half[v]
                pts.append(p)
    return np.concatenate(pts)


def _csg_edges(n=400):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    pts = []
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        for r in (0.5, np.sqrt(1 - 0.75**2)):  # tunnel rims; sphere-box rims
            for s in (-0.75, 0.75):
                p = np.zeros((n, 3))
                p[:, axis] = s
                p[:, u] = r * np.cos(a)
                p[:, v] = r * np.sin(a)
                pts.append(p)
    return np.concatenate(pts)


@pytest.mark.parametrize("case", ["box", "csg"])
def test_dual_contouring_keeps_sharp_edges(case):
    if case == "box":
        half = np.array([0.5, 0.4, 0.3])
        shape, edges = csdf.box(2 * half).rotate(0.3, (1, 2, 3)), None
        R = None
    else:
        shape, edges = csg_example(), _csg_edges()
    if case == "box":
        from scipy.spatial.transform import Rotation

        R = Rotation.from_rotvec(0.3 * np.array([1, 2, 3]) / np.linalg.norm([1, 2, 3]))
        edges = R.apply(_box_edges(half))
    dist = {}
    for method in ("mc", "dc"):
        m = csdf.mesh(shape, resolution=48, method=method, progress=False)
        h = m.metadata["csdf"]["voxel_size"]
        _, d, _ = trimesh.proximity.closest_point(m, edges)
        dist[method] = d.max() / h
    assert dist["dc"] <= 0.1, f"dual contouring misses sharp edges by {dist['dc']:.3f} voxel"
    assert dist["mc"] > 0.2, f"marching cubes unexpectedly sharp ({dist['mc']:.3f} voxel)"


def test_case_table_is_consistent():
    # every crossed edge is in exactly one component; triangles use only crossed edges
    for case in range(256):
        inside = [bool(case >> i & 1) for i in range(8)]
        polys = cube_components(inside)
        crossed = {e for p in polys for e in p}
        assert crossed == {e for e in range(12) if COMPONENT_TABLE[case, e] >= 0}
        used = {e for t in TRI_TABLE[case] for e in t if e >= 0}
        assert used == crossed
    # no fan diagonal joins two edges of one cube face (a neighbour could repeat it)
    from csdf.mesh.cases import _FACES_OF_EDGE

    for case in range(256):
        polys = cube_components([bool(case >> i & 1) for i in range(8)])
        diag = {tuple(sorted((int(a), int(b)))) for t in TRI_TABLE[case] if t[0] >= 0
                for a, b in ((t[0], t[2]),) }
        boundary = {tuple(sorted((p[k], p[(k + 1) % len(p)]))) for p in polys
                    for k in range(len(p))}
        for a, b in diag - boundary:
            assert not (_FACES_OF_EDGE[a] & _FACES_OF_EDGE[b]), (case, a, b)
    # complementary patterns give the same number of triangles
    counts = (TRI_TABLE[:, :, 0] >= 0).sum(axis=1)
    assert counts[0] == counts[255] == 0


def test_parameters_change_the_mesh():
    r = csdf.param("r", 0.5, 0.2, 1.0)
    shape = csdf.sphere(r)
    small = csdf.mesh(shape, resolution=32, progress=False, bounds=((-1, -1, -1), (1, 1, 1)))
    big = csdf.mesh(shape, resolution=32, params={"r": 0.9}, progress=False,
                    bounds=((-1, -1, -1), (1, 1, 1)))
    assert big.volume > 4 * small.volume
    auto = csdf.mesh(shape, resolution=32, params={"r": 0.9}, progress=False)
    assert auto.bounds[1, 0] == pytest.approx(0.9, abs=0.05)


def test_shapes_cut_by_bounds_are_closed():
    m = csdf.mesh(csdf.sphere(1.0), resolution=32, bounds=((-1, -1, 0), (1, 1, 1)),
                  progress=False)
    assert m.is_watertight and m.euler_number == 2
    assert m.bounds[0, 2] >= -0.2


@pytest.mark.parametrize("ext", [".stl", ".obj", ".ply", ".glb"])
def test_export_round_trip(tmp_path, ext):
    m = csdf.mesh(csdf.torus(0.6, 0.2), resolution=24, progress=False)
    path = csdf.io.write_mesh(m, tmp_path / f"torus{ext}")
    back = trimesh.load(path, force="mesh")
    assert len(back.faces) == len(m.faces)
    back.merge_vertices()
    assert back.is_watertight
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_export_errors_leave_nothing(tmp_path):
    m = csdf.mesh(csdf.sphere(1.0), resolution=8, progress=False)
    with pytest.raises(csdf.CsdfError, match="mesh format"):
        csdf.io.write_mesh(m, tmp_path / "out.xyz")
    with pytest.raises(csdf.CsdfError, match="does not exist"):
        csdf.io.write_mesh(m, tmp_path / "missing" / "out.stl")
    assert list(tmp_path.iterdir()) == []


def test_mesh_errors():
    s = csdf.sphere(1.0)
    with pytest.raises(csdf.CsdfError, match="method"):
        csdf.mesh(s, method="poisson", progress=False)
    with pytest.raises(csdf.CsdfError, match="not both"):
        csdf.mesh(s, resolution=10, voxel_size=0.1, progress=False)
    with pytest.raises(csdf.CsdfError, match="over the limit"):
        csdf.mesh(s, resolution=100_000, progress=False)
    with pytest.raises(csdf.CsdfError, match="unbounded"):
        csdf.mesh(csdf.plane(), progress=False)
    with pytest.raises(csdf.CsdfError, match="bounds"):
        csdf.mesh(s, bounds=((1, 1, 1), (0, 0, 0)), progress=False)
    with pytest.raises(csdf.CsdfError, match="3D shape"):
        csdf.mesh(csdf.circle(1.0), progress=False)
    with pytest.raises(csdf.ParamError, match="unknown parameter"):
        csdf.mesh(s, params={"r": 1.0}, progress=False)
