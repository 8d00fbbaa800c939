"""The model zoo (src/csdf/zoo): every model loads, compiles, documents its parameters,
and meshes watertight with a plausible size for its class, at its defaults and at both
ends of every parameter range (one parameter at a time)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import csdf
from csdf import zoo

REQUIRED = {
    "chair", "table", "stool", "bookshelf", "lamp", "cross_shaft", "electrical_box",
    "flange", "connector", "gear", "car", "house", "street_sign",
}

# Voxel edge (m) for the meshing tests: about the thinnest part at its default size, so
# the mesh holds every part (a marching-cubes grid misses anything thinner than a voxel)
# while each mesh stays small (about 3k-90k triangles). The lamp's shade wall and the
# sign's plate are thinner than this at some parameter values; they may then be missing,
# which the size checks below allow for.
VOXEL = {
    "chair": 0.012, "table": 0.012, "stool": 0.01, "bookshelf": 0.01, "lamp": 0.004,
    "cross_shaft": 0.002, "electrical_box": 0.002, "flange": 0.003, "connector": 0.0008,
    "gear": 0.0015, "car": 0.05, "house": 0.12, "street_sign": 0.03,
}

# Plausible sizes by class (metres), checked on the mesh's bounding box:
# height = z extent, length = the larger horizontal extent, size = the largest extent.
CLASS = {
    "chair": {"height": (0.7, 1.2), "length": (0.3, 0.8)},
    "table": {"height": (0.55, 1.15), "length": (0.7, 2.5)},
    "stool": {"height": (0.4, 0.9), "length": (0.2, 0.6)},
    "bookshelf": {"height": (0.9, 2.2), "length": (0.35, 1.3)},
    "lamp": {"height": (0.25, 0.8), "length": (0.1, 0.5)},
    "cross_shaft": {"size": (0.01, 0.5)},
    "electrical_box": {"size": (0.01, 0.5)},
    "flange": {"size": (0.01, 0.5)},
    "connector": {"size": (0.01, 0.5)},
    "gear": {"size": (0.01, 0.5)},
    "car": {"length": (3.0, 5.0), "height": (1.0, 2.0)},
    "house": {"length": (4.0, 20.0), "height": (4.0, 15.0)},
    "street_sign": {"height": (2.0, 4.0)},
}
# models that stand on the floor / ground at z = 0
GROUNDED = {"chair", "table", "stool", "bookshelf", "lamp", "car", "house", "street_sign",
            "electrical_box"}


def _cases() -> list:
    out = []
    for name in zoo.names():
        out.append(pytest.param(name, {}, id=f"{name}-default"))
        for p in zoo.load(name).params:
            for end, v in (("lo", p.lo), ("hi", p.hi)):
                out.append(pytest.param(name, {p.name: v}, id=f"{name}-{p.name}-{end}"))
    return out


def test_catalogue():
    names = zoo.names()
    assert names == sorted(names)
    assert len(names) >= 12
    assert REQUIRED <= set(names)
    assert set(names) == set(VOXEL) == set(CLASS), "every model needs test settings"


@pytest.mark.parametrize("name", zoo.names())
def test_model_loads_compiles_and_documents_its_parameters(name):
    shape = zoo.load(name)
    assert isinstance(shape, csdf.Shape) and shape.dim == 3
    prog = shape.compile()
    assert len(prog) > 0 and prog.nbytes > prog.compact_nbytes() > 0
    assert csdf.load(zoo.path(name)).compile() == prog
    assert zoo.source(name) == zoo.path(name).read_text(encoding="utf-8")
    info = zoo.info(name)
    assert info.description, "the file starts with a comment saying what the model is"
    assert [p.name for p, _ in info.params] and {p.name for p, _ in info.params} == {
        p.name for p in shape.params
    }
    for p, doc in info.params:
        assert doc, f"parameter {p.name} has no comment"
        assert math.isfinite(p.lo) and math.isfinite(p.hi) and p.lo < p.hi, p
        assert p.lo <= p.default <= p.hi


@pytest.mark.parametrize("name,params", _cases())
def test_meshes_watertight_with_a_plausible_size(name, params):
    shape = zoo.load(name, **params)
    for key, value in params.items():
        assert {p.name: p.default for p in shape.params}[key] == value
    h = VOXEL[name]
    mesh = csdf.mesh(shape, voxel_size=h, method="mc", progress=False)
    assert len(mesh.faces) > 0
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0
    ext = mesh.bounds[1] - mesh.bounds[0]
    measured = {"height": ext[2], "length": max(ext[0], ext[1]), "size": ext.max()}
    for what, (lo, hi) in CLASS[name].items():
        assert lo <= measured[what] <= hi, f"{name} {params}: {what} {measured[what]:.3f} m"
    if name in GROUNDED:
        assert abs(mesh.bounds[0][2]) <= 1.5 * h, f"{name} does not stand on z = 0"


@pytest.mark.parametrize("name", zoo.names())
def test_load_with_params_sets_the_defaults(name):
    base = zoo.load(name)
    p = base.params[0]
    v = (p.lo + p.default) / 2 if p.default > p.lo else (p.default + p.hi) / 2
    shape = zoo.load(name, **{p.name: v})
    assert {q.name: (q.default, q.lo, q.hi) for q in shape.params}[p.name] == (v, p.lo, p.hi)
    pts = np.random.default_rng(0).uniform(-1, 1, (500, 3)) * np.abs(base.bounds).max()
    np.testing.assert_allclose(shape(pts), base(pts, **{p.name: v}), rtol=0, atol=1e-12)
    assert zoo.load(name) is base, "loading without parameters gives the cached model"


def test_load_errors_name_the_known_parameters():
    with pytest.raises(csdf.CsdfError, match="did you mean 'chair'"):
        zoo.load("chiar")
    with pytest.raises(csdf.ParamError, match=r"no parameter 'seat_hight'.*seat_height in"):
        zoo.load("chair", seat_hight=0.5)
    with pytest.raises(csdf.ParamError, match=r"outside its range \[0.38, 0.55\]"):
        zoo.load("chair", seat_height=0.9)
    with pytest.raises(csdf.ParamError, match="real number"):
        zoo.load("chair", seat_height="0.5")
    with pytest.raises(csdf.ParamError, match="real number"):
        zoo.load("chair", seat_height=True)
    with pytest.raises(csdf.ParamError, match="finite"):
        zoo.load("chair", seat_height=float("nan"))
    # numpy scalars and range ends are fine
    assert zoo.load("chair", seat_height=np.float64(0.55), leg=0.025).compile()


def test_chair_arm_height_zero_removes_the_armrests():
    text = zoo.source("chair")
    arms = " | arms.color((0.62, 0.42, 0.24))\n"
    assert arms in text
    plain = csdf.loads(text.replace(arms, "\n"))
    chair = zoo.load("chair", arm_height=0.0)
    pts = np.random.default_rng(1).uniform((-0.4, -0.4, 0), (0.4, 0.4, 1.1), (20000, 3))
    d_plain, d_chair = plain(pts), chair(pts)
    outside = d_plain >= 0
    np.testing.assert_allclose(d_chair[outside], d_plain[outside], rtol=0, atol=1e-12)
    assert np.all((d_chair <= 0) == (d_plain <= 0))
    armchair = zoo.load("chair", arm_height=0.25)
    assert np.any((armchair(pts) < 0) & ~(d_plain < 0)), "armrests add material"


def test_cross_shaft_is_small():
    """Fig. 5's cross shaft with few primitives: 5 cylinders, one parameter."""
    prog = zoo.load("cross_shaft").compile()
    assert len(prog.calls) == 5
    assert len(prog.params) == 1
    assert prog.compact_nbytes() < 600


def test_cli_zoo_list_and_show():
    """`csdf zoo list` and `csdf zoo show NAME [--source]`."""
    from typer.testing import CliRunner

    from csdf.cli import app

    runner = CliRunner()
    r = runner.invoke(app, ["zoo", "list"])
    assert r.exit_code == 0, r.output
    for name in zoo.names():
        assert name in r.output
    r = runner.invoke(app, ["zoo", "show", "chair"])
    assert r.exit_code == 0, r.output
    for word in ("seat_height", "[0.38, 0.55]", "floor to the top of the seat", "compact",
                 "chair.csdf"):
        assert word in r.output
    r = runner.invoke(app, ["zoo", "show", "cross_shaft", "--source"])
    assert r.exit_code == 0 and r.output == zoo.source("cross_shaft")
    r = runner.invoke(app, ["zoo", "show", "chiar"])
    assert r.exit_code == 2 and "did you mean 'chair'" in r.output


def test_clutter_is_seeded_and_checks_its_arguments():
    a, b = csdf.zoo.clutter(9, seed=3).compile(), csdf.zoo.clutter(9, seed=3).compile()
    assert np.array_equal(a.code, b.code) and np.array_equal(a.consts, b.consts)
    c = csdf.zoo.clutter(9, seed=4).compile()
    assert not np.array_equal(a.consts, c.consts)
    lo, hi = a.bounds
    assert np.all(hi - lo < 9 ** (1 / 3) + 1.0)  # a cube of side n**(1/3) plus a part
    assert csdf.zoo.clutter(1).compile().bounds is not None
    for bad in (0, 100_001):
        with pytest.raises(ValueError, match="n must be"):
            csdf.zoo.clutter(bad)
    with pytest.raises(ValueError, match="spacing"):
        csdf.zoo.clutter(3, spacing=float("nan"))
