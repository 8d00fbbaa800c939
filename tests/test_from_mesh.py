"""csdf.from_mesh / polyhedron: a closed triangle mesh as one mesh call of a program,
with the mesh as a data block of the bytecode (format version 3)."""

from __future__ import annotations

import pickle
import struct

import numpy as np
import pytest
import trimesh

import csdf
from csdf.backends.interval_eval import evaluate_intervals
from csdf.backends.meshdist import MeshDistance
from csdf.compiler import binary
from csdf.expr import mesh_call
from csdf.interval import _ARG, _MESH
from csdf.meshdata import MeshData
from csdf.ops import ARG_CODE, MESH_CODE
from test_bytecode_versions import _with_crc
from test_meshdist import brute_unsigned

RNG = np.random.default_rng(7)


@pytest.fixture(scope="module")
def torus():
    m = trimesh.creation.torus(1.0, 0.3, major_sections=32, minor_sections=16)
    return m, csdf.from_mesh(m)


@pytest.fixture(scope="module")
def annulus():
    """A thick ring: a non-convex mesh with a through hole."""
    return trimesh.creation.annulus(r_min=0.5, r_max=1.0, height=0.4, sections=48)


def test_opcodes_agree_with_the_interval_runner():
    assert (_MESH, _ARG) == (MESH_CODE, ARG_CODE)


def test_one_call_in_the_tape_with_the_mesh_as_data(torus):
    m, s = torus
    p = s.compile()
    assert len(p.code) == 2 and p.code[0, 0] == MESH_CODE and p.code[1, 0] == ARG_CODE
    assert len(p.data) == 1 and len(p.data[0].faces) == len(m.faces)
    assert p.counts() == {"add": 0, "mul": 0, "div": 0, "call": 1, "branch": 0}
    assert s.exactness == "exact" and s.lipschitz == 1.0
    np.testing.assert_array_equal(s.bounds, m.bounds)
    # the same mesh twice is one block; two meshes are two
    two = (s | s.translate((3, 0, 0))).compile()
    assert len(two.data) == 1
    box = csdf.from_mesh(trimesh.creation.box((1, 1, 1)))
    assert len((s | box).compile().data) == 2


def test_distances_equal_brute_force_near_edges_and_vertices(torus):
    m, s = torus
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    e = F[RNG.integers(0, len(F), 150)]
    P = np.concatenate([
        RNG.uniform(-1.6, 1.6, (300, 3)),
        V[RNG.integers(0, len(V), 150)] + RNG.normal(0, 1e-3, (150, 3)),
        0.5 * (V[e[:, 0]] + V[e[:, 1]]) + RNG.normal(0, 1e-3, (150, 3)),
    ])
    d = s(P)
    np.testing.assert_allclose(np.abs(d), brute_unsigned(P, V, F), rtol=0, atol=1e-9)
    ok = np.abs(d) > 1e-3
    np.testing.assert_array_equal(d[ok] < 0, m.contains(P[ok]))


def test_signs_inside_a_ring_with_a_hole(annulus):
    s = csdf.from_mesh(annulus)
    P = np.array([[0, 0, 0], [0.75, 0, 0], [0, -0.75, 0.1], [1.2, 0, 0], [0.75, 0, 0.3],
                  [0.3, 0.3, 0]])
    d = s(P)
    np.testing.assert_array_equal(d < 0, [False, True, True, False, False, False])
    np.testing.assert_allclose(d[:2], [0.5, -0.2], atol=0.01)  # to the faceting


def _plate_with_hole():
    """A 4 x 4 x 1 plate with a 2 x 2 square hole through it, as quads."""
    outer = [(-2, -2), (2, -2), (2, 2), (-2, 2)]
    inner = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    pts = [(x, y, z) for z in (0.0, 1.0) for x, y in outer + inner]
    faces = []
    for z0 in (0, 8):  # bottom (z0 = 0) and top rings between outer and inner squares
        for i in range(4):
            j = (i + 1) % 4
            quad = [z0 + i, z0 + j, z0 + 4 + j, z0 + 4 + i]
            faces.append(quad[::-1] if z0 == 0 else quad)
    for base in (0, 4):  # the outer walls, and the hole's walls (facing into the hole)
        for i in range(4):
            j = (i + 1) % 4
            quad = [base + i, base + j, base + 8 + j, base + 8 + i]
            faces.append(quad if base == 0 else quad[::-1])
    return pts, faces


def test_signs_inside_a_plate_with_a_square_hole():
    pts, faces = _plate_with_hole()
    s = csdf.polyhedron(points=pts, faces=faces)
    assert s.compile().data[0].volume == pytest.approx(12.0)
    P = np.array([[0, 0, 0.5], [1.5, 0, 0.5], [0, -1.8, 0.9], [2.5, 0, 0.5], [0, 0, 2],
                  [1.5, 1.5, -0.25]])
    # the hole's middle, inside the rim, inside near a face, outside, above the hole
    # (nearest: the hole's top edge), below the rim
    np.testing.assert_allclose(s(P), [1.0, -0.5, -0.1, 0.5, np.sqrt(2), 0.25], atol=1e-12)


def test_gradient_and_parameter_derivatives_through_the_call(torus):
    m, s = torus
    P = RNG.uniform(-1.5, 1.5, (400, 3))
    md = MeshDistance(m)
    v, g = s.compile().value_and_grad(P)
    rv, rg = md.value_and_grad(P)
    np.testing.assert_array_equal(v, rv)
    np.testing.assert_array_equal(g, rg)
    # posed by parameters: d/dt of d(R(p - t)/k) through the chain rule of the call
    tx, k = csdf.param("tx", 0.2), csdf.param("k", 1.3)
    posed = s.rotate(0.3, axis=(0, 0, 1)).scale(k).translate((tx, 0.1, 0))
    prog = posed.compile()
    val, grad, jac = prog.value_grad_param_jacobian(P)
    h = 1e-6
    for i, name in enumerate(prog.param_names):
        base = {"tx": 0.2, "k": 1.3}
        up = dict(base, **{name: base[name] + h})
        dn = dict(base, **{name: base[name] - h})
        fd = (prog(P, up) - prog(P, dn)) / (2 * h)
        smooth = np.abs(val) > 1e-3
        np.testing.assert_allclose(jac[smooth, i], fd[smooth], atol=2e-5)
    fd = np.stack([(prog(P + h * e) - prog(P - h * e)) / (2 * h) for e in np.eye(3)], 1)
    np.testing.assert_allclose(grad, fd, atol=2e-5)


def test_nan_and_infinite_points(torus):
    _, s = torus
    v, g = s.compile().value_and_grad(np.array([[np.nan, 0, 0], [np.inf, 0, 0],
                                                [0, 0, -np.inf]]))
    assert np.isnan(v[0]) and np.isnan(g[0]).all()
    assert v[1] == np.inf and v[2] == np.inf
    np.testing.assert_array_equal(g[1:], [[1, 0, 0], [0, 0, -1]])
    assert np.isnan(s.compile()(np.zeros((2, 3)) + [[0, 0, 0]], check_ranges=False)).sum() == 0


def test_binary_and_text_round_trips(torus):
    _, s = torus
    model = (s - csdf.sphere(csdf.param("r", 0.4)).translate((1, 0, 0))) | \
        csdf.from_mesh(trimesh.creation.box((0.5, 0.5, 0.5))).translate((2, 0, 0))
    p = model.compile()
    raw = p.to_bytes()
    assert struct.unpack_from("<H", raw, 4)[0] == 3
    q = csdf.Program.from_bytes(raw)
    assert q == p and len(q.data) == 2
    r = csdf.Program.from_text(p.disassemble())
    assert r == p
    P = RNG.uniform(-1.5, 2.5, (300, 3))
    np.testing.assert_array_equal(q(P, r=0.3), p(P, r=0.3))
    assert "= mesh d0 " in p.disassemble()
    # a program without meshes keeps its old encoding
    assert struct.unpack_from("<H", csdf.sphere(1).compile().to_bytes(), 4)[0] == 2


def test_bad_data_blocks_are_refused(torus):
    _, s = torus
    raw = bytearray(s.compile().to_bytes()[:-4])
    n_t = len(s.compile().data[0].faces)
    # the last triangle points at a vertex that does not exist
    struct.pack_into("<I", raw, len(raw) - 4, 10**6)
    with pytest.raises(csdf.BytecodeError, match="data block 0: faces hold vertex"):
        csdf.Program.from_bytes(_with_crc(bytes(raw)))
    # a triangle turned round: the mesh is no longer consistently oriented
    raw = bytearray(s.compile().to_bytes()[:-4])
    at = len(raw) - 12 * n_t
    a, b, c = struct.unpack_from("<III", raw, at)
    struct.pack_into("<III", raw, at, a, c, b)
    with pytest.raises(csdf.BytecodeError, match="consistently oriented"):
        csdf.Program.from_bytes(_with_crc(bytes(raw)))
    with pytest.raises(csdf.BytecodeError, match="truncated"):
        csdf.Program.from_bytes(_with_crc(bytes(raw[:-100])))
    text = s.compile().disassemble()
    lines = text.splitlines()
    cut = next(i for i, ln in enumerate(lines) if ln.startswith("f "))
    with pytest.raises(csdf.BytecodeError, match=r"line \d+: data d0 declares"):
        csdf.Program.from_text("\n".join(lines[:cut] + lines[cut + 1:]))
    # a mesh call whose argument row is missing
    with pytest.raises(csdf.BytecodeError, match="argument row"):
        p = s.compile()
        binary.validate(csdf.Program(params=(), consts=np.zeros(0), code=p.code[:1],
                                     output=p.output, n_regs=1, data=p.data))


def test_intervals_hold_every_value(torus):
    _, s = torus
    p = s.compile()
    c = RNG.uniform(-1.8, 1.8, (2000, 3))
    h = RNG.uniform(0, 0.4, (2000, 3))
    lo, hi = evaluate_intervals(p, c - h, c + h)
    for _ in range(10):
        q = c - h + 2 * h * RNG.uniform(0, 1, c.shape)
        v = p(q)
        assert np.all(v >= lo) and np.all(v <= hi)
    # unbounded boxes: the gap to the mesh's box below, nothing above
    lo, hi = evaluate_intervals(p, [[3, -np.inf, -np.inf], [-np.inf] * 3],
                                [[np.inf] * 3, [np.inf] * 3])
    assert lo[0] == pytest.approx(3 - 1.3) and hi[0] == np.inf
    assert lo[1] == pytest.approx(-0.5 * np.linalg.norm(s.bounds[1] - s.bounds[0]))


def test_meshing_a_mesh_field_gives_the_mesh_back(torus):
    m, s = torus
    out = csdf.mesh(s - csdf.sphere(0.4).translate((1, 0, 0)), resolution=96)
    assert out.is_watertight
    ref = csdf.mesh(csdf.torus(1.0, 0.3) - csdf.sphere(0.4).translate((1, 0, 0)),
                    resolution=96)
    assert abs(out.volume - ref.volume) < 0.05 * ref.volume  # a 32 x 16 faceted torus
    assert abs(csdf.mesh(s, resolution=96).volume - m.volume) < 0.01 * m.volume


def test_consumers_that_cannot_run_a_mesh_call_say_so(torus):
    _, s = torus
    with pytest.raises(csdf.CsdfError, match="GLSL export cannot hold a mesh call"):
        csdf.to_glsl(s)
    with pytest.raises(csdf.CsdfError, match="C and NumPy source export"):
        csdf.to_c(s)
    with pytest.raises(csdf.CsdfError, match=r"\.vm"):
        csdf.io.dumps_vm(s)
    for backend in ("fast", "interp"):
        with pytest.raises(csdf.CsdfError, match=f"the '{backend}' evaluator cannot run"):
            s.compile()(np.zeros((2, 3)), backend=backend)
        with pytest.raises(csdf.CsdfError, match="only 'numpy' evaluates"):
            csdf.Field(s, backend=backend)
    assert csdf.Field(s).backend == "numpy"


def test_language_and_pickle_round_trips(torus):
    _, s = torus
    text = csdf.dumps(s.translate((1, 0, 0)))
    assert "polyhedron(points=[" in text
    assert csdf.loads(text).compile() == s.translate((1, 0, 0)).compile()
    e = s.compile()  # a program pickles through its bytes
    assert pickle.loads(pickle.dumps(e)) == e
    x = mesh_call(e.data[0], csdf.expr.X, csdf.expr.Y, csdf.expr.Z)
    assert pickle.loads(pickle.dumps(x)) is x  # interned again
    assert pickle.loads(pickle.dumps(e.data[0])) == e.data[0]


def test_polyhedron_faces_and_checks():
    cube = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1],
            [0, 1, 1]]
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6],
             [3, 0, 4, 7]]
    s = csdf.polyhedron(points=cube, faces=quads)
    np.testing.assert_allclose(s([[0.5, 0.5, 0.5], [2, 0.5, 0.5], [2, 2, 0.5]]),
                               [-0.5, 1.0, np.sqrt(2)], atol=1e-12)
    # a non-convex face (an L-shaped cap) is ear-clipped in its plane
    L = [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]
    pts = [[x, y, 0] for x, y in L] + [[x, y, 1] for x, y in L]
    faces = [[5, 4, 3, 2, 1, 0], [6, 7, 8, 9, 10, 11]] + [
        [i, (i + 1) % 6, (i + 1) % 6 + 6, i + 6] for i in range(6)]
    el = csdf.polyhedron(points=pts, faces=faces)
    assert el.compile().data[0].volume == pytest.approx(3.0)
    assert csdf.polyhedron()([[0, 0, 0]])[0] < 0  # the default tetrahedron
    with pytest.raises(csdf.ShapeError, match="not closed"):
        csdf.polyhedron(points=cube, faces=quads[:-1])
    with pytest.raises(csdf.ShapeError, match=r"faces\[1\] has 2 vertices"):
        csdf.polyhedron(points=cube, faces=[[0, 1, 2], [0, 1]])
    with pytest.raises(csdf.ShapeError, match="outside 0..7"):
        csdf.polyhedron(points=cube, faces=[[0, 1, 9]] + quads)
    with pytest.raises(csdf.ShapeError, match="finite"):
        csdf.polyhedron(points=[[np.nan, 0, 0]] + cube[1:], faces=quads)


def test_from_mesh_reads_files_and_names_the_problem(tmp_path, torus):
    m, s = torus
    path = tmp_path / "t.stl"
    m.export(path)
    assert csdf.from_mesh(path).compile()(np.zeros((1, 3)))[0] == pytest.approx(
        s(np.zeros((1, 3)))[0], abs=1e-6)  # (STL holds float32)
    with pytest.raises(csdf.CsdfError, match="no mesh file"):
        csdf.from_mesh(tmp_path / "missing.stl")
    open_box = trimesh.creation.box((1, 1, 1))
    with pytest.raises(csdf.CsdfError, match="from_mesh: the mesh is not closed"):
        csdf.from_mesh(open_box.vertices, open_box.faces[:-1])
    assert isinstance(s.compile().data[0], MeshData)


def test_scenes_and_fitting_with_a_mesh_object(torus):
    _, s = torus
    scene = csdf.Scene()
    scene.add(s)
    scene.add(csdf.sphere(0.3), pose=csdf.Pose(translation=(3, 0, 0)))
    P = RNG.uniform(-2, 4, (3000, 3))
    ref = np.minimum(s(P), np.linalg.norm(P - [3, 0, 0], axis=1) - 0.3)
    np.testing.assert_allclose(scene.distance(P), ref, atol=1e-12)
    np.testing.assert_array_equal(
        scene.collide(np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0], [2, 0, 0.]]), [0.1] * 4),
        [False, True, True, False])
    pts, _ = csdf.sample_surface(s.translate((0.05, -0.03, 0.02)), 800, seed=1)
    fit = csdf.fit(s, pts)
    np.testing.assert_allclose(fit.pose.translation, [0.05, -0.03, 0.02], atol=1e-6)
