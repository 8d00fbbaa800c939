"""``csdf.Scene`` (issue 17): instances, batched queries over a bounding volume
hierarchy, and the scene file.

Queries are checked against brute force over the instances' own fields (the minimum,
which instance gives it, the gradient), against closed-form distances for exact
models, and for what the contract flags say; the file round-trips and its errors
name where they are.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import csdf
from csdf.errors import CsdfError, ParamError
from csdf.fieldset import SERIAL_BELOW, FieldSet, build_bvh

RNG = np.random.default_rng(7)


def _scene(n: int = 24, seed: int = 0) -> csdf.Scene:
    rng = np.random.default_rng(seed)
    shapes = [csdf.sphere(0.3), csdf.box((0.3, 0.2, 0.4)), csdf.torus(0.3, 0.08),
              csdf.capsule((0, 0, -0.3), (0, 0, 0.3), 0.1)]
    sc = csdf.Scene()
    sc.add("stool", pose=csdf.Pose(translation=[0.0, 0.0, -0.5]), params={"height": 0.5})
    for k in range(n):
        pose = csdf.Pose.from_rotvec(rng.normal(size=3), rng.uniform(-2, 2, 3))
        sc.add(shapes[k % len(shapes)], pose=pose, scale=rng.uniform(0.5, 1.5))
    return sc


def _brute(sc: csdf.Scene, pts: np.ndarray):
    ids = [inst.id for inst in sc]
    vals = np.stack([sc.field(k).value(pts) for k in ids], axis=1)
    return vals, np.array(ids)


def test_queries_match_brute_force_over_the_instances():
    sc = _scene()
    pts = RNG.uniform(-3, 3, (3000, 3))
    q = sc.query(pts)
    vals, ids = _brute(sc, pts)
    np.testing.assert_allclose(q.distance, vals.min(axis=1), rtol=0, atol=1e-12)
    # the instance reported gives the minimum (up to rounding of the pose transform)
    got = vals[np.arange(len(pts)), np.searchsorted(ids, q.instance)]
    np.testing.assert_allclose(got, q.distance, rtol=0, atol=1e-12)
    for i in range(0, len(pts), 97):
        g = sc.field(int(q.instance[i])).gradient(pts[i:i + 1])[0]
        np.testing.assert_allclose(q.gradient[i], g, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(sc.distance(pts), q.distance)
    # a large batch (threaded) agrees with small ones
    big = RNG.uniform(-3, 3, (SERIAL_BELOW + 777, 3))
    d = sc.distance(big)
    np.testing.assert_array_equal(d[:500], sc.distance(big[:500]))


def test_exact_models_give_euclidean_distances_and_say_so():
    sc = csdf.Scene()
    centres = RNG.uniform(-2, 2, (40, 3))
    radii = RNG.uniform(0.1, 0.4, 40)
    for c, r in zip(centres, radii):
        sc.add(csdf.sphere(1.0), pose=csdf.Pose(translation=c), scale=r)
    pts = RNG.uniform(-3, 3, (4000, 3))
    q = sc.query(pts)
    true = (np.linalg.norm(pts[:, None] - centres[None], axis=2) - radii).min(axis=1)
    np.testing.assert_allclose(q.distance, true, rtol=0, atol=1e-12)
    assert q.exact.all()
    np.testing.assert_allclose(np.linalg.norm(q.gradient, axis=1), 1.0, atol=1e-12)
    # a model that is neither a distance nor a bound, near some points: not exact there
    tw = sc.add(csdf.box((0.5, 0.5, 1.0)).twist(1.0), pose=csdf.Pose(translation=[4, 0, 0]))
    assert sc[tw].model.exactness == "neither"
    q2 = sc.query(pts + [2.5, 0, 0])
    near_tw = q2.instance == tw
    assert near_tw.any() and not q2.exact[near_tw].any()
    far = np.linalg.norm(pts + [2.5, 0, 0] - [4, 0, 0], axis=1) > 4.0
    assert q2.exact[far & ~near_tw].all()


def test_spheres_clearance_and_collisions():
    sc = _scene()
    c = RNG.uniform(-3, 3, (2000, 3))
    r = RNG.uniform(0.0, 0.5, 2000)
    clear, g = sc.sphere_distance(c, r)
    d = sc.distance(c)
    np.testing.assert_array_equal(clear, d - r)
    np.testing.assert_array_equal(g, sc.query(c).gradient)
    hit = sc.collide(c, r)
    np.testing.assert_array_equal(hit, d < r)
    assert 0.05 < hit.mean() < 0.95
    assert not sc.collide(c, 0.0)[d > 0].any()
    np.testing.assert_array_equal(sc.collide(c[:3], 0.2), d[:3] < 0.2)  # one radius


def test_nan_points_empty_scenes_and_bad_arguments():
    sc = _scene(4)
    q = sc.query([[np.nan, 0, 0], [0, 0, 5]])
    assert np.isnan(q.distance[0]) and q.instance[0] == -1 and not q.exact[0]
    assert np.isfinite(q.distance[1]) and q.instance[1] >= 0
    empty = csdf.Scene()
    assert np.all(np.isinf(empty.distance(np.zeros((3, 3)))))
    assert not empty.collide(np.zeros((2, 3)), 1.0).any()
    assert (empty.query(np.zeros((2, 3))).instance == -1).all()
    with pytest.raises(CsdfError, match=r"shape \(N, 3\)"):
        sc.distance(np.zeros((4, 2)))
    with pytest.raises(CsdfError, match="radii must be finite"):
        sc.collide(np.zeros((2, 3)), [-1.0, 0.5])
    with pytest.raises(CsdfError, match=r"shape \(2,\)"):
        sc.sphere_distance(np.zeros((2, 3)), [0.1, 0.2, 0.3])


def test_instances_are_added_updated_removed_and_named():
    sc = csdf.Scene()
    a = sc.add("chair", name="left")
    b = sc.add("chair", pose=csdf.Pose(translation=[1, 0, 0]), params={"seat_height": 0.5})
    assert (a, b) == (0, 1) and len(sc) == 2
    assert sc[a].model is sc[b].model  # loaded once, compiled once
    assert [i.name for i in sc] == ["left", "chair_1"]
    fs = sc._fieldset()
    parts = int((fs.owner == a).sum())  # the chair is a union: searched part by part
    assert parts > 1 and (fs.owner == b).sum() == parts
    assert len(np.unique(fs.inst_i[:, 0])) == 2 * parts  # two parameter values: two sets
    three = csdf.Scene()
    for x in range(3):  # same values, same tapes
        three.add("chair", pose=csdf.Pose(translation=[x, 0, 0]))
    assert len(np.unique(three._fieldset().inst_i[:, 0])) == parts
    sc.update(b, params={"leg": 0.03})
    assert sc[b].params == {"seat_height": 0.5, "leg": 0.03}
    p = np.array([[1.0, 0.0, 0.45]])
    want = csdf.zoo.load("chair")(p - [1, 0, 0], {"seat_height": 0.5, "leg": 0.03})
    np.testing.assert_allclose(sc.field(b).value(p), want, atol=1e-15)
    sc.update(b, pose=csdf.Pose(translation=[5, 0, 0]), scale=2.0)
    assert sc[b].pose.scale == 2.0 and sc[b].params["leg"] == 0.03
    sc.remove(a)
    assert len(sc) == 1 and sc.add(csdf.sphere(1)) == 2  # ids are not reused
    assert sc.query([[0, 0, 0]]).instance[0] == 2
    with pytest.raises(CsdfError, match="no instance 0"):
        sc.remove(a)
    with pytest.raises(CsdfError, match="already has an instance named"):
        sc.add(csdf.sphere(1), name="chair_1")
    with pytest.raises(ParamError, match="outside its range"):
        sc.add("chair", params={"seat_height": 3.0})
    with pytest.raises(CsdfError, match="unknown zoo model 'chiar'"):
        sc.add("chiar")
    with pytest.raises(CsdfError, match="3D models"):
        sc.add(csdf.circle(1.0))
    with pytest.raises(CsdfError, match="scale must be a positive"):
        sc.add(csdf.sphere(1), scale=0)
    with pytest.raises(CsdfError, match="model must be a shape"):
        sc.add(42)
    with pytest.raises(CsdfError):
        sc.add(csdf.plane((0, 0, 1)))  # unbounded: no box for the hierarchy


def test_scene_files_round_trip(tmp_path):
    sc = _scene(6)
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "peg.csdf").write_text("param r = 0.1 in [0.05, 0.2]\n"
                                                 "export cylinder(r, 0.5)\n")
    sc.add(tmp_path / "parts" / "peg.csdf", params={"r": 0.15}, name="peg")
    sc.add(csdf.box(0.4).compile(), pose=csdf.Pose(translation=[0, 3, 0]))
    path = tmp_path / "scene.json"
    sc.save(path)
    text = path.read_text()
    assert text.count('"ref": "m0"') == 2  # the sphere model is stored once
    back = csdf.Scene.load(path)
    assert [(i.id, i.name, i.params) for i in back] == [(i.id, i.name, i.params) for i in sc]
    pts = RNG.uniform(-3, 3, (2000, 3))
    np.testing.assert_array_equal(back.distance(pts), sc.distance(pts))
    # files are found relative to the scene file; a hand-written file may omit pose
    doc = json.loads(text)
    doc["instances"] = [{"model": {"file": "parts/peg.csdf"}}]
    (tmp_path / "small.json").write_text(json.dumps(doc))
    small = csdf.Scene.load(tmp_path / "small.json")
    assert len(small) == 1 and small[0].pose.is_identity()
    assert not list(tmp_path.glob(".scene.json.*"))  # no temporary file left
    # a scene saved in another folder names its model files relative to that folder,
    # and one loaded from a file and saved again elsewhere still finds them
    (tmp_path / "out" / "deep").mkdir(parents=True)
    sc.save(tmp_path / "out" / "scene.json")
    assert '"file": "../parts/peg.csdf"' in (tmp_path / "out" / "scene.json").read_text()
    moved = csdf.Scene.load(tmp_path / "out" / "scene.json")
    moved.save(tmp_path / "out" / "deep" / "again.json")
    again = csdf.Scene.load(tmp_path / "out" / "deep" / "again.json")
    np.testing.assert_array_equal(again.distance(pts), sc.distance(pts))


@pytest.mark.parametrize("text, match", [
    ('{"format": "csdf-scene", "version": 1,\n "instances": [}', r"<string>:2:16: bad JSON"),
    ('{"format": "csdf-scene", "version": 2, "instances": []}', "version: must be 1"),
    ('{"format": "x", "version": 1, "instances": []}', "format: must be 'csdf-scene'"),
    ('{"format": "csdf-scene", "version": 1, "instances": [{"model": {"zoo": "chair"}, '
     '"pose": {"rotation": [[1, 0, 0], [0, 1, 0]]}}]}',
     r"instances\[0\].pose.rotation: must be 3 lists of 3 numbers"),
    ('{"format": "csdf-scene", "version": 1, "instances": [{"model": {"zoo": "chair"}, '
     '"pose": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}}]}', r"instances\[0\]: .*rotation"),
    ('{"format": "csdf-scene", "version": 1, "instances": [{"model": {"zoo": "chair"}}, '
     '{"model": {"ref": "m9"}}]}', r"instances\[1\].model.ref: no model 'm9'"),
    ('{"format": "csdf-scene", "version": 1, "instances": [{"model": {"zoo": "chair"}, '
     '"params": {"seat_height": NaN}}]}', "NaN is not a number"),
    ('{"format": "csdf-scene", "version": 1, "instances": [{"model": {"zoo": "chair"}, '
     '"colour": 1}]}', r"instances\[0\]: unknown field\(s\) colour"),
    ('{"format": "csdf-scene", "version": 1, "instances": [{"id": 3, "model": {"zoo": '
     '"chair"}}, {"id": 3, "model": {"zoo": "chair"}}]}', r"instances\[1\].id: 3 is used twice"),
    ('{"format": "csdf-scene", "version": 1, "instances": [{"model": {"file": "nope.csdf"}}]}',
     r"instances\[0\]: .*nope.csdf"),
    ('{"format": "csdf-scene", "version": 1, "models": {"m0": {"csdf": "export sphere("}}, '
     '"instances": []}', r"<string> \(models.m0\):1:14: '\(' was never closed"),
])
def test_bad_scene_files_say_where(text, match):
    with pytest.raises(CsdfError, match=match):
        csdf.Scene.loads(text)


def test_the_hierarchy_covers_every_box_once():
    lo = RNG.uniform(-5, 5, (101, 3))
    hi = lo + RNG.uniform(0, 1, (101, 3))
    node_f, node_i, order = build_bvh(lo, hi)
    assert sorted(order) == list(range(101))
    seen = []
    stack = [0]
    while stack:
        n = stack.pop()
        a, b = node_i[n]
        if a < 0:
            idx = order[-1 - a:-1 - a + b]
            seen += list(idx)
            assert np.all(node_f[n, :3] <= lo[idx]) and np.all(node_f[n, 3:] >= hi[idx])
        else:
            for c in (a, b):
                assert np.all(node_f[n, :3] <= node_f[c, :3])
                assert np.all(node_f[n, 3:] >= node_f[c, 3:])
                stack.append(c)
    assert sorted(seen) == list(range(101))
    with pytest.raises(CsdfError, match="at least one"):
        FieldSet([])


def test_long_models_run_their_cells_tapes_with_the_same_values(monkeypatch):
    import csdf.fieldset as FS

    chair = csdf.zoo.load("chair").translate((0.0, 0.0, 0.0))  # not a union: kept whole
    assert FS.cell_depth(len(chair.compile().code)) > 0
    fields = [csdf.as_field(chair, pose=csdf.Pose.from_rotvec([0, 0, 0.3], [0.5, 0, 0]))]
    celled = FieldSet(fields)
    assert FS.union_parts(fields[0]) is None and len(celled.owner) == 1
    assert celled.tape_i[0, 4] > 0 and len(celled.tape_i) > 1
    monkeypatch.setattr(FS, "CELL_MIN_INSTRUCTIONS", 10**9)
    whole = FieldSet(fields)
    assert len(whole.tape_i) == 1
    pts = RNG.uniform(-2, 2.5, (20000, 3))  # inside the cells' region and beyond
    a = celled.nearest(pts, grad=True)
    b = whole.nearest(pts, grad=True)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert celled.tape_i[1:, 1].mean() < 0.5 * celled.tape_i[0, 1]  # and shorter


def test_unions_are_searched_part_by_part_with_the_same_answers():
    import csdf.fieldset as FS

    chair = csdf.zoo.load("chair")
    pose = csdf.Pose.from_rotvec([0, 0, 0.3], [0.5, 0, 0], scale=1.5)
    parts = FS.union_parts(csdf.as_field(chair, {"arm_height": 0.2}, pose=pose))
    assert parts is not None and len(parts) >= 5
    split = FieldSet([csdf.as_field(chair, {"arm_height": 0.2}, pose=pose),
                      csdf.as_field(csdf.sphere(0.2), pose=csdf.Pose(translation=[2, 0, 0]))])
    assert len(split.owner) == len(parts) + 1 and set(split.owner) == {0, 1}
    whole_chair = chair.translate((0.0, 0.0, 0.0))
    whole = FieldSet([csdf.as_field(whole_chair, {"arm_height": 0.2}, pose=pose),
                      csdf.as_field(csdf.sphere(0.2), pose=csdf.Pose(translation=[2, 0, 0]))])
    assert len(whole.owner) == 2
    pts = RNG.uniform([-1, -1.5, -0.5], [3, 1.5, 2], (20000, 3))
    a, b = split.nearest(pts, grad=True), whole.nearest(pts, grad=True)
    np.testing.assert_allclose(a[0], b[0], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a[2], b[2])  # instance indices, not parts
    # exact where the whole says so, and more often: a chair part whose tight box is
    # farther than the sphere's surface cannot hide a nearer surface
    assert np.all(a[3][b[3]]) and a[3].sum() > b[3].sum()
    ok = np.abs(a[1] - b[1]).max(axis=1) < 1e-9  # gradients differ only at part ties
    assert ok.mean() > 0.999
    # part boxes are tighter than the whole chair's box, and inside it
    lo, hi = split.inst_f[:-1, 13:16], split.inst_f[:-1, 16:19]
    assert np.all(lo >= split.boxes[0, 0] - 1e-9) and np.all(hi <= split.boxes[0, 1] + 1e-9)
    vol = np.prod(hi - lo, axis=1) / np.prod(split.boxes[0, 1] - split.boxes[0, 0])
    assert np.median(vol) < 0.25
    hits = split.nearest(pts[:500], below=np.full(500, 0.05), stop=True)[2]
    np.testing.assert_array_equal(hits >= 0, a[0][:500] < 0.05)


def test_a_margin_caps_distances_and_skips_far_surfaces():
    sc = _scene()
    pts = RNG.uniform(-3, 3, (3000, 3))
    full = sc.query(pts)
    q = sc.query(pts, max_distance=0.5)
    near = full.distance < 0.5
    assert 0.05 < near.mean() < 0.95
    np.testing.assert_array_equal(q.distance[near], full.distance[near])
    np.testing.assert_array_equal(q.gradient[near], full.gradient[near])
    np.testing.assert_array_equal(q.instance[near], full.instance[near])
    assert np.all(q.distance[~near] == 0.5) and np.all(q.gradient[~near] == 0)
    assert np.all(q.instance[~near] == -1) and not q.exact[~near].any()
    np.testing.assert_array_equal(sc.distance(pts, max_distance=0.5), q.distance)
    c, g = sc.sphere_distance(pts, 0.1, max_distance=0.5)
    ref = np.minimum(full.distance - 0.1, 0.5)
    np.testing.assert_allclose(c, ref, rtol=0, atol=1e-15)
    assert np.all(g[full.distance - 0.1 >= 0.5] == 0)
    with pytest.raises(CsdfError, match="max_distance must not be NaN"):
        sc.distance(pts, max_distance=float("nan"))


def _sphere_hits(o, d, centres, radii):
    """Analytic first hits of unit rays with spheres: (t, index), inf/-1 for misses."""
    oc = o[:, None, :] - centres[None]
    b = np.einsum("nkj,nj->nk", oc, d)
    c = np.einsum("nkj,nkj->nk", oc, oc) - radii ** 2
    disc = b * b - c
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    t[(disc < 0) | (t < 0)] = np.inf
    k = np.argmin(t, axis=1)
    tk = t[np.arange(len(t)), k]
    return tk, np.where(np.isfinite(tk), k, -1)


def test_ray_casts_hit_where_rays_meet_the_spheres():
    sc = csdf.Scene()
    centres = RNG.uniform(-2, 2, (30, 3))
    radii = RNG.uniform(0.1, 0.5, 30)
    ids = [sc.add(csdf.sphere(1.0), pose=csdf.Pose(translation=c), scale=r)
           for c, r in zip(centres, radii)]
    o = np.tile([6.0, 0.5, 0.2], (4000, 1))
    d = 0.3 * RNG.normal(size=(4000, 3)) - [1, 0, 0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    h = sc.raycast(o[0], d)
    t, k = _sphere_hits(o, d, centres, radii)
    assert 0.1 < h.hit.mean() < 0.9
    # the tracer may step over a sliver thinner than its hit tolerance (1e-4 of the
    # scene): rays that only graze a sphere
    differ = h.hit != np.isfinite(t)
    assert differ.mean() <= 0.002
    both = h.hit & np.isfinite(t)
    np.testing.assert_allclose(h.distance[both], t[both], rtol=0, atol=1e-8)
    np.testing.assert_array_equal(h.instance[both], np.array(ids)[k[both]])
    p = o[both] + h.distance[both, None] * d[both]
    want = (p - centres[k[both]]) / radii[k[both], None]
    np.testing.assert_allclose(h.normal[both], want, atol=3e-5)  # taken 1e-7 before
    assert np.all(h.normal[~h.hit] == 0) and np.all(h.instance[~h.hit] == -1)
    # one origin per ray, unnormalised directions, a farthest distance
    h2 = sc.raycast(o, 3.0 * d, max_distance=6.0)
    np.testing.assert_array_equal(h2.hit, h.hit & (h.distance <= 6.0))
    # a ray starting inside a model hits at its start
    inside = sc.raycast(centres[:3], d[:3])
    assert inside.hit.all() and np.all(inside.distance == 0)


def test_ray_casts_refuse_bad_rays_and_unbounded_steps():
    sc = _scene(3)
    with pytest.raises(CsdfError, match="must not be zero"):
        sc.raycast([0, 0, 0], [[0, 0, 0]])
    with pytest.raises(CsdfError, match=r"origins must have shape"):
        sc.raycast(np.zeros((2, 3)), np.ones((3, 3)))
    with pytest.raises(CsdfError, match="finite"):
        sc.raycast([0, 0, np.inf], [[1, 0, 0]])
    from csdf.expr import X, Y, Z
    from csdf.shapes.exprfield import expr_shape

    blob = expr_shape(X * X + Y * Y + Z * Z - 1.0, bounds=np.array([[-1.0] * 3, [1.0] * 3]))
    sc.add(blob)
    with pytest.raises(CsdfError, match="has none"):
        sc.raycast([0, 0, 5], [[0, 0, -1]])
    assert not csdf.Scene().raycast([0, 0, 0], [[1, 0, 0]]).hit.any()


def test_boxes_found_by_intervals_are_kept_per_parameter_values():
    chair = csdf.zoo.load("chair")
    a = csdf.as_field(chair, {"seat_height": 0.5}).model_bounds
    a[:] = 0.0  # a caller's copy: the program's cached box is not touched
    b = csdf.as_field(chair, {"seat_height": 0.5}, pose=csdf.Pose(translation=[1, 0, 0]))
    assert b.model_bounds[1, 2] > 0.8  # the backrest's top, not the zeroed copy
    c = csdf.as_field(chair, {"seat_height": 0.5, "back_height": 0.3}).model_bounds
    assert c[1, 2] < b.model_bounds[1, 2] - 0.05  # other values, another box


def test_sphere_queries_refuse_centres_they_cannot_place():
    sc = _scene()
    with pytest.raises(CsdfError, match=r"centers must be finite \(1 row\(s\) are not, e.g. row 1"):
        sc.collide([[0, 0, 0], [np.nan, 0, 0]], 0.1)
    with pytest.raises(CsdfError, match="centers must be finite"):
        sc.sphere_distance([[np.inf, 0, 0]], 0.1)
    with pytest.raises(CsdfError, match="max_distance must be >= 0"):
        sc.distance([[0, 0, 0]], max_distance=-1)


def test_instances_of_one_program_keep_their_own_parameters() -> None:
    """Eight instances of one parametrised sphere, each with its own radius: the scene's
    distance and first hits are each instance's own. The field set used to key shared
    tapes by ``id(tape)`` without holding the tapes; ``reg_tape``'s cache keeps four per
    program, so a dropped tape's id was reused by a later instance's tape, which then
    got the dropped tape's parameters (instances 4-6 had radius 0.18, 0.16, 0.14)."""
    s = csdf.sphere(csdf.param("r", 0.1, 0.01, 1.0))
    sc = csdf.Scene()
    radii = 0.1 + 0.02 * np.arange(8)
    for i, r in enumerate(radii):
        sc.add(s, csdf.Pose(translation=(float(i), 0.0, 0.0)), params={"r": float(r)})
    above = np.array([[float(i), 0.0, 0.5] for i in range(8)])
    np.testing.assert_allclose(sc.distance(above), 0.5 - radii, atol=1e-9)
    hits = sc.raycast(above + [0.0, 0.0, 1.0], np.tile([0.0, 0.0, -1.0], (8, 1)))
    np.testing.assert_allclose(1.5 - hits.distance, radii, atol=1e-6)
