"""Fit overlays: the fitted model with the scan drawn over it (``csdf fit --overlay``)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

import csdf
from csdf.cli import app
from csdf.errors import CsdfError
from csdf.io import write_points
from csdf.render.overlay import INLIER, OUTLIER, fit_overlay

MODEL = "export box(1.0) - sphere(0.6)\n"


def _result(shape, **kw):
    base = dict(rotation=np.eye(3), translation=np.zeros(3), scale=1.0, params={},
                rmse=0.0, inlier_fraction=1.0, inlier_threshold=0.01, converged=True,
                iterations=1, seconds=0.0)
    base.update(kw)
    return csdf.FitResult(**base)


def _cloud(shape, n=400):
    pts, _ = csdf.sample_surface(shape, n, seed=0)
    return pts


def test_overlay_colours_points_by_residual():
    shape = csdf.box(1.0) - csdf.sphere(0.6)
    pts = _cloud(shape)
    good = fit_overlay(shape, pts, _result(shape), 160, 120)
    assert good.shape == (120, 160, 3) and good.dtype == np.uint8
    # the same cloud moved away from the model: every point is an outlier
    bad = fit_overlay(shape, pts, _result(shape, translation=np.array([0.3, 0.3, 0.3])),
                      160, 120)
    green = lambda im: np.sum((im[..., 1] > 150) & (im[..., 0] < 120))  # noqa: E731
    red = lambda im: np.sum((im[..., 0] > 180) & (im[..., 1] < 100))  # noqa: E731
    assert green(good) > 50 and red(good) == 0
    assert red(bad) > 50 and green(bad) <= 0.05 * red(bad)
    assert INLIER[1] > INLIER[0] and OUTLIER[0] > OUTLIER[1]


def test_overlay_rejects_bad_points():
    with pytest.raises(CsdfError, match=r"\(N, 3\)"):
        fit_overlay(csdf.sphere(1.0), np.zeros((5, 2)), _result(None))


def test_cli_fit_writes_an_overlay(tmp_path):
    model = tmp_path / "part.csdf"
    model.write_text(MODEL)
    shape = csdf.box(1.0) - csdf.sphere(0.6)
    scan = tmp_path / "scan.ply"
    write_points(scan, _cloud(shape, 2000) + np.array([0.05, -0.02, 0.03]))
    out, png = tmp_path / "fit.json", tmp_path / "overlay.png"
    r = CliRunner().invoke(app, ["fit", str(model), str(scan), "-o", str(out),
                                 "--overlay", str(png)])
    assert r.exit_code == 0, r.output
    img = np.asarray(Image.open(png))
    assert img.shape == (480, 640, 3)
    assert np.sum((img[..., 1] > 150) & (img[..., 0] < 120)) > 100  # inlier dots drawn
    bad = CliRunner().invoke(app, ["fit", str(model), str(scan), "-o", str(out),
                                   "--overlay", str(tmp_path / "o.jpg")])
    assert bad.exit_code != 0 and "png" in bad.output
