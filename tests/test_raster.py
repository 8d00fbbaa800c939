"""``csdf.raster`` (issue 16): the quadtree of shortened programs gives, pixel for pixel,
the values of the whole field at every pixel centre."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import csdf
from csdf.cli import app

VM = Path(__file__).resolve().parents[2] / "shared" / "data" / "vm"


def _brute(prog, w, h, box, params=None):
    (x0, y0), (x1, y1) = box
    xs = x0 + (np.arange(w) + 0.5) * ((x1 - x0) / w)
    ys = y1 - (np.arange(h) + 0.5) * ((y1 - y0) / h)
    gx, gy = np.meshgrid(xs, ys)
    return prog(np.stack([gx.ravel(), gy.ravel()], axis=1), params,
                backend="numpy").reshape(h, w)


def _shapes():
    r = csdf.param("r", 0.3, 0.1, 0.5)
    yield "csg", (csdf.circle(0.6) - csdf.rectangle((0.5, 0.2))) | csdf.circle(r).translate(
        (0.5, 0.4)), {"r": 0.25}
    rng = np.random.default_rng(5)
    s = csdf.circle(0.05).translate(tuple(rng.uniform(-0.8, 0.8, 2)))
    for _ in range(40):  # many small parts: most tiles keep a few of them
        s = s | csdf.circle(float(rng.uniform(0.02, 0.1))).translate(
            tuple(rng.uniform(-0.8, 0.8, 2)))
    yield "forty circles", s, None


@pytest.mark.parametrize("name, shape, params", list(_shapes()))
@pytest.mark.parametrize("leaf", [8, 128])
def test_raster_is_pixel_identical_to_brute_force(name, shape, params, leaf):
    box = ((-1.0, -0.9), (1.1, 1.0))
    prog = shape.compile()
    ref = _brute(prog, 97, 83, box, params)
    vals = csdf.raster(shape, 97, 83, box, values=True, params=params, leaf=leaf)
    np.testing.assert_array_equal(vals, ref)  # bit for bit
    inside = csdf.raster(shape, 97, 83, box, params=params, leaf=leaf)
    np.testing.assert_array_equal(inside, ref < 0)
    assert 0 < inside.mean() < 1


def test_raster_uses_the_own_box_and_interp():
    s = csdf.circle(1.0)
    img = csdf.raster(s, 64, 64, backend="interp")
    assert img[32, 32] and not img[0, 0]
    assert img.mean() == pytest.approx(np.pi / 4, abs=0.02)


@pytest.mark.parametrize("kw, match", [
    ({"width": 0}, "width must be an integer"),
    ({"height": 10**6}, "height must be an integer"),
    ({"width": 2.5}, "width must be an integer"),
    ({"leaf": 0}, "leaf must be an integer in"),
    ({"backend": "fast"}, "backend must be 'auto', 'numpy' or 'interp'"),
    ({"bounds": ((1, 1), (0, 0))}, "min < max"),
])
def test_raster_bad_arguments(kw, match):
    args = {"width": 16, "height": 16, **kw}
    with pytest.raises(csdf.CsdfError, match=match):
        csdf.raster(csdf.circle(1.0), **args)


def test_raster_needs_2d_and_bounds():
    with pytest.raises(csdf.CsdfError, match="2D"):
        csdf.raster(csdf.sphere(1.0), 8, 8)
    field = csdf.io.loads_vm("x var-x\ny var-y\nr add x y\n")
    with pytest.raises(csdf.CsdfError, match="bounds="):
        csdf.raster(field, 8, 8)
    img = csdf.raster(field, 8, 8, ((-1, -1), (1, 1)))
    assert img[-1, 0] and not img[0, -1]  # x + y < 0: the lower left


@pytest.mark.skipif(not VM.is_dir(), reason="../shared/data/vm (Fidget's models) absent")
def test_prospero_and_the_cli(tmp_path):
    page = csdf.io.load_vm(VM / "prospero.vm").compile()
    box = ((-1.0, -1.0), (1.0, 1.0))
    np.testing.assert_array_equal(csdf.raster(page, 128, 128, box),
                                  _brute(page, 128, 128, box) < 0)
    out = tmp_path / "p.png"
    r = CliRunner().invoke(app, ["raster", str(VM / "quarter.vm"), "-o", str(out),
                                 "--size", "64x48", "--bounds", "-1,-1,1,1"])
    assert r.exit_code == 0, r.output
    from PIL import Image

    img = np.asarray(Image.open(out))
    assert img.shape == (48, 64) and img[31, 22] == 0 and img[5, 60] == 255  # (-0.3, -0.3) in
    r = CliRunner().invoke(app, ["raster", str(VM / "quarter.vm"), "-o", str(out)])
    assert r.exit_code == 2 and "--bounds" in r.output
    r = CliRunner().invoke(app, ["raster", str(VM / "quarter.vm"), "-o", str(out),
                                 "--bounds", "1,2,3"])
    assert r.exit_code == 2 and "four numbers" in r.output
