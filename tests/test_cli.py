"""The csdf command line: info, mesh, compile; errors exit 2 with file:line:column."""

from __future__ import annotations

import pytest
import trimesh
from typer.testing import CliRunner

from csdf.cli import app

MODEL = """\
# the CSG example
param r = 1.0 in [0.8, 1.2]
let c = cylinder(0.5, 3)
export (sphere(r) & box(1.5)) - c - c.orient("x") - c.orient("y")
"""

runner = CliRunner()


def _model(tmp_path, text=MODEL, name="csg.csdf"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_info(tmp_path):
    r = runner.invoke(app, ["info", str(_model(tmp_path))])
    assert r.exit_code == 0, r.output
    for word in ("71 instructions", "bound", "Lipschitz 1", "[0.8, 1.2]", "expanded",
                 "primitive", "878"):  # expanded bytes (830 before the v2 bounds section)
        assert word in r.output


def test_mesh_writes_a_watertight_mesh(tmp_path):
    out = tmp_path / "csg.stl"
    r = runner.invoke(app, ["mesh", str(_model(tmp_path)), "-o", str(out), "-r", "40",
                            "--method", "dc", "-p", "r=1.1", "-q"])
    assert r.exit_code == 0, r.output
    assert "watertight=True" in r.output
    m = trimesh.load(out, force="mesh")
    m.merge_vertices()
    assert m.is_watertight and m.euler_number == -8


def test_compile_then_mesh_bytecode(tmp_path):
    blob = tmp_path / "csg.csdfb"
    listing = tmp_path / "csg.csdft"
    assert runner.invoke(app, ["compile", str(_model(tmp_path)), "-o", str(blob)]).exit_code == 0
    assert runner.invoke(app, ["compile", str(_model(tmp_path)), "-o", str(listing)]).exit_code == 0
    assert listing.read_text().startswith("csdf-program 1")
    for src in (blob, listing):
        out = tmp_path / f"{src.suffix[1:]}.ply"
        r = runner.invoke(app, ["mesh", str(src), "-o", str(out), "-r", "24", "-q"])
        assert r.exit_code == 0, r.output
        assert trimesh.load(out, force="mesh").faces.shape[0] > 100


def test_errors_exit_2_with_location(tmp_path):
    bad = _model(tmp_path, "export sphere(1)\nexport box(q)\n", "bad.csdf")
    r = runner.invoke(app, ["info", str(bad)])
    assert r.exit_code == 2
    assert "bad.csdf:2:" in r.output
    r = runner.invoke(app, ["mesh", str(_model(tmp_path)), "-o", str(tmp_path / "x.xyz")])
    assert r.exit_code == 2 and "mesh format" in r.output
    assert not (tmp_path / "x.xyz").exists()
    r = runner.invoke(app, ["mesh", str(_model(tmp_path)), "-o", str(tmp_path / "y.stl"),
                            "-p", "radius=2"])
    assert r.exit_code == 2 and "unknown parameter 'radius'" in r.output
    r = runner.invoke(app, ["info", str(tmp_path / "missing.csdf")])
    assert r.exit_code == 2 and "cannot read" in r.output
    # every command takes a zoo name where it takes a model file
    r = runner.invoke(app, ["info", "stool"])
    assert r.exit_code == 0 and "seat_radius" in r.output, r.output
    r = runner.invoke(app, ["info", "stoool"])
    assert r.exit_code == 2 and "not a zoo model" in r.output
    r = runner.invoke(app, ["--version"])
    assert r.exit_code == 0 and "csdf" in r.output


@pytest.mark.parametrize("args, option", [
    (["mesh", "stool", "-o", "m.stl", "--voxel-size", "0"], "'--voxel-size'"),
    (["mesh", "stool", "-o", "m.stl", "--workers", "0"], "'--workers'"),
    (["sample", "stool", "-o", "s.ply", "-n", "-5"], "'--count'"),
    (["sample", "stool", "-o", "s.ply", "--volume", "--near", "2"], "'--near'"),
    (["sample", "stool", "-o", "s.ply", "--seed", "-1"], "'--seed'"),
    (["infer", "s.ply", "-o", "m.csdf", "--time-limit", "0"], "'--time-limit'"),
    (["infer", "s.ply", "-o", "m.csdf", "--max-primitives", "40"], "'--max-primitives'"),
    (["infer", "s.ply", "-o", "m.csdf", "--prefer", "near"], "'--prefer'"),
    (["detect", "s.ply", "--models", "stool", "-o", "d.json", "--max-instances", "0"],
     "'--max-instances'"),
    (["detect", "s.ply", "--models", "stool", "-o", "d.json", "--noise", "nan"], "'--noise'"),
])
def test_bad_option_values_name_the_option(tmp_path, monkeypatch, args, option):
    """A value out of an option's range is refused before any work, and the message
    names the option as typed (not the Python argument it becomes)."""
    monkeypatch.chdir(tmp_path)
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    assert option in " ".join(r.output.split()), r.output
    assert not any(tmp_path.iterdir())


def test_export_glsl(tmp_path):
    r = runner.invoke(app, ["export", "--glsl", str(_model(tmp_path))])
    assert r.exit_code == 0, r.output
    assert "void mainImage(out vec4 fragColor, in vec2 fragCoord)" in r.output
    assert "const float u_r = 1.0" in r.output
    out = tmp_path / "csg.glsl"
    r = runner.invoke(app, ["export", "--glsl", "--snippet", str(_model(tmp_path)), "-o",
                            str(out)])
    assert r.exit_code == 0 and "uniform float u_r;" in out.read_text()
    r = runner.invoke(app, ["export", str(_model(tmp_path))])
    assert r.exit_code == 2 and "--glsl" in r.output


def test_fit_recovers_a_translated_model(tmp_path):
    import json

    import numpy as np

    from csdf.io import write_points

    box = tmp_path / "box.csdf"
    box.write_text("param w = 0.4 in [0.2, 0.8]\nexport box((w, 0.3, 0.2))\n")
    rng = np.random.default_rng(0)
    # points on the faces of the box, moved by (0.1, 0.2, 0.3)
    u = rng.uniform(-1, 1, (3000, 3)) * np.array([0.2, 0.15, 0.1])
    axis = rng.integers(0, 3, 3000)
    u[np.arange(3000), axis] = np.sign(rng.uniform(-1, 1, 3000)) * np.array([0.2, 0.15, 0.1])[axis]
    scan = tmp_path / "scan.ply"
    write_points(scan, u + np.array([0.1, 0.2, 0.3]))
    out = tmp_path / "fit.json"
    r = runner.invoke(app, ["fit", str(box), str(scan), "-o", str(out), "--estimate",
                            "pose,params"])
    assert r.exit_code == 0, r.output
    res = json.loads(out.read_text())
    np.testing.assert_allclose(res["translation"], [0.1, 0.2, 0.3], atol=1e-6)
    assert abs(res["params"]["w"] - 0.4) < 1e-6


def test_fit_passes_the_sensor_options(tmp_path):
    """--viewpoint / --no-escape / --no-debias reach csdf.fit; bad values are reported
    with the flag's name."""
    import json

    import numpy as np

    import csdf
    from csdf.io import write_points

    model = tmp_path / "plate.csdf"
    model.write_text("export box((0.3, 0.2, 0.02)) - sphere(0.04).translate((0.08, 0.05, 0))\n")
    shape = csdf.load(model)
    eye = (0.2, -0.3, 0.4)
    cam = csdf.Camera.look_at(eye=eye, target=(0, 0, 0), fov=40, width=80, height=60)
    pts, _ = csdf.scan(shape, cam, seed=0)
    scan = tmp_path / "scan.ply"
    write_points(scan, cam.camera_to_world(pts) + np.array([0.01, -0.02, 0.005]))
    out = tmp_path / "fit.json"
    r = runner.invoke(app, ["fit", str(model), str(scan), "-o", str(out), "--viewpoint",
                            ",".join(map(str, eye)), "--no-escape", "--no-debias"])
    assert r.exit_code == 0, r.output
    res = json.loads(out.read_text())
    np.testing.assert_allclose(res["translation"], [0.01, -0.02, 0.005], atol=1e-4)
    np.testing.assert_allclose(res["rotation"], np.eye(3), atol=1e-3)
    r = runner.invoke(app, ["fit", str(model), str(scan), "-o", str(out), "--solver", "x"])
    assert r.exit_code == 2 and "solver" in r.output
    r = runner.invoke(app, ["fit", str(model), str(scan), "-o", str(out), "--viewpoint", "1,2"])
    assert r.exit_code == 2 and "--viewpoint" in r.output
