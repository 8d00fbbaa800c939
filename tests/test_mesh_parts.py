"""A grid meshed in parts (super-bricks) and stitched by grid edge is the one-machine mesh,
bit for bit up to order; the streamed mesh writer writes the same mesh to PLY and STL."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import csdf
from csdf.errors import CsdfError
from csdf.field import as_field
from csdf.io.meshstream import MeshStreamWriter
from csdf.mesh.api import mesh_grid, prepare_field
from csdf.mesh.grid import Grid
from csdf.mesh.parts import canonical, mesh_part, plan_parts, shared_edges, stitch

CSG = (csdf.sphere(1.0) & csdf.box(1.5)) - csdf.cylinder(0.5, 3)


def _parts(shape, resolution, super_brick=None, bounds=None, max_tasks=96):
    fld = as_field(shape, what="mesh")
    if bounds is not None:
        fld = csdf.Field(fld, bounds=bounds)
    grid = mesh_grid(fld.bounds, resolution)
    prepare_field(fld, grid)
    cells, size = plan_parts(fld, grid, super_brick, max_tasks)
    return grid, size, [mesh_part(fld, grid, c, size) for c in cells]


def _same(m, verts, faces):
    a, b = canonical(m.vertices, m.faces), canonical(verts, faces)
    return a[0].shape == b[0].shape and np.array_equal(a[0], b[0]) and \
        np.array_equal(a[1], b[1])


@pytest.mark.parametrize("shape, resolution, bounds", [
    (CSG, 150, None),
    # cut by the bounds: the mesh is closed on the grid box, across several parts
    (csdf.sphere(1.0), 120, ((-0.6, -0.6, -0.6), (0.6, 0.6, 0.6))),
    # not a distance (a twist): the root search sees values far from the surface
    (csdf.box((1.0, 0.4, 2.0)).twist(1.0), 130, None),
])
def test_parts_equal_the_whole_mesh(shape, resolution, bounds):
    whole = csdf.mesh(shape, resolution=resolution, bounds=bounds, progress=False,
                      check_thin=False)
    grid, size, parts = _parts(shape, resolution, super_brick=32, bounds=bounds)
    assert len(parts) > 8 and size == 32
    verts, faces = stitch(parts)
    assert _same(whole, verts, faces)
    m = trimesh.Trimesh(verts, faces, process=False)
    assert m.is_watertight and m.is_winding_consistent
    # a vertex two parts hold is shared in both (own vertices are never duplicated)
    own = np.concatenate([p.vertices[:p.n_own] for p in parts])
    shared = np.concatenate([p.vertices[p.n_own:] for p in parts])
    assert len(own) + len(np.unique(np.concatenate([p.keys for p in parts]))) == len(verts)
    assert len(np.unique(own, axis=0)) == len(own)
    assert len(shared) > len(verts) - len(own)  # some were held twice


def test_plan_respects_max_tasks_and_checks_super_brick():
    fld = as_field(CSG, what="mesh")
    grid = mesh_grid(fld.bounds, 256)
    cells, size = plan_parts(fld, grid, max_tasks=20)
    assert 0 < len(cells) <= 20 and size >= 64
    finer, fsize = plan_parts(fld, grid, max_tasks=1000)
    assert fsize < size and len(finer) > len(cells)
    assert np.all(np.diff(cells[:, 0]) >= 0)  # sorted by x first
    for bad in (12, 4, 0, -8, 2.5, True, "64"):
        with pytest.raises(CsdfError, match="super_brick"):
            plan_parts(fld, grid, super_brick=bad)
    with pytest.raises(CsdfError, match="max_tasks"):
        plan_parts(fld, grid, max_tasks=0)


def test_shared_edges_rule():
    grid = Grid(origin=np.zeros(3), h=1.0, dims=(64, 64, 64))
    # edge along x at (3, 32, 5): in the plane j = 32 -> shared; along y at (32, 3, 5):
    # its axis crosses no plane of its own; i = 32 makes it shared
    def key(c, a):
        return ((c[0] * 65 + c[1]) * 65 + c[2]) * 3 + a
    keys = np.array([key((3, 32, 5), 0), key((32, 3, 5), 1), key((32, 3, 5), 0),
                     key((3, 5, 7), 2)])
    assert shared_edges(keys, grid, 32).tolist() == [True, True, False, False]


@pytest.mark.parametrize("suffix", [".ply", ".stl"])
def test_stream_writer_round_trip(tmp_path, suffix):
    _, _, parts = _parts(CSG, 100, super_brick=32)
    verts, faces = stitch(parts)
    path = tmp_path / f"m{suffix}"
    with MeshStreamWriter(path) as w:
        for p in parts:
            w.add(p)
    assert (w.vertices, w.faces) == (len(verts), len(faces))
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporaries left
    back = trimesh.load(path, process=False)
    if suffix == ".ply":  # float64: the same mesh, bit for bit
        assert _same(back, verts, faces)
    else:  # float32 corners, one triple per face
        ref = trimesh.Trimesh(verts, faces, process=False)
        assert len(back.faces) == len(faces)
        assert np.allclose(np.sort(back.triangles.reshape(-1, 9), axis=0),
                           np.sort(ref.triangles.reshape(-1, 9), axis=0), atol=1e-6)
        assert trimesh.load(path).is_watertight  # (merged on load)


def test_stream_writer_bad_input_leaves_nothing(tmp_path):
    with pytest.raises(CsdfError, match=r"\.ply or \.stl"):
        MeshStreamWriter(tmp_path / "m.obj")
    with pytest.raises(CsdfError, match="does not exist"):
        MeshStreamWriter(tmp_path / "nowhere" / "m.ply")
    _, _, parts = _parts(CSG, 64, super_brick=32)
    with pytest.raises(RuntimeError):
        with MeshStreamWriter(tmp_path / "m.ply") as w:
            w.add(parts[0])
            raise RuntimeError("stopped")
    assert list(tmp_path.iterdir()) == []
