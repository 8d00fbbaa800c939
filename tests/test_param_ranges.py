"""Parameter values outside their declared ranges (issue: "the CLI refuses them with the
range in the message; the Python API raises ParamError unless check_ranges=False
(fitting still clips to the range)").

One place resolves parameter values (:meth:`csdf.Program.param_values`); these tests go
through every door that leads there: the program's and shape's evaluation methods,
:class:`csdf.field.Field` and :func:`csdf.field.as_field`, the consumers that take
``params=``, fitting, the command line and the editor's server.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import csdf
from csdf.cli import app
from csdf.field import Field, as_field

ROOT = Path(__file__).resolve().parents[1]
RANGE = r"parameter 'r' = 3 is outside its range \[0.5, 2\]"
MODEL = "param r = 1.0 in [0.5, 2]\nexport sphere(r)\n"
PTS = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]])
runner = CliRunner()


def _sphere() -> csdf.Shape:
    return csdf.sphere(csdf.param("r", 1.0, 0.5, 2.0))


def _model(tmp_path: Path) -> Path:
    p = tmp_path / "ball.csdf"
    p.write_text(MODEL)
    return p


# ------------------------------------------------------------------ the one place
METHODS = ["__call__", "gradient", "value_and_grad", "param_jacobian",
           "value_grad_param_jacobian", "contains"]


@pytest.mark.parametrize(("kind", "method"), [("program", m) for m in METHODS]
                         + [("shape", m) for m in METHODS if hasattr(csdf.Shape, m)])
def test_evaluation_methods_refuse_out_of_range(kind, method):
    model = _sphere()
    target = model.compile() if kind == "program" else model
    fn = getattr(target, method)
    with pytest.raises(csdf.ParamError, match=RANGE + "; pass check_ranges=False"):
        fn(PTS, {"r": 3.0}, backend="numpy")
    with pytest.raises(csdf.ParamError, match=RANGE):
        fn(PTS, backend="numpy", r=3)  # keyword form
    fn(PTS, {"r": 3.0}, backend="numpy", check_ranges=False)  # evaluates


def test_unchecked_values_are_evaluated():
    prog = _sphere().compile()
    np.testing.assert_allclose(prog(PTS, r=3, check_ranges=False, backend="numpy"),
                               [-3.0, 1.0])
    J = prog.param_jacobian(PTS, {"r": 0.1}, check_ranges=False, backend="numpy")
    np.testing.assert_allclose(J, [[-1.0], [-1.0]])


def test_range_ends_nan_and_unbounded_ranges():
    prog = _sphere().compile()
    for r in (0.5, 2.0, 1.3):  # the ends are inside
        prog(PTS, r=r, backend="numpy")
    assert np.isnan(prog(PTS, r=math.nan, backend="numpy")).all()  # NaN in, NaN out
    with pytest.raises(csdf.ParamError, match=r"= inf is outside its range \[0.5, 2\]"):
        prog(PTS, r=math.inf, backend="numpy")
    free = csdf.sphere(1.0).translate((csdf.param("t", 0.0), 0, 0)).compile()
    free(PTS, t=1e300, backend="numpy")  # unbounded: anything goes
    half = csdf.sphere(csdf.param("s", 1.0, 0.1)).compile()
    half(PTS, s=1e9, backend="numpy")
    with pytest.raises(csdf.ParamError, match=r"'s' = 0.05 is outside its range \[0.1, inf\]"):
        half(PTS, s=0.05, backend="numpy")


def test_param_values_check_and_hint():
    prog = _sphere().compile()
    with pytest.raises(csdf.ParamError, match=RANGE + "; pass check_ranges=False to "
                       "evaluate it anyway"):
        prog.param_values({"r": 3})
    with pytest.raises(csdf.ParamError, match=RANGE + "; do something$"):
        prog.param_values({"r": 3}, range_hint="do something")
    with pytest.raises(csdf.ParamError, match=RANGE + "$"):
        prog.param_values({"r": 3}, range_hint="")
    assert prog.param_values({"r": 3}, check_ranges=False).tolist() == [3.0]
    with pytest.raises(csdf.ParamError, match="unknown parameter"):  # names still checked
        prog.param_values({"q": 1}, check_ranges=False)


def test_check_ranges_is_a_reserved_parameter_name():
    with pytest.raises(csdf.ParamError, match="reserved"):
        csdf.param("check_ranges", 1.0)


# ------------------------------------------------------------------ the field layer
def test_field_and_as_field():
    s = _sphere()
    with pytest.raises(csdf.ParamError, match=RANGE):
        Field(s, {"r": 3})
    with pytest.raises(csdf.ParamError, match=RANGE):
        as_field(s, {"r": 3})
    fld = as_field(s, {"r": 3}, backend="numpy", check_ranges=False)
    assert fld.check_ranges is False
    np.testing.assert_allclose(fld.value(PTS), [-3.0, 1.0])
    np.testing.assert_allclose(fld.bounds, [[-3] * 3, [3] * 3], atol=0.05)  # interval box
    flo, fhi = fld.intervals(np.zeros((1, 3)), np.ones((1, 3)))
    assert flo[0] <= -3.0 + 1e-12 and fhi[0] >= -3.0 + math.sqrt(3) - 1e-12
    # a field made from it keeps its accepted values; new values are checked
    assert as_field(fld, bounds=[[-4] * 3, [4] * 3]).params == {"r": 3}
    assert Field(fld, pose=csdf.Pose.from_rotvec((0, 0, 0), (1, 0, 0))).params == {"r": 3}
    with pytest.raises(csdf.ParamError, match=r"'r' = 0.1 is outside"):
        fld.replace(params={"r": 0.1})
    assert fld.replace(params={"r": 0.1}, check_ranges=False).params == {"r": 0.1}
    assert as_field(s, {"r": 1.5}).check_ranges is True


# ------------------------------------------------------------------ consumers
def test_consumers_refuse_then_accept():
    from csdf.render import auto_camera
    from csdf.slicing import slice_values

    s = _sphere()
    bad = {"r": 3.0}
    cam = auto_camera(s, 16, 12)
    calls = {
        "render": lambda **kw: csdf.render(s, cam, params=bad, backend="numpy", **kw),
        "auto_camera": lambda **kw: auto_camera(s, 16, 12, params=bad, **kw),
        "scan": lambda **kw: csdf.scan(s, cam, params=bad, backend="numpy", **kw),
        "sample_volume": lambda **kw: csdf.sample_volume(s, 50, params=bad, seed=0,
                                                         near_surface=0.0,
                                                         backend="numpy", **kw),
        "slice_values": lambda **kw: slice_values(s, params=bad, resolution=8, **kw),
    }
    for name, call in calls.items():
        with pytest.raises(csdf.ParamError, match=RANGE):
            call()
        assert call(check_ranges=False) is not None, name
    with pytest.raises(csdf.ParamError, match=RANGE):
        csdf.sample_surface(s, 10, params=bad)
    # the unchecked value is used: a ball of radius 3
    img = csdf.render(s, auto_camera(s, 16, 12, params=bad, check_ranges=False),
                      params=bad, backend="numpy", check_ranges=False)
    assert img.mask.any()
    data = slice_values(s, params=bad, resolution=8, extent=((-1, 1), (-1, 1)),
                        check_ranges=False)
    assert (data["f"] < -1.5).all()


def test_slice_and_save_slice(tmp_path):
    pytest.importorskip("matplotlib")
    s = _sphere()
    with pytest.raises(csdf.ParamError, match=RANGE):
        csdf.slice(s, params={"r": 3}, resolution=8)
    out = csdf.save_slice(s, tmp_path / "s.png", params={"r": 3}, resolution=8,
                          check_ranges=False)
    assert out.exists()


# ------------------------------------------------------------------ fitting
def _cloud(r: float = 1.2, n: int = 400) -> np.ndarray:
    d = np.random.default_rng(0).normal(size=(n, 3))
    return r * d / np.linalg.norm(d, axis=1, keepdims=True) + np.array([0.1, -0.2, 0.3])


def test_fit_clips_estimated_initial_values():
    from csdf.fit import fit

    s = _sphere()
    for start in (5.0, 0.01):  # outside the range on either side: clipped, not refused
        res = fit(s, _cloud(), init={"params": {"r": start}}, estimate="pose,params",
                  backend="numpy")
        assert 0.5 <= res.params["r"] <= 2.0
        assert res.params["r"] == pytest.approx(1.2, abs=1e-3)


def test_fit_checks_held_initial_values():
    from csdf.fit import fit, icp

    s = _sphere()
    with pytest.raises(csdf.ParamError, match=r"'r' = 2.5 is outside its range"):
        fit(s, _cloud(), init={"params": {"r": 2.5}}, estimate="pose", backend="numpy")
    res = fit(s, _cloud(2.5), init={"params": {"r": 2.5}}, estimate="pose",
              backend="numpy", check_ranges=False)
    assert res.params["r"] == 2.5 and res.rmse < 1e-6
    with pytest.raises(csdf.ParamError, match=r"'r' = 2.5 is outside its range"):
        icp(s, _cloud(), params={"r": 2.5}, backend="numpy")


def test_fit_overlay_checks_result_values():
    from csdf.fit import fit
    from csdf.render.overlay import fit_overlay

    s = _sphere()
    pts = _cloud(2.5, 200)
    res = fit(s, pts, init={"params": {"r": 2.5}}, backend="numpy", check_ranges=False)
    with pytest.raises(csdf.ParamError, match=r"'r' = 2.5 is outside"):
        fit_overlay(s, pts, res, 16, 12)
    assert fit_overlay(s, pts, res, 16, 12, check_ranges=False).shape == (12, 16, 3)


# ------------------------------------------------------------------ zoo
def test_zoo_refuses_out_of_range_defaults_too():
    from csdf import zoo

    p = zoo.load("chair").params[0]
    with pytest.raises(csdf.ParamError, match=r"is outside its range \["):
        zoo.load("chair", **{p.name: p.hi + 1.0})


# ------------------------------------------------------------------ command line
def _cli_commands(tmp_path: Path, model: Path) -> dict[str, list[str]]:
    return {
        "mesh": ["mesh", str(model), "-o", str(tmp_path / "m.stl"), "-r", "8", "-q"],
        "render": ["render", str(model), "-o", str(tmp_path / "r.png"), "--size", "16x12"],
        "scan": ["scan", str(model), "-o", str(tmp_path / "s.ply"), "--size", "16x12"],
        "sample": ["sample", str(model), "-o", str(tmp_path / "p.ply"), "-n", "20"],
        "slice": ["slice", str(model), "-o", str(tmp_path / "c.png"), "-r", "8"],
        "fit": ["fit", str(model), str(tmp_path / "missing.ply"), "-o",
                str(tmp_path / "f.json")],
    }


def test_cli_refuses_out_of_range_params(tmp_path):
    model = _model(tmp_path)
    for name, args in _cli_commands(tmp_path, model).items():
        r = runner.invoke(app, [*args, "-p", "r=3"])
        assert r.exit_code == 2, (name, r.output)
        assert "error:" in r.output and "outside its range [0.5, 2]" in r.output, name
        assert "--no-check-ranges" in r.output, name
        assert not any(p.name != model.name for p in tmp_path.iterdir()), name


def test_cli_no_check_ranges(tmp_path):
    model = _model(tmp_path)
    out = tmp_path / "m.stl"
    r = runner.invoke(app, ["mesh", str(model), "-o", str(out), "-r", "8", "-q", "-p", "r=3",
                            "--no-check-ranges"])
    assert r.exit_code == 0, r.output
    import trimesh

    m = trimesh.load(out)
    assert m.extents.max() == pytest.approx(6.0, rel=0.05)  # the radius-3 ball
    r = runner.invoke(app, ["sample", str(model), "-o", str(tmp_path / "p.ply"), "-n", "20",
                            "-p", "r=3", "--no-check-ranges", "--seed", "1"])
    assert r.exit_code == 0, r.output


def test_cli_error_on_stderr_in_a_process(tmp_path):
    model = _model(tmp_path)
    r = subprocess.run([sys.executable, "-m", "csdf.cli", "render", str(model), "-o",
                        str(tmp_path / "r.png"), "-p", "r=3"], capture_output=True,
                       text=True, cwd=ROOT, env=dict(os.environ), timeout=300)
    assert r.returncode == 2
    assert "error:" in r.stderr and "'r' = 3 is outside its range [0.5, 2]" in r.stderr
    assert r.stdout == ""


# ------------------------------------------------------------------ editor
def test_editor_refuses_out_of_range_slider_values(tmp_path):
    pytest.importorskip("starlette")
    pytest.importorskip("httpx")
    from starlette.testclient import TestClient

    from csdf.editor.server import create_app

    c = TestClient(create_app(tmp_path / "ball.csdf"), base_url="http://127.0.0.1")
    for path in ("/api/export/shadertoy", "/api/export/mesh"):
        r = c.post(path, json={"text": MODEL, "params": {"r": 3}, "resolution": 8})
        assert r.status_code == 400, (path, r.text)
        body = r.json()
        assert body["ok"] is False
        assert "'r' = 3 is outside its range [0.5, 2]" in body["error"]
    r = c.post("/api/export/shadertoy", json={"text": MODEL, "params": {"r": 1.5}})
    assert r.status_code == 200
