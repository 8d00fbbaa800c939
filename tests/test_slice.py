"""Slice plots: the field on a plane, the zero contour where the surface is, the gradient
error panel, saving PNGs atomically, and argument errors."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

import csdf  # noqa: E402
from csdf.slicing import ZERO_CONTOUR_GID, save_slice, slice_values  # noqa: E402
from csdf.slicing import slice as slice_plot  # noqa: E402


def csg_example():
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


def zero_segments(fig: Figure) -> list[np.ndarray]:
    ax = fig.axes[0]
    found = [c for c in ax.collections if c.get_gid() == ZERO_CONTOUR_GID]
    assert len(found) == 1, "no zero contour drawn"
    return [s for s in found[0].allsegs[0] if len(s)]


@pytest.mark.parametrize("at", [0.0, 0.6])
def test_sphere_slice_zero_contour_is_the_circle(at):
    fig = slice_plot(csdf.sphere(1.0), axis="z", at=at, resolution=300)
    assert isinstance(fig, Figure)
    segs = zero_segments(fig)
    assert len(segs) == 1
    r = np.linalg.norm(segs[0], axis=1)
    want = np.sqrt(1.0 - at**2)
    assert np.max(np.abs(r - want)) < 1e-3
    # a closed curve all around
    ang = np.sort(np.arctan2(segs[0][:, 1], segs[0][:, 0]))
    assert np.max(np.diff(ang)) < 0.1 and ang[0] < -3.0 and ang[-1] > 3.0
    assert fig.axes[0].get_xlabel() == "x" and fig.axes[0].get_ylabel() == "y"


def test_axis_selects_the_plane():
    # the torus around z cut by x = 0: two circles of radius 0.2 at (y, z) = (+-0.6, 0)
    fig = slice_plot(csdf.torus(0.6, 0.2), axis="x", at=0.0, resolution=300)
    segs = zero_segments(fig)
    assert len(segs) == 2
    for s in segs:
        centre = np.array([np.sign(s[:, 0].mean()) * 0.6, 0.0])
        assert np.max(np.abs(np.linalg.norm(s - centre, axis=1) - 0.2)) < 1e-3
    assert fig.axes[0].get_xlabel() == "y" and fig.axes[0].get_ylabel() == "z"
    # y = 0.6 cuts the tube through its centre: a ring of radii 0.4 and 0.8 ... in (x, z)
    data = slice_values(csdf.torus(0.6, 0.2), axis="y", at=0.6, resolution=50)
    assert data["labels"] == ("x", "z")
    u, v = np.meshgrid(data["u"], data["v"])
    want = np.hypot(np.hypot(u, 0.6) - 0.6, v) - 0.2
    np.testing.assert_allclose(data["f"], want, atol=1e-12)


def test_default_extent_and_aspect():
    box = csdf.box((2.0, 1.0, 0.5))
    data = slice_values(box, axis="z", resolution=100)
    (u0, u1), (v0, v1) = data["extent"]
    assert (u0, u1) == pytest.approx((-1.2, 1.2)) and (v0, v1) == pytest.approx((-0.6, 0.6))
    assert data["f"].shape == (50, 100)
    data = slice_values(box, axis="y", extent=((0, 1), (-2, 2)), resolution=40)
    assert data["f"].shape == (40, 10)
    # a Program: bounds found by interval arithmetic
    data = slice_values(csdf.sphere(1.0).compile(), resolution=20)
    (u0, u1), _ = data["extent"]
    assert -1.3 < u0 < -1.1 and 1.1 < u1 < 1.3


def test_field_colours_are_centred_and_levels_regular():
    fig = slice_plot(csdf.sphere(0.5).translate((0.3, 0, 0)), resolution=120)
    ax = fig.axes[0]
    im = ax.images[0]
    lo, hi = im.get_clim()
    assert lo == pytest.approx(-hi)  # diverging colormap centred at 0
    iso = [c for c in ax.collections if c.get_gid() != ZERO_CONTOUR_GID]
    levels = np.asarray(iso[0].levels)
    assert 0.0 not in levels  # the zero contour is drawn on its own, bold
    steps = np.diff(np.sort(np.append(levels, 0.0)))
    assert len(levels) >= 5 and np.allclose(steps, steps[0])
    fig = slice_plot(csdf.sphere(0.5), resolution=60, levels=[-0.2, 0.1, 0.3])
    iso = [c for c in fig.axes[0].collections if c.get_gid() != ZERO_CONTOUR_GID]
    assert list(iso[0].levels) == [-0.2, 0.1, 0.3]
    assert len(fig.axes) == 2  # the field and its colorbar


def test_gradient_error_panel():
    shape = csdf.union(csdf.sphere(0.5), csdf.box(0.6).translate((0.6, 0, 0)), k=0.3,
                       blend="smooth")
    fig = slice_plot(shape, show_gradient_error=True, resolution=150)
    assert len(fig.axes) == 4  # two panels, two colorbars
    err = np.ma.getdata(fig.axes[1].images[0].get_array())
    assert err.shape == (fig.axes[0].images[0].get_array().shape)
    g = slice_values(shape, resolution=150, gradient=True)["grad"]
    np.testing.assert_allclose(err, np.linalg.norm(g, axis=-1) - 1.0)
    assert err.min() < -0.3  # the blend underestimates the slope
    lo, hi = fig.axes[1].images[0].get_clim()
    assert lo == pytest.approx(-hi)
    # an exact shape: |grad f| = 1 away from the centre
    fig = slice_plot(csdf.sphere(1.0), show_gradient_error=True, resolution=64)
    err = np.ma.getdata(fig.axes[1].images[0].get_array())
    assert np.median(np.abs(err)) < 1e-12


def test_draws_into_given_axes():
    fig = Figure()
    ax = fig.add_subplot(1, 1, 1)
    assert slice_plot(csdf.sphere(1.0), ax=ax, resolution=40) is fig
    fig2 = Figure()
    axes = [fig2.add_subplot(1, 2, i + 1) for i in range(2)]
    assert slice_plot(csdf.sphere(1.0), ax=axes, show_gradient_error=True,
                      resolution=40) is fig2
    assert all(isinstance(a, Axes) for a in fig2.axes)
    with pytest.raises(csdf.CsdfError, match="two matplotlib Axes"):
        slice_plot(csdf.sphere(1.0), ax=ax, show_gradient_error=True, resolution=40)


def test_slice_of_csg_example_with_parameters():
    r = csdf.param("r", 1.0, lo=0.8, hi=1.2)
    c = csdf.cylinder(0.5, 3.0)
    shape = (csdf.sphere(r) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")
    fig = slice_plot(shape, axis="z", at=0.3, show_gradient_error=True, resolution=200,
                     params={"r": 0.9})
    segs = zero_segments(fig)
    assert len(segs) == 4  # four corner pieces between the tunnels
    pts = np.concatenate(segs)
    p3 = np.column_stack([pts, np.full(len(pts), 0.3)])
    assert np.max(np.abs(shape(p3, r=0.9))) < 5e-3


def test_save_slice_writes_png_atomically(tmp_path):
    path = tmp_path / "slice.png"
    out = save_slice(csg_example(), path, axis="z", at=0.3, show_gradient_error=True,
                     resolution=100)
    assert out == path
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert [p.name for p in tmp_path.iterdir()] == ["slice.png"]
    fig = slice_plot(csdf.sphere(1.0), resolution=50)  # plain savefig works too
    fig.savefig(tmp_path / "plain.png")
    assert (tmp_path / "plain.png").read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(csdf.CsdfError, match="image format"):
        save_slice(csdf.sphere(1.0), tmp_path / "x.jpg2")
    with pytest.raises(csdf.CsdfError, match="does not exist"):
        save_slice(csdf.sphere(1.0), tmp_path / "missing" / "x.png", resolution=20)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.png", "slice.png"]


def test_slice_misses_the_shape():
    fig = slice_plot(csdf.sphere(1.0), axis="z", at=2.0, extent=((-1, 1), (-1, 1)),
                     resolution=20)
    assert not [c for c in fig.axes[0].collections if c.get_gid() == ZERO_CONTOUR_GID]


def test_two_dimensional_shape():
    fig = slice_plot(csdf.circle(0.5), resolution=200)
    segs = zero_segments(fig)
    assert np.max(np.abs(np.linalg.norm(segs[0], axis=1) - 0.5)) < 1e-3


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"axis": "w"}, "axis"),
        ({"at": float("nan")}, "at must be"),
        ({"at": "0"}, "at must be"),
        ({"resolution": 1}, "resolution"),
        ({"resolution": 10_000}, "resolution"),
        ({"resolution": 50.0}, "resolution"),
        ({"extent": ((1, 0), (0, 1))}, "extent"),
        ({"extent": (1, 2, 3)}, "extent"),
        ({"params": {"nope": 1}}, "unknown parameter"),
        ({"levels": 0}, "levels"),
        ({"levels": ["a"]}, "levels"),
        ({"ax": "axes"}, "ax must be"),
    ],
)
def test_slice_errors(kwargs, match):
    with pytest.raises(csdf.CsdfError, match=match):
        slice_plot(csdf.sphere(1.0), **kwargs)


def test_slice_rejects_non_shapes():
    with pytest.raises(csdf.CsdfError, match="Shape or Program"):
        slice_plot(np.zeros(3))
