"""Dual-contouring meshes stay watertight and 2-manifold after a file round trip (#15):
vertices of neighbouring voxels projected onto one sharp feature point used to end
~1e-9 apart, and readers that merge close vertices (trimesh, within 1e-8) fused them."""

from __future__ import annotations

import io

import numpy as np
import pytest

import csdf
from csdf import zoo
from csdf.mesh.api import min_edge_length, separate_close_vertices


@pytest.mark.parametrize("resolution", [160, 200])
def test_gear_dc_survives_stl_and_ply_round_trips(resolution):
    import trimesh

    m = csdf.mesh(zoo.load("gear"), resolution=resolution, method="dc", progress=False)
    assert m.is_watertight and m.is_winding_consistent
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    h = m.metadata["csdf"]["voxel_size"]
    e = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1).min() >= 0.99 * min_edge_length(v, h)
    for fmt in ("stl", "ply"):
        data = m.export(file_type=fmt)
        back = trimesh.load(io.BytesIO(data if isinstance(data, bytes) else data.encode()),
                            file_type=fmt)
        assert len(back.vertices) == len(v), fmt
        assert back.is_watertight and back.is_winding_consistent, fmt


def test_separate_close_vertices_parts_the_ends_of_short_edges():
    # an octahedron with one vertex split into two that almost coincide
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1],
                  [0, 0, 1 + 1e-12]], dtype=float)
    f = np.array([[0, 2, 4], [2, 1, 6], [1, 3, 6], [3, 0, 4], [2, 0, 5], [1, 2, 5],
                  [3, 1, 5], [0, 3, 5], [4, 2, 6], [4, 6, 3]])
    before = v.copy()
    moved = separate_close_vertices(v, f, 1e-4)
    assert moved >= 2  # (a second round when the first parted them too little)
    assert np.linalg.norm(v[4] - v[6]) >= 1e-4
    others = [0, 1, 2, 3, 5]
    np.testing.assert_array_equal(v[others], before[others])
    assert separate_close_vertices(v, f, 1e-4) == 0  # nothing left to do
