"""``csdf.mesh``: a watertight triangle mesh of a shape's zero set."""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

from ..errors import CsdfError, MeshWarning
from ..field import Field, as_field, auto_bounds, check_bounds, kernel_cache_dir
from .grid import BRICK, Grid
from .reference import extract
from .thin import MC_POINTS, ThinReport, ThinScan, thin_parts

__all__ = ["mesh", "auto_bounds", "mesh_grid", "prepare_field", "MAX_RESOLUTION",
           "MAX_MESH_RESOLUTION", "MAX_VOXELS"]

MAX_RESOLUTION = 4096
_JITTER = np.array([0.3819660112501051, 0.2360679774997897, 0.1458980337503155])  # golden
MAX_VOXELS = 4096**3
_PAD = 5  # voxels added to the bounds' count along each axis (2 + jitter each side)
#: the largest ``resolution`` (voxels along the bounds' longest side) within the limits
MAX_MESH_RESOLUTION = MAX_RESOLUTION - _PAD
#: the finest resolution the thin-part check chooses by default
DEFAULT_MAX_RESOLUTION = 1024
_BASE_RESOLUTION = 128  # the default resolution of a shape without thin parts


def mesh(
    shape,
    resolution: int | None = None,
    voxel_size: float | None = None,
    bounds=None,
    method: str = "mc",
    params: dict | None = None,
    progress: bool = True,
    *,
    max_resolution: int = DEFAULT_MAX_RESOLUTION,
    min_feature: float | None = None,
    check_thin: bool = True,
    check_ranges: bool = True,
    colors: bool = False,
    fit_bounds: bool = False,
):
    """Triangle mesh of the surface ``f = 0``.

    Args:
        shape: a :class:`csdf.Shape` (or a compiled :class:`csdf.Program`), or a
            :class:`csdf.Scene` (:meth:`csdf.Scene.mesh`: each model meshed once and
            placed per instance; the face's instance ids in
            ``mesh.metadata['csdf']['instance']``).
        resolution: voxels along the longest side of the bounds. Default: chosen from
            the shape, 128 or finer where it has thin parts (see ``check_thin``).
        voxel_size: voxel edge length in model units (instead of ``resolution``).
        bounds: ``((xmin, ymin, zmin), (xmax, ymax, zmax))``; default: the shape's
            bounding box, else one found by interval arithmetic; padded by 2 voxels.
            Parts outside are clipped (the mesh is closed on the box).
        method: ``'mc'`` marching cubes, or ``'dc'`` dual contouring (keeps sharp edges
            and corners, using exact gradients).
        params: parameter values ``{name: value}``.
        progress: show a progress bar on stderr (Rich).
        max_resolution: the finest default resolution (a ``resolution`` chosen by the
            thin-part check never exceeds it; default 1024).
        min_feature: the thinnest part or gap (model units) the thin-part check looks
            for (thinner ones may go unnoticed): cells are refined with interval
            arithmetic down to half of it. Default: 1/4 voxel.
        check_thin: look for parts and gaps thinner than a voxel, which a grid loses
            between its samples (:mod:`csdf.mesh.thin`). Without ``resolution`` and
            ``voxel_size``, the resolution is 128, doubled (up to ``max_resolution``)
            while the grid loses more than :data:`~csdf.mesh.thin.LOST_FRACTION` of
            the volume in thin parts, while the mesh's volume differs from the
            field's Monte Carlo volume by more than :data:`VOLUME_TOLERANCE`, or while
            a lost part lies between two pieces of the mesh; a
            :class:`csdf.MeshWarning` says when the last grid still falls short. With
            them, the warning says when the grid loses thin parts and how much.
            ``False`` skips the checks (128 by default).
        check_ranges: refuse parameter values outside their declared ranges.
        colors: give the vertices the shape's colours (:func:`csdf.colors.colors_at`,
            the nearest coloured surface; ``mesh.visual.vertex_colors``, RGBA uint8),
            which PLY and GLB files keep.
        fit_bounds: stretch the grid along each axis (by under one voxel over the
            bounds) so that its first and last sample planes lie a fiftieth of a voxel
            inside each face of the bounds (:data:`FIT_INSET`). A thin part lying on a
            face of the bounding box (a flange on a CAD part's cap, a raised label) is
            then sampled instead of falling between two planes. The voxels become boxes
            whose three edges differ by under ``1/m`` (``m`` voxels along the axis),
            given in ``mesh.metadata['csdf']['voxel_sizes']``. Needs a shape (not a
            compiled program) in its own frame; the field is meshed as the shape scaled
            by those factors (the scale's three factors are parameters, so its kernels
            compile once for every resolution), and the vertices are scaled back.

    Returns:
        ``trimesh.Trimesh``: watertight, 2-manifold, consistently wound (normals point
        outwards), vertices on the zero set to ``1e-6`` voxel (``mc``).

    Raises:
        CsdfError: bad arguments: a ``resolution`` outside ``[2, 4091]``; a
            ``voxel_size`` that is not a positive number, that makes the grid exceed
            4096 voxels per side, or that is over half the bounds' longest side (the
            mesh would be empty); bounds of zero size (a point-like shape), or too
            large or too small to grid in float64.
    """
    import trimesh

    if getattr(shape, "__csdf_scene__", False):  # a csdf.Scene meshes its instances
        if colors:
            raise CsdfError("colors=True meshes a shape; a scene's instances are "
                            "coloured by their own meshes")
        if bounds is not None or params:
            raise CsdfError("a scene's instances carry their own parameters and bounds")
        if fit_bounds:
            raise CsdfError("fit_bounds=True meshes a shape; a scene's instances are "
                            "meshed on their own grids")
        return shape.mesh(resolution, voxel_size, method, progress,
                          max_resolution=max_resolution, min_feature=min_feature,
                          check_thin=check_thin, check_ranges=check_ranges)
    if method not in ("mc", "dc"):
        raise CsdfError(f"method must be 'mc' or 'dc', got {method!r}")
    if resolution is not None and voxel_size is not None:
        raise CsdfError("give resolution or voxel_size, not both")
    # a sweep (csdf.field): one evaluator for the whole mesh, since a sample shared by
    # two bricks must get the same value (and sign) whichever chunk evaluates it
    fld = as_field(shape, params, what="mesh", check_ranges=check_ranges)
    if fld.shape is not None and fld.shape.dim != 3:
        raise CsdfError("mesh needs a 3D shape; extrude or revolve a 2D shape first")
    if bounds is not None:
        fld = Field(fld, bounds=check_bounds(bounds))
    max_resolution = _check_max_resolution(max_resolution)
    fitted = _FittedGrid(fld) if fit_bounds else None
    if min_feature is not None:
        min_feature = _check_min_feature(min_feature)

    t0 = time.perf_counter()
    reporter = _Progress() if progress else None
    try:
        if reporter and not fld.kernels_ready(("value",) if method == "mc" else
                                              ("value", "grad")):
            reporter.compiling(kernel_cache_dir())
        auto = resolution is None and voxel_size is None
        if auto:
            resolution = min(_BASE_RESOLUTION, max_resolution)
        thin, agrees = None, True
        while True:
            if fitted is None:
                origin, h, dims = _grid_layout(fld.bounds, resolution, voxel_size)
                grid, work = Grid(origin=origin, h=h, dims=dims), fld
            else:
                grid, work = fitted.layout(resolution, voxel_size)
                h, dims = grid.h, grid.dims
            verts, faces, thin = _extract(work, grid, method, reporter, check_thin,
                                          min_feature, auto)
            if thin is None:
                break
            mesh_vol = _mesh_volume(verts, faces) if auto else None
            agrees = mesh_vol is None or _volume_agrees(mesh_vol, thin)
            if auto and 2 * resolution <= max_resolution and (
                    thin.too_coarse() or not agrees or _bridges_lost(verts, faces, thin)):
                resolution *= 2
                continue
            break
        if thin is not None and (thin.too_coarse() or not agrees):
            _warn_thin(thin, auto, max_resolution, None if agrees else mesh_vol)
    finally:
        if reporter:
            reporter.close()
    if method == "dc" and len(faces):
        # two dual-contouring vertices of neighbouring voxels can be projected onto the
        # same sharp feature point; a reader that merges close vertices (trimesh does,
        # within 1e-8) would then fuse them and make edges of 4 faces
        separate_close_vertices(verts, faces, min_edge_length(verts, h))
    if fitted is not None:
        verts = verts / fitted.factors
    m = trimesh.Trimesh(vertices=verts, faces=faces, process=False, validate=False)
    if colors:
        from ..colors import colors_of

        rgba = colors_of(shape, verts, params, check_ranges=check_ranges) if len(verts) \
            else np.zeros((0, 4))
        m.visual.vertex_colors = np.rint(np.nan_to_num(rgba, nan=0.0) * 255).astype(np.uint8)
    m.metadata["csdf"] = {
        "method": method, "voxel_size": h, "dims": dims, "seconds": time.perf_counter() - t0,
        "resolution": resolution,
        "thin_fraction": None if thin is None else thin.fraction,
        "field_volume": None if thin is None else thin.field_volume,
    }
    if fitted is not None:
        m.metadata["csdf"]["voxel_sizes"] = (h / fitted.factors).tolist()
        m.metadata["csdf"]["field_volume"] = None if thin is None else \
            thin.field_volume / float(np.prod(fitted.factors))
    return m


#: with ``fit_bounds``, the first and last sample planes along each axis lie this
#: share of a voxel inside the low and the high faces of the bounds (two different
#: irrational fractions, so that a face at a rational fraction of the bounds, its middle
#: or a third, never lies on a sample plane)
FIT_INSET = ((math.sqrt(5.0) - 2.0) / 10.0, (3.0 - math.sqrt(5.0)) / 40.0)


class _FittedGrid:
    """The grid of ``fit_bounds``: the shape scaled by ``factors (3,)`` (parameters of
    one program, set per resolution), meshed on a cubic grid whose planes lie
    :data:`FIT_INSET` of a voxel inside the scaled bounds' faces."""

    def __init__(self, fld: Field):
        if fld.shape is None:
            raise CsdfError("fit_bounds=True needs a csdf.Shape (it scales the shape per "
                            "axis), not a compiled program")
        if not fld.pose.is_identity():
            raise CsdfError("fit_bounds=True meshes a shape in its own frame; give the "
                            "shape without a pose")
        from ..expr import param

        taken = set(fld.param_names)
        base = "fit_bounds_scale"
        while any(f"{base}_{a}" in taken for a in "xyz"):
            base += "_"
        self.names = [f"{base}_{a}" for a in "xyz"]
        ks = [param(n, 1.0, 1e-3, 1e3) for n in self.names]
        self.fld = fld
        self.program = fld.shape.scale(ks).compile()  # once, for every resolution
        self.factors = np.ones(3)

    def layout(self, resolution: Any, voxel_size: Any) -> tuple[Grid, Field]:
        """The grid and the scaled field at ``resolution`` or ``voxel_size`` (checked as
        :func:`mesh` checks them); sets :attr:`factors`."""
        b = np.asarray(self.fld.bounds, dtype=np.float64)
        _, h, _ = _grid_layout(b, resolution, voxel_size)
        ext = b[1] - b[0]
        lo_in, hi_in = FIT_INSET
        m = np.maximum(1.0, np.round(ext / h))
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(ext > 0, h * (m + lo_in + hi_in) / ext, 1.0)
        self.factors = s
        # the grid starts (2 + jitter) voxels below its bounds' low corner, so its
        # first plane inside them lies (1 - jitter) voxels above that corner
        lo = b[0] * s - (1.0 - _JITTER - lo_in) * h
        hi = b[1] * s
        origin, h2, dims = _grid_layout(np.array([lo, hi]), None, h)
        params = dict(self.fld.params)
        params.update(zip(self.names, (float(v) for v in s)))
        work = as_field(self.program, params, bounds=np.array([lo, hi]), what="mesh",
                        check_ranges=False)
        return Grid(origin=origin, h=h2, dims=dims), work


#: the default resolution is doubled while the mesh's volume and the field's differ by
#: more than this (relative), besides three standard errors of the field's estimate
VOLUME_TOLERANCE = 0.01


def _extract(fld: Field, grid: Grid, method: str, reporter: Any, check_thin: bool,
             min_feature: float | None, volume: bool
             ) -> tuple[np.ndarray, np.ndarray, ThinReport | None]:
    """``(vertices (V, 3), faces (F, 3), thin-part report or None)`` of the field's zero
    set on ``grid``: compiled and streamed where the field has a serial evaluator (the
    thin-part check then scans the mesher's own samples), else the NumPy reference.
    ``volume``: the report estimates the field's volume too."""
    lip = fld.lipschitz
    lip = lip if math.isfinite(lip) and lip > 0 else None
    mc = MC_POINTS if volume else 0
    serial = fld.serial_values()
    update = reporter.update if reporter else None
    prepare_field(fld, grid)
    if serial is None and not fld.pruned():
        verts, faces = extract(grid, fld.value, fld.gradient, fld.intervals, method, update)
        rep = thin_parts(grid, fld.value, fld.intervals, lip, min_cell=min_feature,
                         mc_points=mc) if check_thin else None
        return verts, faces, rep
    # compiled, streamed over the octree's bricks (same results, see stream.py)
    from .stream import extract_dc, extract_mc

    scan = ThinScan(grid, lip) if check_thin else None
    if method == "mc":
        verts, faces = extract_mc(grid, fld.value, fld.intervals, update, serial=serial,
                                  scan=scan)
    else:
        verts, faces = extract_dc(grid, fld.value, fld.gradient, fld.intervals, update,
                                  serial=serial, values_and_gradients=fld.value_and_grad,
                                  scan=scan)
    if scan is None:
        return verts, faces, None
    if reporter:
        reporter.stage("checking for thin parts")
    return verts, faces, scan.report(fld.value, fld.intervals, min_feature, mc_points=mc)


def prepare_field(fld: Field, grid: Grid) -> None:
    """Get ``fld`` ready to mesh ``grid``: a field with pruned tapes keeps them on the
    octree's own cells (the same cells wherever the grid is meshed, whole or in parts)."""
    if fld.pruned():
        size, depth = BRICK, 0
        while size < max(grid.dims):
            size, depth = 2 * size, depth + 1
        fld.set_region([grid.origin, grid.origin + size * grid.h], min(depth + 2, 7))


def mesh_grid(bounds: Any, resolution: Any = None, voxel_size: Any = None) -> Grid:
    """The grid :func:`mesh` samples for ``bounds (2, 3)`` at ``resolution`` (voxels along
    the longest side; default 128) or ``voxel_size``: padded by 2 voxels and shifted by
    the jitter, every argument checked (:class:`csdf.CsdfError` naming it)."""
    if resolution is not None and voxel_size is not None:
        raise CsdfError("give resolution or voxel_size, not both")
    origin, h, dims = _grid_layout(np.asarray(bounds, dtype=np.float64), resolution,
                                   voxel_size)
    return Grid(origin=origin, h=h, dims=dims)


def _mesh_volume(verts: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume (units^3) of a closed, outward-wound triangle mesh."""
    vol = 0.0
    for a in range(0, len(faces), _FACE_BLOCK):
        f = faces[a:a + _FACE_BLOCK]
        v0, v1, v2 = verts[f[:, 0]], verts[f[:, 1]], verts[f[:, 2]]
        vol += float(np.einsum("ij,ij->", v0, np.cross(v1, v2)))
    return vol / 6.0


def _bridges_lost(verts: np.ndarray, faces: np.ndarray, rep: ThinReport) -> bool:
    """A lost part lies between two pieces of the mesh (within a voxel diagonal of
    both): the grid has broken a thin connection (a rod, a rim) that holds the shape
    together, although little volume is lost."""
    pts = rep.lost_parts
    if pts is None or not len(pts) or not len(faces):
        return False
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(verts)
    e = faces[:, [0, 1, 1, 2]].reshape(-1, 2)
    graph = coo_matrix((np.ones(len(e), dtype=np.int8), (e[:, 0], e[:, 1])), shape=(n, n))
    n_comp, label = connected_components(graph, directed=False)
    if n_comp < 2:
        return False
    from scipy.spatial import cKDTree

    near = cKDTree(verts).query_ball_point(pts, r=float(np.sqrt(3.0)) * rep.h)
    return any(len({int(label[i]) for i in idx}) > 1 for idx in near)


def _volume_agrees(mesh_volume: float, rep: ThinReport) -> bool:
    """The mesh's volume is within :data:`VOLUME_TOLERANCE` (plus three standard
    errors) of the field's Monte Carlo volume on the same grid."""
    want = rep.field_volume
    if not math.isfinite(want) or want <= 0:
        return True
    return abs(mesh_volume - want) <= VOLUME_TOLERANCE * want + 3.0 * rep.field_volume_se


def _warn_thin(rep: ThinReport, auto: bool, max_resolution: int,
               mesh_volume: float | None) -> None:
    """A :class:`csdf.MeshWarning` that the grid loses thin parts (how much, where), or
    (``mesh_volume`` given) that the mesh's volume is off the field's."""
    if auto:
        fix = (f"the default resolution stops at max_resolution={max_resolution}; raise "
               "it, or give resolution= or voxel_size=")
    else:
        fix = "use a finer resolution or voxel_size (leave both unset to choose one)"
    if rep.too_coarse():
        where = "" if rep.where is None else \
            f", e.g. near ({', '.join(_num(v) for v in rep.where)})"
        what = "parts" if rep.lost_volume >= rep.gap_volume else "gaps"
        share = f"about {100 * rep.fraction:.2g}% of the shape's volume" \
            if rep.fraction < 1 else "most of the shape"
        text = (f"the grid (voxel {_num(rep.h)}) loses {what} thinner than a voxel: "
                f"{share}, in {rep.voxels:,} voxels{where}")
    else:
        off = 100 * (mesh_volume - rep.field_volume) / rep.field_volume
        text = (f"the mesh's volume differs from the field's by {off:+.2g}% (voxel "
                f"{_num(rep.h)}): parts or gaps about a voxel thin are resolved poorly")
    warnings.warn(f"csdf.mesh: {text}; {fix}", MeshWarning, stacklevel=3)


def _check_max_resolution(n: Any) -> int:
    """``max_resolution`` checked: an integer in ``[2, MAX_MESH_RESOLUTION]``."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or \
            not 2 <= n <= MAX_MESH_RESOLUTION:
        raise CsdfError(f"max_resolution must be an integer in [2, {MAX_MESH_RESOLUTION}], "
                        f"got {_show(n)}")
    return int(n)


def _check_min_feature(x: Any) -> float:
    """``min_feature`` checked: a positive finite number."""
    return _positive(x, "min_feature must be a positive number (model units)")


def _positive(x: Any, what: str) -> float:
    """``x`` as a positive finite float, else a :class:`CsdfError` ``"{what}, got x"``."""
    bad = isinstance(x, bool)
    v = math.nan
    try:
        v = float(x)
    except (TypeError, ValueError, OverflowError):
        bad = True
    if bad or not (v > 0 and math.isfinite(v)):
        raise CsdfError(f"{what}, got {_show(x)}")
    return v


#: dual-contouring vertices joined by an edge end at least this many voxels apart
MIN_EDGE_VOXELS = 1e-4
_FACE_BLOCK = 1 << 20  # faces per block in the scans of all faces (bounds temporaries)


def min_edge_length(verts: np.ndarray, h: float) -> float:
    """The shortest edge a mesh keeps (model units): :data:`MIN_EDGE_VOXELS` voxels of
    edge ``h``, and at least 32 float32 steps at the mesh's largest coordinate, so the
    ends stay distinct in float32 files (STL, PLY) and for readers that merge vertices
    closer than 1e-8."""
    big = float(np.abs(verts).max()) if len(verts) else 0.0
    return max(MIN_EDGE_VOXELS * h, 32.0 * float(np.finfo(np.float32).eps) * big, 1e-7)


def separate_close_vertices(verts: np.ndarray, faces: np.ndarray, min_edge: float,
                            rounds: int = 4) -> int:
    """Move apart, in place, the two ends of every triangle edge shorter than
    ``min_edge``: each end moves ``min_edge`` towards the centroid of its own
    neighbours (the ends have different neighbours, so they part; a move of 1e-4 voxel
    changes no triangle's orientation), and half the shortfall away from the other end
    along the edge, so the edge reaches ``min_edge`` even where both centroids lie the
    same way. ``verts (V, 3)`` float64, ``faces (F, 3)``.

    Returns:
        The number of vertex moves made (0 for almost every mesh: only the vertices of
        short edges are touched).
    """
    moves = 0
    for _ in range(rounds):
        if not _may_have_short_edge(verts, faces, min_edge):
            break
        ends = _short_edge_ends(verts, faces, min_edge)
        if not len(ends):
            break
        idx = np.unique(ends)
        # the faces around those vertices, and each vertex's neighbours' centroid
        near = faces[np.isin(faces, idx).any(axis=1)]
        e = near[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        e = np.concatenate([e, e[:, ::-1]])
        e = e[np.isin(e[:, 0], idx)]
        acc = np.zeros((len(idx), 3))
        cnt = np.zeros(len(idx))
        pos = np.searchsorted(idx, e[:, 0])
        np.add.at(acc, pos, verts[e[:, 1]])
        np.add.at(cnt, pos, 1.0)
        u = acc / np.maximum(cnt, 1.0)[:, None] - verts[idx]
        n = np.linalg.norm(u, axis=1)
        ok = n > 0
        # the shortfall of each short edge, split between its ends along the edge
        d = verts[ends[:, 0]] - verts[ends[:, 1]]
        dn = np.linalg.norm(d, axis=1)
        push = np.zeros((len(idx), 3))
        along = dn > 0
        step = (0.5 * (min_edge - dn[along]) + 0.5 * min_edge) / dn[along]
        np.add.at(push, np.searchsorted(idx, ends[along, 0]), d[along] * step[:, None])
        np.add.at(push, np.searchsorted(idx, ends[along, 1]), -d[along] * step[:, None])
        verts[idx[ok]] += min_edge * u[ok] / n[ok, None]
        verts[idx] += push
        moves += int(ok.sum())
    return moves


def _may_have_short_edge(verts: np.ndarray, faces: np.ndarray, min_edge: float) -> bool:
    """False when no edge is shorter than ``min_edge``, found in one compiled pass
    (~10 ms per million faces; the common case); True when there may be one, or when
    Numba is missing (then :func:`_short_edge_ends` decides)."""
    try:
        from .dc_kernels import has_short_edge
    except ImportError:  # pragma: no cover - Numba is a dependency
        return True
    if verts.dtype != np.float64:
        return True
    return bool(has_short_edge(verts, np.ascontiguousarray(faces, dtype=np.int64),
                               min_edge * min_edge))


def _short_edge_ends(verts: np.ndarray, faces: np.ndarray, min_edge: float) -> np.ndarray:
    """``(K, 2)`` vertex pairs of the triangle edges shorter than ``min_edge`` (NumPy,
    in blocks of :data:`_FACE_BLOCK` faces)."""
    ends = [np.zeros((0, 2), dtype=faces.dtype)]
    for a in range(0, len(faces), _FACE_BLOCK):
        f = faces[a:a + _FACE_BLOCK]
        for i, j in ((0, 1), (1, 2), (2, 0)):
            d = verts[f[:, i]] - verts[f[:, j]]
            short = np.einsum("ij,ij->i", d, d) < min_edge * min_edge
            if short.any():
                ends.append(f[short][:, [i, j]])
    return np.concatenate(ends)


class _Progress:
    """A Rich progress bar on stderr over the mesher's stages (octree levels, samples,
    roots), with a line when the field's kernels must first be compiled."""

    def __init__(self) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.bar: Any = Progress(TextColumn("meshing {task.description}"), BarColumn(),
                                 TimeElapsedColumn(), transient=True,
                                 console=Console(stderr=True))
        self.bar.start()
        self.task = self.bar.add_task("octree", total=4)

    def compiling(self, where: Any) -> None:
        """Say that the field's kernels are being compiled (their first use on this
        machine: seconds to a minute) and where they are cached: as the bar's stage,
        and as a line that stays (printed plainly when stderr is not a terminal)."""
        self.bar.console.print(
            f"csdf: compiling kernels (first use only; cached in {where})",
            markup=False, highlight=False, soft_wrap=True)
        self.bar.update(self.task, description="compiling kernels (first use only)")

    def stage(self, text: str) -> None:
        """Show a stage outside the octree-samples-roots sequence (the thin-part check)."""
        self.bar.update(self.task, description=text)

    def update(self, stage: str, a: int, b: int) -> None:
        """Show stage ``stage`` at ``a`` of ``b`` items."""
        # octree: up to 1; samples (a of b bricks, called per chunk): 1 to 3; roots: 4
        done = {"octree": 1.0, "samples": 1.0 + 2.0 * a / max(b, 1)}.get(stage, 4.0)
        label = f"{stage} ({b:,} {'cells' if stage == 'octree' else 'items'})"
        self.bar.update(self.task, description=label, completed=done)

    def close(self) -> None:
        """Stop the display (it leaves no bar behind)."""
        self.bar.stop()


def _num(x: Any) -> str:
    """A number for a message: plain and short (``2``, ``0.015625``, ``1e+300``), never
    a NumPy repr such as ``np.float64(2.0)``."""
    try:
        return f"{float(x):.6g}"
    except (TypeError, ValueError, OverflowError):
        return repr(x)


def _show(x: Any) -> str:
    """A user's argument for a message: strings and booleans as written, numbers plainly
    (:func:`_num`), anything else by its type."""
    if isinstance(x, (str, bool)) or x is None:
        return repr(x)
    if isinstance(x, (int, np.integer)):
        return _show_int(x)
    if isinstance(x, (float, np.floating)):
        return _num(x)
    return f"a {type(x).__name__}"


def _limit(x: float, up: bool) -> str:
    """A limit for a message, rounded to 6 digits away from the forbidden side (so the
    value shown is itself allowed): up for a minimum, down for a maximum."""
    shown = float(f"{x:.6g}")
    if (shown < x) if up else (shown > x):
        shown = float(f"{x * (1 + 5e-6 if up else 1 - 5e-6):.6g}")
    return f"{shown:.6g}"


def _show_int(n: int) -> str:
    """An integer for a message, without printing hundreds of digits."""
    n = int(n)
    return str(n) if abs(n) < 10**15 else f"an integer of {n.bit_length()} bits"


def _grid_layout(bounds: np.ndarray, resolution: Any, voxel_size: Any
                 ) -> tuple[np.ndarray, float, tuple[int, int, int]]:
    """``(origin (3,), voxel edge h, dims)`` of the sampling grid over ``bounds``
    (padded by 2 voxels and shifted by the jitter), with every argument checked.

    Raises:
        CsdfError: see :func:`mesh`; each message names the argument and its limits.
    """
    b = np.asarray(bounds, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        extent = b[1] - b[0]
    side = float(extent.max())
    box = f"[{', '.join(_num(v) for v in b[0])}] .. [{', '.join(_num(v) for v in b[1])}]"
    if not math.isfinite(side):
        raise CsdfError(f"bounds {box} are too large: their size overflows float64; "
                        "give bounds whose sides are below 1e308")
    if not side > 0:
        raise CsdfError(f"the bounds {box} have zero size (a point-like or empty "
                        "shape?); nothing to mesh")
    if voxel_size is not None:
        h = _positive(voxel_size, "voxel_size must be a positive number")
        h_min = side / MAX_MESH_RESOLUTION
        if h < h_min:
            raise CsdfError(
                f"voxel_size {_num(h)} makes the grid exceed the limit of "
                f"{MAX_RESOLUTION} voxels per side over bounds whose longest side is "
                f"{_num(side)}; voxel_size must be at least {_limit(h_min, True)} (or use "
                f"resolution <= {MAX_MESH_RESOLUTION})")
        if h > side / 2:
            raise CsdfError(
                f"voxel_size {_num(h)} is larger than half the bounds' longest side "
                f"({_num(side)}): the mesh would be empty; voxel_size must be at most "
                f"{_limit(side / 2, False)}")
    else:
        n = 128 if resolution is None else resolution
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
            raise CsdfError(f"resolution must be an integer in [2, {MAX_MESH_RESOLUTION}] "
                            f"(voxels along the longest side), got {_show(resolution)}")
        if not 2 <= n <= MAX_MESH_RESOLUTION:
            raise CsdfError(f"resolution must be an integer in [2, {MAX_MESH_RESOLUTION}] "
                            f"(voxels along the longest side; the grid is over the limit "
                            f"of {MAX_RESOLUTION} per side beyond), got {_show_int(n)}")
        h = side / int(n)
    # a voxel must be a step float64 can take at these coordinates
    scale = float(np.abs(b).max())
    if h < 16 * float(np.spacing(scale)) or h < 16 * float(np.finfo(np.float64).tiny):
        raise CsdfError(f"bounds {box} are too small for float64 at their position: a "
                        f"voxel of {_num(h)} cannot be resolved; give larger bounds")
    # shift the grid by irrational fractions of a voxel, so faces at round coordinates
    # (an axis-aligned box) never lie on sample planes, where the sign test and the
    # gradient are ambiguous
    origin = b[0] - h * (2.0 + _JITTER)
    counts = np.ceil(extent / h) + _PAD
    if not np.all(np.isfinite(origin)) or not np.all(np.isfinite(origin + h * counts)):
        raise CsdfError(f"bounds {box} are too large: the padded grid overflows float64; "
                        "give smaller bounds")
    dims = tuple(int(c) for c in counts)
    if max(dims) > MAX_RESOLUTION or math.prod(dims) > MAX_VOXELS:
        raise CsdfError(
            f"grid of {dims} voxels is over the limit of {MAX_RESOLUTION} per side; "
            "use a coarser resolution or voxel_size"
        )
    return origin, h, dims
