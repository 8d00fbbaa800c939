"""A grid meshed in parts (cubes of the octree) and stitched by grid edge is the
one-machine mesh, bit for bit up to order; a part's vertices rebuilt from their edges and
``t`` are the mesher's own; the file layout that several processes write into gives the
same mesh in PLY and STL."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import csdf
from csdf.distributed.tasks import part_summary, write_part
from csdf.errors import CsdfError
from csdf.field import as_field
from csdf.io.meshstream import MeshLayout, check_stream_path, mesh_file, write_whole
from csdf.mesh.api import mesh_grid, prepare_field
from csdf.mesh.grid import octree
from csdf.mesh.part_kernels import (
    ESCAPE,
    decode_faces,
    edge_dtype,
    encode_faces,
    on_cube_faces,
    pack_edges,
)
from csdf.mesh.parts import (
    SharedVertices,
    canonical,
    mesh_part,
    plan_level,
    plan_parts,
    stitch,
)

CSG = (csdf.sphere(1.0) & csdf.box(1.5)) - csdf.cylinder(0.5, 3)


def _parts(shape, resolution, super_brick=None, bounds=None, max_tasks=96):
    fld = as_field(shape, what="mesh")
    if bounds is not None:
        fld = csdf.Field(fld, bounds=bounds)
    grid = mesh_grid(fld.bounds, resolution)
    prepare_field(fld, grid)
    plan = plan_parts(fld, grid, super_brick, max_tasks)
    return grid, plan, [mesh_part(fld, grid, task) for task in plan]


def _same(m, verts, faces):
    a, b = canonical(m.vertices, m.faces), canonical(verts, faces)
    return a[0].shape == b[0].shape and np.array_equal(a[0], b[0]) and \
        np.array_equal(a[1], b[1])


@pytest.mark.parametrize("shape, resolution, bounds, super_brick", [
    (CSG, 150, None, 32),
    (CSG, 150, None, None),  # cubes of several sizes, the fullest split first
    # cut by the bounds: the mesh is closed on the grid box, across several parts
    (csdf.sphere(1.0), 120, ((-0.6, -0.6, -0.6), (0.6, 0.6, 0.6)), 32),
    # not a distance (a twist): the root search sees values far from the surface
    (csdf.box((1.0, 0.4, 2.0)).twist(1.0), 130, None, None),
])
def test_parts_equal_the_whole_mesh(shape, resolution, bounds, super_brick):
    whole = csdf.mesh(shape, resolution=resolution, bounds=bounds, progress=False,
                      check_thin=False)
    grid, plan, parts = _parts(shape, resolution, super_brick, bounds, max_tasks=20)
    assert len(parts) > 8
    if super_brick is not None:
        assert {task.size for task in plan} == {super_brick}
    verts, faces = stitch(parts)
    assert _same(whole, verts, faces)
    # the faces as 2-byte codes (what a task sends back) give the same mesh
    coded = [p.encoded() for p in parts]
    assert all(c.faces.dtype == np.uint16 for c in coded)
    assert all(np.array_equal(c.face_indices(), p.faces) for c, p in zip(coded, parts))
    v2, f2 = stitch(coded)
    assert np.array_equal(v2, verts) and np.array_equal(f2, faces)
    m = trimesh.Trimesh(verts, faces, process=False)
    assert m.is_watertight and m.is_winding_consistent
    # a vertex two parts hold is on the faces of both cubes (their own ones are never
    # held twice), and each part's vertices are the whole mesher's, rebuilt from (edge, t)
    own = np.concatenate([p.vertices()[~p.shared()] for p in parts])
    shared_keys = np.concatenate([p.keys(p.shared()) for p in parts])
    assert len(own) + len(np.unique(shared_keys)) == len(verts)
    assert len(np.unique(own, axis=0)) == len(own)
    assert len(shared_keys) > len(np.unique(shared_keys))  # some were held twice
    whole_rows = {tuple(v) for v in np.asarray(whole.vertices)[:2000]}
    part_rows = {tuple(v) for p in parts for v in p.vertices()}
    assert whole_rows <= part_rows


def test_plan_balances_and_covers_the_octree():
    fld = as_field(CSG, what="mesh")
    grid = mesh_grid(fld.bounds, 256)
    prepare_field(fld, grid)
    level = plan_level(grid)
    cells = octree(grid, fld.intervals, None, stop=level)
    for max_tasks in (1, 5, 20, 1000):
        plan = plan_parts(fld, grid, max_tasks=max_tasks)
        assert 0 < len(plan) <= max_tasks
        weights = [task.weight for task in plan]
        assert weights == sorted(weights, reverse=True)  # the fullest first
        got = np.concatenate([task.cells for task in plan])
        assert len(got) == len(cells)  # every cell in exactly one part
        assert len(np.unique(got, axis=0)) == len(cells)
        for task in plan:  # each cell inside its cube
            assert np.all(task.cells >= task.cell) and \
                np.all(task.cells + task.level <= task.cell + task.size)
    assert len(plan_parts(fld, grid, max_tasks=1000)) > len(plan_parts(fld, grid, max_tasks=5))
    for bad in (12, 4, 0, -8, 2.5, True, "64"):
        with pytest.raises(CsdfError, match="super_brick"):
            plan_parts(fld, grid, super_brick=bad)
    with pytest.raises(CsdfError, match="max_tasks"):
        plan_parts(fld, grid, max_tasks=0)


def test_edge_numbers_inside_a_cube():
    # edges of a cube of 32 at (32, 0, 64): along x at (35, 32, 69) lies in the plane
    # j = 32 (shared); along y at (64, 3, 69) in i = 64 (shared); along x at (64, 3, 69)
    # crosses that plane (own); along z at (35, 5, 70) inside (own)
    corner = np.array([[35, 32, 69], [64, 3, 69], [64, 3, 69], [35, 5, 70]])
    axis = np.array([0, 1, 0, 2])
    out = np.empty(4, dtype=edge_dtype(32))
    pack_edges(corner, axis, np.array([32, 0, 64]), 6, out)
    assert on_cube_faces(out, 32).tolist() == [True, True, False, False]
    assert edge_dtype(512) == np.uint32 and edge_dtype(1024) == np.int64


def test_face_codes_round_trip():
    # a strip of new vertices, then faces that reach far back (escapes) and a face of
    # three new vertices after them
    strip = np.array([[v, v + 1, v + 2] for v in range(0, 80_000, 3)])
    far = np.array([[79_999, 3, 80_000], [80_000, 0, 79_998], [80_001, 80_002, 80_003]])
    faces = np.concatenate([strip, far]).astype(np.int32)
    codes, escapes = encode_faces(faces)
    assert codes.dtype == np.uint16 and escapes.tolist() == [3, 0]
    assert (codes == ESCAPE).sum() == 2
    out = np.empty_like(faces)
    decode_faces(codes, escapes, out)
    assert np.array_equal(out, faces)


def _write(parts, grid, path):
    """A file of ``parts`` as :func:`csdf.distributed.mesh` writes it (here, in one
    process): the counts and shared vertices first, then each part's records."""
    shared = SharedVertices(grid)
    sums = [part_summary(p) for p in parts]
    ids = [shared.add(keys, t) for _, _, keys, t in sums]
    own_total = sum(s[0] for s in sums)
    layout = MeshLayout(path.suffix, own_total + shared.count, sum(s[1] for s in sums))
    own_base = np.cumsum([0] + [s[0] for s in sums])
    face_base = np.cumsum([0] + [s[1] for s in sums])
    with mesh_file(path, layout) as fh:
        if layout.format == ".ply":
            fh.write(layout.vertex_offset(own_total), layout.vertex_records(shared.vertices()))
        for i, p in enumerate(parts):
            # the first part as a worker that does not see the file: the records come back
            where = str(fh.path) if i else str(path.parent / "elsewhere" / "m.tmp")
            blocks = write_part(where, layout, p, int(own_base[i]), int(face_base[i]),
                                own_total + ids[i])
            assert (blocks is None) == (i > 0)
            for offset, records in blocks or ():
                fh.write(offset, records)
    return layout


@pytest.mark.parametrize("suffix", [".ply", ".stl"])
def test_file_written_in_parts(tmp_path, suffix):
    grid, _, parts = _parts(CSG, 100, super_brick=32)
    verts, faces = stitch(parts)
    path = tmp_path / f"m{suffix}"
    layout = _write(parts, grid, path)
    assert (layout.vertices, layout.faces) == (len(verts), len(faces))
    assert path.stat().st_size == layout.size()
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
    # the same layout for a mesh held whole (the one-process baseline of the benchmark)
    whole = tmp_path / f"w{suffix}"
    assert write_whole(whole, verts, faces, block=1000) == layout
    if suffix == ".ply":
        assert _same(trimesh.load(whole, process=False), verts, faces)
    else:  # the same triangles in the same order (parts in plan order)
        assert whole.read_bytes() == path.read_bytes()


def test_file_bad_input_leaves_nothing(tmp_path):
    with pytest.raises(CsdfError, match=r"\.ply or \.stl"):
        check_stream_path(tmp_path / "m.obj")
    with pytest.raises(CsdfError, match="does not exist"):
        check_stream_path(tmp_path / "nowhere" / "m.ply")
    with pytest.raises(CsdfError, match="int32"):
        with mesh_file(tmp_path / "m.ply", MeshLayout(".ply", 2**31, 1)):
            pass
    with pytest.raises(RuntimeError):
        with mesh_file(tmp_path / "m.ply", MeshLayout(".ply", 10, 10)) as fh:
            fh.write(0, b"x")
            raise RuntimeError("stopped")
    assert list(tmp_path.iterdir()) == []

