"""Bad input gets a clear error naming what is wrong; NaN in, NaN out."""

from __future__ import annotations

import numpy as np
import pytest

import csdf


@pytest.fixture
def prog():
    return (csdf.sphere(csdf.param("r", 1.0, 0.5, 2.0)) | csdf.box(csdf.param("b", 1.0))).compile()


@pytest.mark.parametrize("shape", [(5, 2), (5, 4), (3, 1), ()])
def test_wrong_point_shape_names_expected_shape(prog, shape):
    with pytest.raises(csdf.CsdfError) as e:
        prog(np.zeros(shape))
    assert "(N, 3)" in str(e.value) and str(shape) in str(e.value)


def test_wrong_dtype(prog):
    with pytest.raises(csdf.CsdfError, match="float32 or float64"):
        prog(np.zeros((2, 3), dtype=complex))
    with pytest.raises(csdf.CsdfError):
        prog([["a", "b", "c"]])


def test_unknown_parameter_lists_known_ones(prog):
    with pytest.raises(csdf.ParamError) as e:
        prog(np.zeros((1, 3)), radius=2.0)
    assert "'radius'" in str(e.value) and "b, r" in str(e.value)
    with pytest.raises(csdf.ParamError, match="real number"):
        prog(np.zeros((1, 3)), r="big")
    with pytest.raises(csdf.ParamError, match="given twice"):
        prog(np.zeros((1, 3)), {"r": 1.0}, r=2.0)


def test_nan_in_nan_out(prog):
    pts = np.array([[np.nan, 0, 0], [0, 0, 0], [0, np.inf, 0]])
    v, g = prog.value_and_grad(pts)
    assert np.isnan(v[0]) and np.isnan(g[0]).all()
    assert v[1] == pytest.approx(-1.0)
    assert v[2] == np.inf
    J = prog.param_jacobian(pts)
    assert np.isnan(J[0]).all() and not np.isnan(J[1]).any()
    assert np.isnan(prog(pts[1:2], r=np.nan)).all()


def test_param_declaration_errors():
    with pytest.raises(csdf.ParamError, match="not an identifier"):
        csdf.param("2r", 1.0)
    with pytest.raises(csdf.ParamError, match="outside its range"):
        csdf.param("r", 3.0, 0.0, 2.0)
    with pytest.raises(csdf.ParamError, match="reserved"):
        csdf.param("points", 1.0)
    with pytest.raises(csdf.ParamError, match="finite"):
        csdf.param("r", float("nan"))
    with pytest.raises(csdf.ParamError, match="not a range"):
        csdf.param("r", 1.0, 2.0, 0.0)
    clash = csdf.sphere(csdf.param("r", 1.0)) | csdf.box(csdf.param("r", 2.0))
    with pytest.raises(csdf.ParamError, match="declared twice"):
        clash.compile()


def test_shape_argument_errors():
    with pytest.raises(csdf.ShapeError, match="sphere: radius"):
        csdf.sphere("big")
    with pytest.raises(csdf.ShapeError, match="box: size must have 3 components"):
        csdf.box((1, 2))
    with pytest.raises(csdf.ShapeError, match="2D and 3D"):
        csdf.circle(1) | csdf.sphere(1)
    with pytest.raises(csdf.ShapeError, match="unknown blend"):
        csdf.union(csdf.sphere(1), csdf.box(1), k=0.1, blend="wavy")
    with pytest.raises(csdf.ShapeError, match="k must be > 0"):
        csdf.union(csdf.sphere(1), csdf.box(1), k=-0.1)
    with pytest.raises(csdf.ShapeError, match="regular_polygon: n must be an integer"):
        csdf.regular_polygon(2.5, 1)
    with pytest.raises(csdf.ShapeError, match="constant integer"):
        csdf.regular_polygon(csdf.param("n", 5), 1)
    with pytest.raises(csdf.ShapeError, match="extrude expects a 2D shape"):
        csdf.extrude(csdf.sphere(1), 1)
    with pytest.raises(csdf.ShapeError, match="not a rotation"):
        csdf.box(1).rotate([[1, 0, 0], [0, 1, 0], [0, 0, 2]])
    with pytest.raises(csdf.ShapeError, match="must not depend on x, y or z"):
        from csdf.expr import X

        csdf.sphere(X)
    with pytest.raises(csdf.ShapeError, match="coincide"):
        csdf.polygon([(0, 0), (0, 0), (1, 0)])
    with pytest.raises(csdf.ShapeError, match="twist needs a 3D shape"):
        csdf.circle(1).twist(1)
    with pytest.raises(csdf.ShapeError, match="scale: factor must be > 0"):
        csdf.sphere(1).scale(0)
    with pytest.raises(csdf.ShapeError, match="mirror"):
        csdf.sphere(1).mirror("w")
    with pytest.raises(csdf.ShapeError, match="difference needs at least two"):
        csdf.difference(csdf.sphere(1))
    with pytest.raises(csdf.ShapeError, match="csdf.compile expects a Shape"):
        csdf.compile("sphere")
