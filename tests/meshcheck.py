"""Mesh-quality checks for the model zoo (issue #15), shared by
``tests/test_zoo_mesh_quality.py`` and ``benchmarks/zoo_mesh_quality.py``.

The goal: every zoo model at every range end, meshed at default settings, has the same
number of connected components as at 4x the resolution and a volume within 2 % of the
Monte Carlo volume of its field.

* :func:`range_end_cases` lists a model's cases: its defaults, then each parameter at
  the low and at the high end of its range with the others at their defaults.
* :func:`monte_carlo_volume` estimates the volume of ``{f < 0}`` inside a field's
  (slightly padded) box with scrambled Sobol points, and its standard error from
  independent scrambles.
* :func:`check_case` meshes one case at default settings and at a quarter of the
  default voxel size, and compares components, watertightness and volume.

No test functions live here.
"""

from __future__ import annotations

import inspect
import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

import csdf
from csdf import zoo
from csdf.field import Field, as_field

__all__ = [
    "VOLUME_TOL", "MC_REL_SE_MAX", "MC_N", "MC_N_MAX", "CaseResult", "monte_carlo_volume",
    "range_end_cases", "mesh_components", "mesh_volume", "is_closed", "check_case", "all_cases",
]

#: the largest relative difference allowed between mesh volume and Monte Carlo volume
VOLUME_TOL = 0.02
#: the Monte Carlo estimate must be at least this precise (relative standard error)
#: before the volume comparison is trusted (well under :data:`VOLUME_TOL`)
MC_REL_SE_MAX = 0.003
#: points of the first Monte Carlo estimate; doubled up to :data:`MC_N_MAX` as needed
MC_N = 1 << 20
MC_N_MAX = 1 << 25
#: independent Sobol scrambles behind each estimate (its standard error)
MC_REPLICATES = 16
#: the box is padded by this fraction of its extent on each side
MC_PAD = 0.02
#: the fine mesh's longest side is at most this many voxels: the mesher's limit
#: (``csdf.mesh.api.MAX_MESH_RESOLUTION``, 4096 minus its padding). 4x of a default grid
#: above about 1023 voxels does not fit; such a case is compared at this resolution
#: (``fine_factor`` says how much finer) and noted, not failed. Beware the memory: a
#: compact shape at 4091^3 makes about 100M triangles (over 10 GB).
FINE_MAX_RESOLUTION = 4091
_CHUNK = 1 << 18  # points per evaluation (a power of two, to keep Sobol balance)


def monte_carlo_volume(fld: Field, n: int = MC_N, seed: int = 0,
                       replicates: int = MC_REPLICATES, pad: float = MC_PAD
                       ) -> tuple[float, float]:
    """Volume of ``{f < 0}`` inside the field's bounds, by randomised quasi-Monte Carlo.

    The bounds (which hold the surface) are padded by ``pad`` times their extent on each
    side. ``replicates`` independently scrambled Sobol sequences (Owen scrambling,
    :class:`scipy.stats.qmc.Sobol`) of ``n / replicates`` points each (rounded to a
    power of two) give independent unbiased estimates; their mean is the volume and
    their standard deviation over ``sqrt(replicates)`` its standard error.

    Args:
        fld: a :class:`csdf.field.Field` (``as_field(shape, params)``).
        n: total number of points (all replicates together).
        seed: seed of the scrambles (the result is deterministic for a seed).
        replicates: number of independent scrambles (at least 2).
        pad: relative padding of the bounds on each side.

    Returns:
        ``(volume, standard error)`` in model units cubed. Points where the field is NaN
        count as outside.
    """
    from scipy.stats import qmc

    if replicates < 2:
        raise ValueError("replicates must be at least 2 (for the standard error)")
    per = 1 << max(4, round(math.log2(max(n // replicates, 16))))
    b = np.asarray(fld.bounds, dtype=np.float64)
    ext = b[1] - b[0]
    lo = b[0] - pad * ext
    size = ext * (1.0 + 2.0 * pad)
    box = float(np.prod(size))
    seeds = np.random.SeedSequence([int(seed), 15]).spawn(replicates)
    estimates = np.empty(replicates)
    for r, ss in enumerate(seeds):
        sob = qmc.Sobol(d=3, scramble=True, seed=np.random.default_rng(ss))
        inside = 0
        done = 0
        while done < per:
            m = min(_CHUNK, per - done)
            pts = lo + sob.random(m) * size
            inside += int(np.count_nonzero(np.asarray(fld.value(pts)) < 0.0))
            done += m
        estimates[r] = box * inside / per
    vol = float(estimates.mean())
    se = float(estimates.std(ddof=1) / math.sqrt(replicates))
    return vol, se


def range_end_cases(name: str) -> list[tuple[str, dict[str, float]]]:
    """The cases of zoo model ``name``: ``("default", defaults)``, then for each
    parameter (in declaration order) ``("<p>=lo", ...)`` and ``("<p>=hi", ...)`` with
    that parameter at its range end and every other at its default. Infinite ends are
    skipped. Each dict gives every parameter's value explicitly."""
    shape = zoo.load(name)
    defaults = {p.name: float(p.default) for p in shape.params}
    cases: list[tuple[str, dict[str, float]]] = [("default", dict(defaults))]
    for p in shape.params:
        for end, value in (("lo", float(p.lo)), ("hi", float(p.hi))):
            if not math.isfinite(value):
                continue
            cases.append((f"{p.name}={end}", {**defaults, p.name: value}))
    return cases


def all_cases(models: list[str] | None = None) -> list[tuple[str, str, dict[str, float]]]:
    """``(model, label, params)`` for every case of every model (default: the zoo)."""
    return [(m, label, p) for m in (models or zoo.names()) for label, p in range_end_cases(m)]


@numba.njit(cache=True, nogil=True)
def _signed_volume(v: np.ndarray, f: np.ndarray) -> float:  # pragma: no cover - compiled
    total = 0.0
    for i in range(f.shape[0]):
        a, b, c = v[f[i, 0]], v[f[i, 1]], v[f[i, 2]]
        total += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                  + a[2] * (b[0] * c[1] - b[1] * c[0]))
    return total / 6.0


@numba.njit(cache=True, nogil=True)
def _vertex_components(n_vertices: int, f: np.ndarray) -> int:  # pragma: no cover
    parent = np.arange(n_vertices)

    def find(x: int) -> int:
        root = x
        while parent[root] != root:
            root = parent[root]
        while parent[x] != root:  # path compression
            parent[x], x = root, parent[x]
        return root

    used = np.zeros(n_vertices, dtype=np.bool_)
    for i in range(f.shape[0]):
        r0 = find(f[i, 0])
        used[f[i, 0]] = used[f[i, 1]] = used[f[i, 2]] = True
        for j in (1, 2):
            rj = find(f[i, j])
            if rj != r0:
                parent[rj] = r0
    count = 0
    for x in range(n_vertices):
        if used[x] and find(x) == x:
            count += 1
    return count


def mesh_volume(mesh: Any) -> float:
    """Enclosed volume of a closed, outward-wound triangle mesh (divergence theorem;
    the same value as ``mesh.volume``, without trimesh's mass-property pass)."""
    f = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    if not len(f):
        return 0.0
    return float(_signed_volume(np.ascontiguousarray(mesh.vertices, dtype=np.float64), f))


@numba.njit(cache=True, nogil=True)
def _closed_and_oriented(n_vertices: int, f: np.ndarray) -> bool:  # pragma: no cover
    # directed edges grouped by their first vertex (a counting sort), then each edge
    # a -> b must be the only a -> b and have exactly one b -> a
    n_edges = 3 * f.shape[0]
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for i in range(f.shape[0]):
        for j in range(3):
            start[f[i, j] + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    head = np.empty(n_edges, dtype=np.int64)
    for i in range(f.shape[0]):
        for j in range(3):
            a = f[i, j]
            head[fill[a]] = f[i, (j + 1) % 3]
            fill[a] += 1
    for a in range(n_vertices):
        for k in range(start[a], start[a + 1]):
            b = head[k]
            if b == a:
                return False
            same = 0
            for q in range(start[a], start[a + 1]):
                if head[q] == b:
                    same += 1
            back = 0
            for q in range(start[b], start[b + 1]):
                if head[q] == a:
                    back += 1
            if same != 1 or back != 1:
                return False
    return True


def is_closed(mesh: Any) -> bool:
    """True when the mesh is watertight and consistently wound: every directed edge
    occurs once and its reverse once (so every edge joins exactly two faces, traversed
    in opposite directions). An empty mesh is not closed."""
    f = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    if not len(f):
        return False
    return bool(_closed_and_oriented(max(len(mesh.vertices), int(f.max()) + 1), f))


def mesh_components(mesh: Any, exact: bool = False) -> int:
    """Connected components of a triangle mesh.

    By default faces are joined through shared vertices (a compiled union-find: about
    0.1 s for millions of faces). For a closed mesh whose vertices are manifold (the
    marching-cubes output: the faces around a vertex form one fan) that is the same
    count as joining faces through shared edges, which ``exact=True`` does (trimesh,
    as ``mesh.split(only_watertight=False)`` counts; seconds for millions of faces).
    """
    f = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    if not len(f):
        return 0
    if exact:
        import trimesh

        groups = trimesh.graph.connected_components(mesh.face_adjacency,
                                                    nodes=np.arange(len(f)), min_len=1)
        return len(groups)
    return int(_vertex_components(len(mesh.vertices), f))


def _closed(mesh: Any, which: str, problems: list[str]) -> bool:
    """Watertightness of ``mesh`` (the ``which`` mesh of a case), noting in ``problems``
    a mesh that is not watertight, or watertight but inconsistently wound."""
    if is_closed(mesh):
        return True
    if len(mesh.faces) and mesh.is_watertight:
        problems.append(f"{which} mesh watertight but not consistently wound")
        return True
    problems.append(f"{which} mesh not watertight")
    return False


def _no_thin_check() -> dict[str, Any]:
    """``{"check_thin": False}`` where :func:`csdf.mesh` takes it: the fine mesh is the
    reference, and the mesher's thin-part check (a warning for an explicit voxel size)
    would only add time."""
    try:
        takes = "check_thin" in inspect.signature(csdf.mesh).parameters
    except (TypeError, ValueError):
        takes = False
    return {"check_thin": False} if takes else {}


_NO_THIN_CHECK = _no_thin_check()


@dataclass
class CaseResult:
    """The outcome of :func:`check_case` for one model and parameter set."""

    model: str
    label: str
    params: dict[str, float]
    dims: tuple[int, int, int] = (0, 0, 0)
    voxel_size: float = float("nan")
    faces: int = 0
    faces_4x: int = 0
    fine_factor: float = 4.0  # default voxel size / fine voxel size (4 unless capped)
    seconds: float = 0.0  # the default mesh's wall time
    seconds_4x: float = 0.0
    seconds_mc: float = 0.0
    components: int = 0
    components_4x: int = 0
    watertight: bool = False
    watertight_4x: bool = False
    volume: float = float("nan")
    volume_4x: float = float("nan")
    mc_volume: float = float("nan")
    mc_stderr: float = float("nan")
    mc_points: int = 0
    error: str = ""  # an exception raised while checking
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # facts that are not failures

    @property
    def rel_error(self) -> float:
        """``(mesh volume - MC volume) / MC volume``."""
        if not self.mc_volume > 0:
            return float("nan")
        return (self.volume - self.mc_volume) / self.mc_volume

    @property
    def passed(self) -> bool:
        """True when no check failed."""
        return not self.problems

    def describe(self) -> str:
        """One line naming the case and what failed (for assertion messages)."""
        text = "; ".join(self.problems) or "ok"
        if self.notes:
            text += " (" + "; ".join(self.notes) + ")"
        return f"{self.model} [{self.label}]: {text}"


def check_case(model: str, label: str, params: Mapping[str, float], *,
               seed: int = 0, four_x: bool = True) -> CaseResult:
    """Check one case: mesh ``zoo.load(model)`` with ``params`` at default settings and
    at ``voxel_size`` = default voxel size / 4 (same params), then require

    * both meshes watertight;
    * the same number of connected components (when ``four_x``; where 4x would exceed
      :data:`FINE_MAX_RESOLUTION` voxels, the fine grid is that fine and a note says
      so);
    * the Monte Carlo volume's relative standard error at most :data:`MC_REL_SE_MAX`
      (the estimate is refined up to :data:`MC_N_MAX` points first);
    * ``|mesh volume - MC volume| <= VOLUME_TOL * MC volume``.

    Failures are listed in :attr:`CaseResult.problems` (an exception becomes one).
    """
    r = CaseResult(model=model, label=label, params=dict(params))
    try:
        shape = zoo.load(model)
        t0 = time.perf_counter()
        m = csdf.mesh(shape, params=dict(params), progress=False)
        r.seconds = time.perf_counter() - t0
        meta = m.metadata.get("csdf", {})
        r.dims = tuple(int(d) for d in meta.get("dims", (0, 0, 0)))  # type: ignore[assignment]
        r.voxel_size = float(meta.get("voxel_size", float("nan")))
        r.faces = len(m.faces)
        r.watertight = _closed(m, "default", r.problems)
        r.components = mesh_components(m)
        r.volume = mesh_volume(m)
        if r.faces == 0:
            r.problems.append("default mesh empty")
        if four_x:
            side = float(np.max(np.diff(as_field(shape, dict(params)).bounds, axis=0)))
            h4 = max(r.voxel_size / 4, side / FINE_MAX_RESOLUTION * (1 + 1e-9))
            r.fine_factor = r.voxel_size / h4
            if r.fine_factor < 3.999:
                r.notes.append(f"fine mesh capped at {FINE_MAX_RESOLUTION} voxels "
                               f"({r.fine_factor:.3f}x, not 4x)")
            t0 = time.perf_counter()
            with warnings.catch_warnings():  # a thin-part warning of the fine grid
                warnings.simplefilter("ignore")
                m4 = csdf.mesh(shape, params=dict(params), voxel_size=h4, progress=False,
                               **_NO_THIN_CHECK)
            r.seconds_4x = time.perf_counter() - t0
            r.faces_4x = len(m4.faces)
            r.watertight_4x = _closed(m4, "4x", r.problems)
            r.components_4x = mesh_components(m4)
            r.volume_4x = mesh_volume(m4)
            del m4
            if r.components != r.components_4x:
                r.problems.append(f"components {r.components} at default, "
                                  f"{r.components_4x} at 4x")
        t0 = time.perf_counter()
        fld = as_field(shape, dict(params))
        n = MC_N
        while True:
            vol, se = monte_carlo_volume(fld, n=n, seed=seed)
            if (vol > 0 and se <= MC_REL_SE_MAX * vol) or n >= MC_N_MAX:
                break
            n *= 2
        r.seconds_mc = time.perf_counter() - t0
        r.mc_volume, r.mc_stderr, r.mc_points = vol, se, n
        if not vol > 0:
            r.problems.append("Monte Carlo volume is zero")
        elif se > MC_REL_SE_MAX * vol:
            r.problems.append(f"Monte Carlo too imprecise: stderr {se / vol:.2%} "
                              f"> {MC_REL_SE_MAX:.2%} at {n} points")
        elif abs(r.rel_error) > VOLUME_TOL:
            r.problems.append(f"volume {r.volume:.6g} vs Monte Carlo {vol:.6g} +- {se:.2g} "
                              f"({r.rel_error:+.2%}, limit {VOLUME_TOL:.0%})")
    except Exception as exc:  # every failure is a finding
        r.error = f"{type(exc).__name__}: {exc}"
        r.problems.append(r.error)
    return r
