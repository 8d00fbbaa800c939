"""Plots of a distance field on an axis-aligned plane (matplotlib, Agg; no display).

:func:`slice` samples ``f`` on a grid in the plane ``axis = at`` and draws it with a
diverging colormap centred at 0 (inside ``f < 0`` blue, outside red), isolines at
regular distances and the zero contour (the surface) in bold black. With
``show_gradient_error=True`` a second panel shows ``|grad f| - 1`` from the exact
gradients, as in the paper's Figs. 7 and 9: 0 where the field is a distance, negative
where it underestimates the distance's slope (smooth blends, bounds), positive where a
field overestimates it (non-uniform scale, twist).

Figures are made without pyplot (``matplotlib.figure.Figure`` with the Agg canvas), so
nothing is opened on screen and nothing needs closing; in Jupyter the returned figure
displays as usual. :func:`save_slice` writes one atomically.

Needs matplotlib, which a plain ``pip install csdf`` does not install:
``pip install 'csdf[plot]'``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .errors import CsdfError
from .field import Field, as_field

__all__ = ["slice", "save_slice", "slice_values", "AXES", "ZERO_CONTOUR_GID",
           "SLICE_FORMATS"]

#: plane axes: the normal axis -> (index of the normal, indices of the (u, v) coordinates)
AXES = {"x": (0, (1, 2)), "y": (1, (0, 2)), "z": (2, (0, 1))}
#: ``gid`` of the bold zero contour (a ``ContourSet``), to find it in ``ax.collections``
ZERO_CONTOUR_GID = "csdf-zero-contour"
SLICE_FORMATS = {".png": "png", ".pdf": "pdf", ".svg": "svg"}
MAX_SLICE_RESOLUTION = 4096
_NAMES = "xyz"




def _default_extent(fld: Field, axis: str) -> tuple[tuple[float, float], ...]:
    """The field's bounds in the plane's ``(u, v)`` coordinates, padded by 10% (a 2D
    program's prism is taken as deep in z as it is wide in x and y)."""
    _, (iu, iv) = AXES[axis]
    try:
        if fld.dim == 2:
            b = fld.planar_bounds
            half = float(np.max(b[1] - b[0])) / 2
            b = np.column_stack([b, [-half, half]])
        else:
            b = fld.bounds
    except CsdfError as exc:
        if fld.dim == 2:
            raise CsdfError("give extent= for a 2D program (its bounds are not known)"
                            ) from None
        raise CsdfError(f"cannot find the shape's bounds ({exc}); pass extent=") from None
    out = []
    for i in (iu, iv):
        lo, hi = float(b[0, i]), float(b[1, i])
        pad = 0.1 * (hi - lo) if hi > lo else 0.5
        out.append((lo - pad, hi + pad))
    return tuple(out)


def _check_extent(extent: Any) -> tuple[tuple[float, float], tuple[float, float]]:
    try:
        e = np.asarray(extent, dtype=np.float64).reshape(2, 2)
    except (TypeError, ValueError):
        raise CsdfError("extent must be ((u0, u1), (v0, v1))") from None
    if not np.all(np.isfinite(e)) or np.any(e[:, 1] <= e[:, 0]):
        raise CsdfError(f"extent must be finite with u0 < u1 and v0 < v1, got {e.tolist()}")
    return (float(e[0, 0]), float(e[0, 1])), (float(e[1, 0]), float(e[1, 1]))


def slice_values(
    shape: Any,
    axis: str = "z",
    at: float = 0.0,
    extent: Any = None,
    params: dict | None = None,
    resolution: int = 400,
    gradient: bool = False,
    *,
    check_ranges: bool = True,
) -> dict[str, Any]:
    """The field sampled on a plane (the data :func:`slice` draws).

    Args:
        shape: a :class:`csdf.Shape` or :class:`csdf.Program`.
        axis: the plane's normal, ``'x' | 'y' | 'z'``; the plane's coordinates ``(u, v)``
            are ``(y, z)``, ``(x, z)`` and ``(x, y)`` respectively.
        at: the plane's coordinate along ``axis`` (model units).
        extent: ``((u0, u1), (v0, v1))`` in model units; default: the shape's bounds
            (analytic, else by interval arithmetic) padded by 10% on each side.
        params: parameter values ``{name: value}``.
        resolution: samples along the longer side of ``extent`` (2..4096); the other
            side gets as many as keep the samples square.
        gradient: also compute the exact gradient.
        check_ranges: refuse a parameter value outside its declared range
            (:class:`csdf.ParamError` naming the range); False samples it anyway.

    Returns:
        dict with ``'u' (nu,)`` and ``'v' (nv,)`` sample coordinates, ``'f' (nv, nu)``
        field values (rows along v), ``'grad' (nv, nu, 3)`` when ``gradient``,
        ``'axis'``, ``'at'``, ``'extent'`` and ``'labels'`` (the names of u and v).
    """
    if axis not in AXES:
        raise CsdfError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    if isinstance(at, bool) or not isinstance(at, (int, float, np.number)) or \
            not math.isfinite(float(at)):
        raise CsdfError(f"at must be a finite number, got {at!r}")
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or \
            not 2 <= resolution <= MAX_SLICE_RESOLUTION:
        raise CsdfError(f"resolution must be an integer in [2, {MAX_SLICE_RESOLUTION}], "
                        f"got {resolution!r}")
    # a sweep: one evaluator for the plane
    fld = as_field(shape, params, what="slice", check_ranges=check_ranges)
    ext = _check_extent(_default_extent(fld, axis) if extent is None else extent)
    (u0, u1), (v0, v1) = ext
    su, sv = u1 - u0, v1 - v0
    nu = resolution if su >= sv else max(2, round(resolution * su / sv))
    nv = resolution if sv >= su else max(2, round(resolution * sv / su))
    u = np.linspace(u0, u1, nu)
    v = np.linspace(v0, v1, nv)
    k, (iu, iv) = AXES[axis]
    pts = np.empty((nv, nu, 3))
    pts[..., k] = float(at)
    pts[..., iu] = u[None, :]
    pts[..., iv] = v[:, None]
    out: dict[str, Any] = {"u": u, "v": v, "axis": axis, "at": float(at), "extent": ext,
                           "labels": (_NAMES[iu], _NAMES[iv])}
    if gradient:
        f, g = fld.value_and_grad(pts)
        out["grad"] = np.asarray(g, dtype=np.float64)
    else:
        f = fld.value(pts)
    out["f"] = np.asarray(f, dtype=np.float64)
    return out


def _nice_step(span: float, count: int) -> float:
    """The smallest 1-2-5 step giving at most ``count`` intervals over ``span``."""
    raw = span / max(count, 1)
    if not (raw > 0 and math.isfinite(raw)):
        return 0.0
    mag = 10.0 ** math.floor(math.log10(raw))
    for m in (1.0, 2.0, 5.0, 10.0):
        if raw <= m * mag:
            return m * mag
    return 10.0 * mag


def _iso_levels(f: np.ndarray, levels: Any) -> np.ndarray:
    """Isoline values other than 0: ``levels`` values, or a regular 1-2-5 spacing."""
    finite = f[np.isfinite(f)]
    if finite.size == 0:
        return np.zeros(0)
    lo, hi = float(finite.min()), float(finite.max())
    if levels is None or (isinstance(levels, (int, np.integer)) and not isinstance(levels, bool)):
        count = 16 if levels is None else int(levels)
        if count < 1:
            raise CsdfError(f"levels must be >= 1 or a sequence of values, got {levels}")
        step = _nice_step(hi - lo, count)
        if step == 0.0:
            return np.zeros(0)
        vals = np.arange(math.ceil(lo / step), math.floor(hi / step) + 1) * step
    else:
        try:
            vals = np.asarray(levels, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            raise CsdfError("levels must be a count or a sequence of numbers") from None
        if not np.all(np.isfinite(vals)):
            raise CsdfError("levels must be finite numbers")
    vals = np.unique(vals[(vals != 0) & (vals > lo) & (vals < hi)])
    return vals


#: the one-line message when matplotlib is missing (it comes with the ``plot`` extra)
MATPLOTLIB_MISSING = "csdf slice needs matplotlib: pip install 'csdf[plot]'"


def _need_matplotlib() -> None:
    """Raise :class:`CsdfError` (:data:`MATPLOTLIB_MISSING`) when matplotlib cannot be
    imported: a plain ``pip install csdf`` does not install it."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise CsdfError(MATPLOTLIB_MISSING) from None


def _axes(ax: Any, panels: int, figsize: tuple[float, float] | None):
    """``(figure, [axes])``: new ones (Agg canvas, no pyplot), or the caller's."""
    from matplotlib.axes import Axes
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if ax is None:
        size = figsize or ((6.2, 5.0) if panels == 1 else (12.0, 5.0))
        fig = Figure(figsize=size, dpi=110, layout="constrained")
        FigureCanvasAgg(fig)
        axes = [fig.add_subplot(1, panels, i + 1) for i in range(panels)]
        return fig, axes
    axes = [ax] if isinstance(ax, Axes) else list(ax) if isinstance(ax, Sequence) else None
    if axes is None or not all(isinstance(a, Axes) for a in axes) or len(axes) != panels:
        need = "one matplotlib Axes" if panels == 1 else \
            "a sequence of two matplotlib Axes (field, gradient error)"
        raise CsdfError(f"ax must be {need}")
    return axes[0].get_figure(), axes


def slice(  # noqa: A001 - public name csdf.slice
    shape: Any,
    axis: str = "z",
    at: float = 0.0,
    extent: Any = None,
    params: dict | None = None,
    resolution: int = 400,
    levels: Any = None,
    show_gradient_error: bool = False,
    ax: Any = None,
    *,
    title: str | None = None,
    figsize: tuple[float, float] | None = None,
    check_ranges: bool = True,
):
    """Plot a distance field on the plane ``axis = at``.

    The field is drawn with a diverging colormap centred at 0 (symmetric limits: inside
    ``f < 0`` blue, outside red), thin isolines at regular distances (black outside,
    white inside) and the zero contour in bold black; with ``show_gradient_error`` a
    second panel shows ``|grad f| - 1`` (exact gradients, diverging colormap centred at
    0, with the zero contour for reference). Each panel has a colorbar.

    Args:
        shape: a :class:`csdf.Shape` or :class:`csdf.Program` (2D shapes are drawn as
            their prisms).
        axis: the plane's normal ``'x' | 'y' | 'z'``; the horizontal and vertical plot
            axes are ``(y, z)``, ``(x, z)`` and ``(x, y)`` respectively.
        at: the plane's coordinate along ``axis`` (model units).
        extent: ``((u0, u1), (v0, v1))`` in model units; default the shape's bounds
            padded by 10% on each side.
        params: parameter values ``{name: value}``.
        resolution: samples along the longer side of the plot (2..4096).
        levels: isolines besides the zero contour: ``None`` (multiples of a 1-2-5 step,
            at most 16 intervals over the range), a count of intervals, or a sequence
            of field values (model units).
        show_gradient_error: add the ``|grad f| - 1`` panel.
        ax: draw into this matplotlib ``Axes`` (a sequence of two with
            ``show_gradient_error``) instead of a new figure.
        title: title of the field panel (default: the plane, e.g. ``'z = 0.3'``).
        figsize: size of a new figure in inches.
        check_ranges: refuse a parameter value outside its declared range
            (:class:`csdf.ParamError` naming the range); False plots it anyway.

    Returns:
        ``matplotlib.figure.Figure``. The bold zero contour is the ``ContourSet`` in
        ``fig.axes[0].collections`` whose ``get_gid()`` is :data:`ZERO_CONTOUR_GID`;
        its ``allsegs[0]`` are the surface's cross-section polylines ``(M, 2)`` in
        ``(u, v)`` model coordinates.

    Raises:
        CsdfError: bad arguments; matplotlib not installed.
    """
    _need_matplotlib()
    from matplotlib.colors import Normalize

    data = slice_values(shape, axis, at, extent, params, resolution,
                        gradient=bool(show_gradient_error), check_ranges=check_ranges)
    f = data["f"]
    u, v = data["u"], data["v"]
    (u0, u1), (v0, v1) = data["extent"]
    lu, lv = data["labels"]
    iso = _iso_levels(f, levels)
    fig, axes = _axes(ax, 2 if show_gradient_error else 1, figsize)
    fm = np.ma.masked_invalid(f)
    finite = f[np.isfinite(f)]
    vmax = float(np.max(np.abs(finite))) if finite.size else 1.0
    vmax = vmax if vmax > 0 else 1.0
    img_extent = (u0, u1, v0, v1)

    a = axes[0]
    im = a.imshow(fm, origin="lower", extent=img_extent, cmap="RdBu_r",
                  norm=Normalize(-vmax, vmax), interpolation="bilinear", aspect="equal")
    if iso.size:
        a.contour(u, v, fm, levels=iso, colors=["white" if x < 0 else "black" for x in iso],
                  linewidths=0.5, alpha=0.55)
    zero = None
    if finite.size and finite.min() < 0 < finite.max():
        zero = a.contour(u, v, fm, levels=[0.0], colors="black", linewidths=2.2)
        zero.set_gid(ZERO_CONTOUR_GID)
    cb = fig.colorbar(im, ax=a, shrink=0.9)
    cb.set_label("f (model units; < 0 inside)")
    a.set_xlabel(lu)
    a.set_ylabel(lv)
    a.set_title(title if title is not None else f"{axis} = {data['at']:g}")

    if show_gradient_error:
        g = data["grad"]
        err = np.linalg.norm(g, axis=-1) - 1.0
        em = np.ma.masked_invalid(err)
        ef = err[np.isfinite(err)]
        emax = max(float(np.max(np.abs(ef))) if ef.size else 0.0, 1e-3)
        b = axes[1]
        im2 = b.imshow(em, origin="lower", extent=img_extent, cmap="PuOr_r",
                       norm=Normalize(-emax, emax), interpolation="nearest", aspect="equal")
        if zero is not None:
            b.contour(u, v, fm, levels=[0.0], colors="black", linewidths=1.2)
        cb2 = fig.colorbar(im2, ax=b, shrink=0.9)
        cb2.set_label("|∇f| − 1")
        b.set_xlabel(lu)
        b.set_ylabel(lv)
        worst = float(np.max(np.abs(ef))) if ef.size else float("nan")
        b.set_title(f"gradient error |∇f| − 1 (max |·| = {worst:.3g})")
    return fig


def save_slice(
    shape: Any,
    path: str | os.PathLike,
    *,
    dpi: int | None = None,
    **kwargs: Any,
) -> Path:
    """Draw :func:`slice` and write it to ``path`` (``.png``, ``.pdf`` or ``.svg``)
    atomically.

    Args:
        shape: a :class:`csdf.Shape` or :class:`csdf.Program`.
        path: output file; the format follows the extension.
        dpi: resolution of a PNG (default the figure's, 110).
        **kwargs: :func:`slice`'s arguments (``axis``, ``at``, ``extent``, ...; not
            ``ax``).

    Returns:
        The path written.

    Raises:
        CsdfError: unknown extension, unwritable folder, or bad :func:`slice` arguments.
    """
    from .io import atomic_path

    _need_matplotlib()
    target = Path(path)
    fmt = SLICE_FORMATS.get(target.suffix.lower())
    if fmt is None:
        raise CsdfError(f"cannot tell the image format of {target.name!r}; use one of "
                        f"{', '.join(sorted(SLICE_FORMATS))}")
    if "ax" in kwargs:
        raise CsdfError("save_slice draws its own figure; call slice(ax=...) and save that")
    fig = slice(shape, **kwargs)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, format=fmt, dpi=dpi)
    return target
