"""Scenes in the consumers (issue 17): ``csdf.render``, ``csdf.scan``, ``csdf.mesh`` and
``csdf.sample_surface`` take a :class:`csdf.Scene` and say which instance each pixel,
point or face belongs to."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.errors import CsdfError

pytestmark = pytest.mark.filterwarnings("ignore::csdf.MeshWarning")

POSES = [
    (csdf.sphere(0.4), csdf.Pose(translation=[0.0, 0.0, 0.0])),
    (csdf.box((0.5, 0.3, 0.2)), csdf.Pose.from_rotvec([0.3, -0.2, 0.9], [1.1, 0.2, 0.1], 0.8)),
    (csdf.torus(0.4, 0.1), csdf.Pose.from_rotvec([1.2, 0.0, 0.0], [-0.9, 0.3, 0.2], 1.3)),
    (csdf.sphere(0.4), csdf.Pose(translation=[0.3, 0.9, -0.2], scale=0.5)),
]


def _scene_and_union():
    sc = csdf.Scene()
    parts = []
    for shape, pose in POSES:
        sc.add(shape, pose=pose)
        parts.append(shape.scale(pose.scale).rotate(pose.rotation).translate(pose.translation))
    return sc, csdf.union(*parts)


def test_render_and_scan_of_a_scene_match_the_union_and_name_instances():
    sc, union = _scene_and_union()
    cam = csdf.Camera.look_at(eye=(3.0, -3.5, 2.5), target=(0.1, 0.2, 0.0), fov=40,
                              width=96, height=72)
    a = csdf.render(sc, cam)
    b = csdf.render(union, cam)
    assert a.instance.shape == (72, 96) and b.instance is None
    assert (a.mask != b.mask).mean() <= 0.005
    both = a.mask & b.mask
    assert (np.abs(a.depth[both] - b.depth[both]) <= 1e-7).mean() >= 0.995
    assert set(np.unique(a.instance)) == {-1, 0, 1, 2, 3}
    np.testing.assert_array_equal(a.instance == -1, ~a.mask)
    # each pixel's instance is the one nearest its hit point
    _, dirs = cam.rays()
    t = a.depth.ravel() / cam.pixel_directions()[:, 2]
    hit = a.mask.ravel()
    p = cam.t + t[hit, None] * dirs[hit]
    assert (sc.query(p).instance == a.instance.ravel()[hit]).mean() >= 0.99
    pts, nrm, ids = csdf.scan(sc, cam)
    world = pts @ cam.R.T + cam.t
    assert np.abs(sc.distance(world)).max() <= 1e-8  # refined to 1e-9 of the scene
    np.testing.assert_array_equal(sc.query(world).instance, ids)
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-12)
    _, _, ids2 = csdf.scan(sc, cam, outliers=0.2, seed=1)
    assert (ids2 == -1).any() and (ids2 >= 0).any()
    with pytest.raises(CsdfError, match="carry their own parameters"):
        csdf.render(sc, cam, params={"r": 1.0})


def test_mesh_and_surface_samples_of_a_scene():
    sc, _ = _scene_and_union()
    m = csdf.mesh(sc, voxel_size=0.02, progress=False)
    ids = m.metadata["csdf"]["instance"]
    assert ids.shape == (len(m.faces),) and set(np.unique(ids)) == {0, 1, 2, 3}
    # one model with the same parameters: meshed once, placed twice (the smaller copy
    # at a finer voxel in its own frame: the group's largest scale sets it)
    assert (ids == 0).sum() == (ids == 3).sum()
    for k in range(4):
        v = m.vertices[np.unique(m.faces[ids == k])]
        d = sc.field(k).value(v)
        assert np.abs(d).max() <= 0.02
    p, n, k = csdf.sample_surface(sc, 3000, seed=0)
    assert p.shape == (3000, 3) and k.shape == (3000,)
    assert np.abs(sc.distance(p)).max() <= 1e-9
    q = sc.query(p)
    assert (q.instance == k).mean() >= 0.99
    assert np.all(np.einsum("ij,ij->i", n, q.gradient) > 0.99)
    # the spheres' shares follow their areas (radius 0.4 against 0.2)
    assert 2.5 < (k == 0).sum() / max((k == 3).sum(), 1) < 6.0
    with pytest.raises(CsdfError, match="empty scene"):
        csdf.mesh(csdf.Scene(), voxel_size=0.1)
