"""Parts and gaps thinner than a voxel (issue 15): found, reported, and resolved by the
default resolution; ``params=`` and the same values as defaults give the same mesh."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

import csdf
from csdf import zoo
from csdf.field import as_field
from csdf.mesh.api import _grid_layout
from csdf.mesh.grid import Grid
from csdf.mesh.thin import thin_parts


def _mc_volume(shape, params=None, n=1 << 20, seed=0) -> float:
    """Monte Carlo volume of ``{f < 0}`` over the field's box."""
    f = as_field(shape, params)
    b = f.bounds
    p = np.random.default_rng(seed).uniform(b[0], b[1], size=(n, 3))
    return float((f.value(p) < 0).mean() * np.prod(b[1] - b[0]))


def _mesh(shape, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", csdf.MeshWarning)
        m = csdf.mesh(shape, progress=False, **kw)
    return m, [w for w in caught if issubclass(w.category, csdf.MeshWarning)]


def _plate():
    """A 1 x 1 plate 0.01 thick: thinner than a voxel below resolution ~100."""
    return csdf.box((1.0, 1.0, 0.01))


def test_thin_parts_finds_a_plate_between_the_samples():
    f = as_field(_plate())
    origin, h, dims = _grid_layout(f.bounds, 16, None)
    assert h > 0.05  # the plate (0.01) is far thinner than a voxel
    rep = thin_parts(Grid(origin=origin, h=h, dims=dims), f.value, f.intervals, 1.0)
    assert rep.voxels > 0 and rep.gap_volume == 0
    # the plate's volume is 0.01; the estimate from the refined cells is close to it
    assert 0.5 * 0.01 < rep.lost_volume < 2.0 * 0.01
    assert rep.too_coarse()
    assert abs(rep.where[2]) < h  # the plate lies at z = 0


def test_thin_parts_finds_a_slot_and_passes_a_plain_solid():
    slot = csdf.box((1.0, 1.0, 1.0)) - csdf.box((2.0, 2.0, 0.01))
    f = as_field(slot)
    origin, h, dims = _grid_layout(f.bounds, 16, None)
    rep = thin_parts(Grid(origin=origin, h=h, dims=dims), f.value, f.intervals, None)
    assert rep.voxels > 0 and rep.gap_volume > 0.3 * 0.01 and rep.lost_volume == 0
    f = as_field(csdf.sphere(1.0))
    origin, h, dims = _grid_layout(f.bounds, 32, None)
    rep = thin_parts(Grid(origin=origin, h=h, dims=dims), f.value, f.intervals, 1.0)
    assert rep.voxels == 0 and rep.fraction == 0.0
    assert rep.volume == pytest.approx(4 / 3 * np.pi, rel=0.02)


def test_explicit_resolution_warns_when_parts_are_lost():
    m, caught = _mesh(_plate(), resolution=16)
    assert len(caught) == 1
    msg = str(caught[0].message)
    assert "loses parts thinner than a voxel" in msg and "resolution" in msg
    # the check can be turned off, and a fine enough grid does not warn
    _, caught = _mesh(_plate(), resolution=16, check_thin=False)
    assert not caught
    _, caught = _mesh(_plate(), resolution=300)
    assert not caught


def test_default_resolution_resolves_thin_parts():
    plate = csdf.box((1.0, 1.0, 0.005))  # lost between the samples at 128
    m, caught = _mesh(plate)
    assert not caught
    assert m.metadata["csdf"]["resolution"] > 128  # chosen finer for the plate
    assert m.is_watertight
    assert m.volume == pytest.approx(0.005, rel=0.02)


def test_default_resolution_follows_the_volume_of_slanted_shells():
    """The lamp's conical shade (a 3 mm shell met at a slant) keeps samples inside at
    128, so nothing is lost outright, but the mesh breaks into pieces and loses volume:
    the default grid is refined until the mesh's volume matches the field's."""
    lamp = zoo.load("lamp")
    f = as_field(lamp, what="mesh")
    origin, h, dims = _grid_layout(f.bounds, 128, None)
    rep = thin_parts(Grid(origin=origin, h=h, dims=dims), f.value, f.intervals, f.lipschitz)
    coarse = csdf.mesh(lamp, resolution=128, progress=False, check_thin=False)
    true = _mc_volume(lamp, n=1 << 21)
    assert not rep.too_coarse() and abs(coarse.volume / true - 1) > 0.05
    m, caught = _mesh(lamp)
    assert not caught and m.metadata["csdf"]["resolution"] > 128
    assert m.volume == pytest.approx(true, rel=0.02)
    assert m.metadata["csdf"]["field_volume"] == pytest.approx(true, rel=0.02)
    assert len(m.split(only_watertight=False)) == 1


def test_a_plain_shape_keeps_128():
    m, caught = _mesh(csdf.sphere(1.0))
    assert not caught and m.metadata["csdf"]["resolution"] == 128
    # without the check the default is 128
    m, caught = _mesh(csdf.box((1.0, 1.0, 0.005)), check_thin=False)
    assert m.metadata["csdf"]["resolution"] == 128


def test_max_resolution_caps_the_default_and_says_so():
    m, caught = _mesh(csdf.box((1.0, 1.0, 0.002)), max_resolution=128)
    assert m.metadata["csdf"]["resolution"] == 128
    assert len(caught) == 1 and "max_resolution=128" in str(caught[0].message)


@pytest.mark.parametrize("kw, match", [
    ({"max_resolution": 1}, "max_resolution must be an integer"),
    ({"max_resolution": 10**6}, "max_resolution must be an integer"),
    ({"max_resolution": 2.5}, "max_resolution must be an integer"),
    ({"min_feature": -1.0}, "min_feature must be a positive number"),
    ({"min_feature": "a"}, "min_feature must be a positive number"),
    ({"min_feature": float("nan")}, "min_feature must be a positive number"),
])
def test_bad_thin_arguments(kw, match):
    with pytest.raises(csdf.CsdfError, match=match):
        csdf.mesh(csdf.sphere(1.0), progress=False, **kw)


def test_min_feature_sets_how_deep_the_check_looks():
    # a plate 1/20 voxel thick: found when the cells reach below it, not at 1/2 voxel
    plate = csdf.box((1.0, 1.0, 0.004))
    f = as_field(plate)
    origin, h, dims = _grid_layout(f.bounds, 13, None)
    grid = Grid(origin=origin, h=h, dims=dims)
    assert thin_parts(grid, f.value, f.intervals, 1.0, min_cell=h / 64).voxels > 0
    shallow = thin_parts(grid, f.value, f.intervals, 1.0, min_cell=h / 2)
    deep = thin_parts(grid, f.value, f.intervals, 1.0, min_cell=h / 64)
    assert shallow.lost_volume <= deep.lost_volume


def test_bookshelf_keeps_its_boards():
    """The issue's case: ``board=0.012`` at resolution 64 gave 0 faces; the default
    resolution gave 25 % of the volume."""
    shelf = zoo.load("bookshelf")
    true = _mc_volume(shelf, {"board": 0.012})
    m, caught = _mesh(shelf, params={"board": 0.012})
    assert not caught and m.is_watertight
    assert m.volume == pytest.approx(true, rel=0.02)
    # an explicit grid too coarse for the boards: the mesh says what it lost
    m, caught = _mesh(shelf, params={"board": 0.012}, resolution=64)
    assert len(caught) == 1 and "loses parts thinner than a voxel" in str(caught[0].message)


@pytest.mark.parametrize("resolution", [64, None])
def test_params_and_defaults_give_the_same_mesh(resolution):
    given = csdf.mesh(zoo.load("bookshelf"), params={"board": 0.012}, resolution=resolution,
                      progress=False, check_thin=resolution is None)
    loaded = csdf.mesh(zoo.load("bookshelf", board=0.012), resolution=resolution,
                       progress=False, check_thin=resolution is None)
    np.testing.assert_array_equal(given.faces, loaded.faces)
    np.testing.assert_array_equal(given.vertices, loaded.vertices)


def test_cli_prints_the_warning(tmp_path):
    model = tmp_path / "plate.csdf"  # a ball in a plate 0.3 voxel thick at 12
    model.write_text("export box((1, 1, 0.025)) | sphere(0.3)\n")
    out = tmp_path / "plate.stl"
    r = subprocess.run([sys.executable, "-m", "csdf.cli", "mesh", str(model), "-o", str(out),
                        "-r", "12", "-q"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "warning: csdf.mesh: the grid" in r.stderr and out.exists()
    r = subprocess.run([sys.executable, "-m", "csdf.cli", "mesh", str(model), "-o", str(out),
                        "-r", "12", "-q", "--no-check-thin"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0 and "warning" not in r.stderr
    # a grid that loses everything: the warning, then a clear error, and no file
    out.unlink()
    model.write_text("export box((1, 1, 0.025))\n")
    r = subprocess.run([sys.executable, "-m", "csdf.cli", "mesh", str(model), "-o", str(out),
                        "-r", "12", "-q"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "the mesh is empty" in r.stderr and not out.exists()
    assert "most of the shape" in r.stderr or "% of the shape's volume" in r.stderr
