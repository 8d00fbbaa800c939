"""``csdf.mesh(fit_bounds=True)``: sample planes just inside the faces of the bounds, so
that a part thinner than a voxel lying on a face of the bounding box is sampled."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.mesh.api import _JITTER, FIT_INSET


def _flanged(t: float):
    """A 2 x 2 x 1 block (z from 0 to 1) with a plate of thickness ``t`` on its bottom
    face, sticking out 0.5 beyond it in +x: the plate's bottom is the bounds' low z face."""
    block = csdf.box((2.0, 2.0, 1.0)).translate((0.0, 0.0, 0.5))
    plate = csdf.box((1.0, 1.0, t)).translate((1.25, 0.0, t / 2))
    return block | plate


@pytest.mark.parametrize("method", ["mc", "dc"])
def test_a_plate_thinner_than_a_voxel_on_the_bounds_face_is_kept(method):
    res = 40  # bounds 2.5 x 2 x 1: a voxel of 1/16
    h = 2.5 / res
    t = 0.3 * h  # the default grid's first plane lies (1 - jitter) = 0.85 voxel up
    assert t < (1.0 - _JITTER[2]) * h
    shape = _flanged(t)
    plain = csdf.mesh(shape, resolution=res, method=method, progress=False,
                      check_thin=False)
    fitted = csdf.mesh(shape, resolution=res, method=method, progress=False,
                       check_thin=False, fit_bounds=True)
    assert plain.is_watertight and fitted.is_watertight
    assert plain.vertices[:, 0].max() < 1.0 + h  # the plate is lost between the planes
    assert fitted.vertices[:, 0].max() > 1.5 - h  # the plate is there, out to x = 1.5
    true_volume = 4.0 + 0.5 * t  # the plate's part beyond the block: 0.5 x 1 x t
    assert abs(fitted.volume - true_volume) < abs(plain.volume - true_volume)
    # every vertex on the surface, in the shape's own coordinates
    f = csdf.as_field(shape)
    tol = 1e-6 * h if method == "mc" else 0.05 * h
    assert np.abs(f.value(fitted.vertices)).max() < tol


def test_fitted_grid_puts_planes_just_inside_each_face():
    shape = csdf.box((2.0, 1.3, 0.7))
    m = csdf.mesh(shape, resolution=24, progress=False, check_thin=False, fit_bounds=True)
    hs = np.array(m.metadata["csdf"]["voxel_sizes"])
    assert hs.shape == (3,)
    # the voxel edges differ from the nominal one by under one voxel over each side
    ext = np.array([2.0, 1.3, 0.7])
    h = 2.0 / 24
    assert np.all(np.abs(hs - h) * ext / hs < h * 1.01)
    # a box's faces are the bounds: the mesh covers the box to a few 1e-3 of a voxel
    # (the default grid cuts its edges and corners by up to a voxel)
    assert m.volume == pytest.approx(float(np.prod(ext)), rel=2e-3)
    plain = csdf.mesh(shape, resolution=24, progress=False, check_thin=False)
    assert abs(plain.volume - np.prod(ext)) > 3 * abs(m.volume - np.prod(ext))
    assert 0.0 < FIT_INSET[1] < FIT_INSET[0] < 0.03


def test_fit_bounds_keeps_parameters_and_checks_its_input():
    r = csdf.param("r", 0.5, 0.1, 1.0)
    shape = csdf.sphere(r)
    m = csdf.mesh(shape, resolution=32, params={"r": 0.8}, progress=False,
                  check_thin=False, fit_bounds=True)
    assert np.abs(np.linalg.norm(m.vertices, axis=1) - 0.8).max() < 0.01
    assert m.bounds[1][0] == pytest.approx(0.8, abs=0.01)
    # a user's parameter may take the name the scale factors would use
    clash = csdf.sphere(csdf.param("fit_bounds_scale_x", 0.5, 0.1, 1.0))
    m2 = csdf.mesh(clash, resolution=16, progress=False, check_thin=False,
                   fit_bounds=True)
    assert np.abs(np.linalg.norm(m2.vertices, axis=1) - 0.5).max() < 0.02
    with pytest.raises(csdf.CsdfError, match="fit_bounds=True needs a csdf.Shape"):
        csdf.mesh(shape.compile(), resolution=16, progress=False, fit_bounds=True)
    scene = csdf.Scene()
    scene.add(shape, name="ball")
    with pytest.raises(csdf.CsdfError, match="fit_bounds"):
        csdf.mesh(scene, resolution=16, progress=False, fit_bounds=True)


def test_cli_fit_bounds(tmp_path):
    import trimesh
    from typer.testing import CliRunner

    from csdf.cli import app

    model = tmp_path / "plate.csdf"
    model.write_text("export box((2, 2, 1)).translate((0, 0, 0.5)) | "
                     "box((1, 1, 0.02)).translate((1.25, 0, 0.01))\n")
    out = tmp_path / "plate.stl"
    r = CliRunner().invoke(app, ["mesh", str(model), "-o", str(out), "-r", "40", "-q",
                                 "--no-check-thin", "--fit-bounds"])
    assert r.exit_code == 0, r.output
    m = trimesh.load(out)
    assert m.is_watertight and m.vertices[:, 0].max() > 1.45
    r = CliRunner().invoke(app, ["mesh", str(model), "-o", str(tmp_path / "b.stl"),
                                 "--fit-bounds", "--workers", "2"])
    assert r.exit_code != 0 and "--fit-bounds meshes in this process" in r.output
    assert not (tmp_path / "b.stl").exists()
