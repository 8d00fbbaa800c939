"""Empty-space skipping of the sphere tracer (``Field.empty_cells``, ``trace._empty_run``).

Properties: every cell flagged empty holds only positive values; the digital
differential analyser walks only through flagged cells and stops at the first cell
that is not flagged; tracing with skipping finds the same hits as without (but for
rays grazing a sliver thinner than the hit tolerance) with fewer evaluations; fields
that are not pruned, or posed, offer no cells.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

import csdf
from csdf.render.trace import _empty_run, sphere_trace, trace_frame

F = importlib.import_module("csdf.field")  # (csdf.field is the user-field function)
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


@pytest.fixture
def pruned_field(monkeypatch):
    monkeypatch.setattr(F, "PRUNE_MIN_INSTRUCTIONS", 100)
    prog = csdf.zoo.clutter(30, seed=4).compile()
    fld = csdf.as_field(prog)
    assert fld.pruned()
    return prog, fld


def _cell_index(p, lo, span, n):
    u = (p - lo) / span
    return np.clip(np.floor(u * n).astype(np.int64), 0, n - 1)


def _trace(fld, skip):
    b = fld.bounds
    cam = csdf.Camera.look_at(eye=b[1] + 0.9 * np.max(b[1] - b[0]), target=b.mean(0),
                              width=96, height=72)
    _, d = cam.rays()
    return cam, d, sphere_trace(fld, cam.t, d, skip_empty=skip)


def test_flagged_cells_hold_only_positive_values(pruned_field):
    prog, fld = pruned_field
    lo, span, n, empty = fld.empty_cells()
    assert n == 2 * (1 << 5)  # one level finer than the tapes' cells
    _trace(fld, True)  # builds cells along the rays
    flagged = np.flatnonzero(empty)
    assert 50 < len(flagged) < n ** 3
    rng = np.random.default_rng(0)
    pick = rng.choice(flagged, min(300, len(flagged)), replace=False)
    ijk = np.stack(np.unravel_index(pick, (n, n, n)), 1)
    h = span / n
    pts = (lo + (ijk[:, None, :] + rng.uniform(0, 1, (len(pick), 20, 3))) * h).reshape(-1, 3)
    assert np.all(prog(pts, backend="interp") > 0)
    # the cells' corners too (their boxes are closed)
    corners = (lo + (ijk[:, None, :] + np.array(np.meshgrid([0, 1], [0, 1], [0, 1]))
                     .reshape(3, -1).T[None]) * h).reshape(-1, 3)
    assert np.all(prog(corners, backend="interp") > 0)


def test_the_walk_stays_in_flagged_cells_and_stops_at_the_first_other(pruned_field):
    prog, fld = pruned_field
    cam, d, _ = _trace(fld, True)
    lo, span, n, empty = fld.empty_cells()
    flag = empty.reshape(n, n, n)
    tmax = 1e3
    o = np.asarray(cam.t, float)
    walked = 0
    rng = np.random.default_rng(1)
    for i in rng.choice(len(d), 600, replace=False):
        for t in (np.linalg.norm(o - lo - span / 2) * rng.uniform(0.6, 1.2),):
            te = _empty_run(o, d[i], t, tmax, lo, span, n, empty)
            assert te >= t
            if te == t:
                continue
            walked += 1
            s = np.linspace(t, te, 64)[1:-1]
            p = o + s[:, None] * d[i]
            c = _cell_index(p, lo, span, n)
            inside = np.all((p >= lo) & (p <= lo + span), axis=1)
            assert np.all(flag[tuple(c[inside].T)] == 1)
            assert np.all(prog(p, backend="interp") > 0)
            if te < tmax:  # just past the end: outside the grid or a cell not flagged
                q = o + (te + 1e-6 * np.linalg.norm(span)) * d[i]
                if np.all((q >= lo) & (q <= lo + span)):
                    assert flag[tuple(_cell_index(q, lo, span, n))] == 0
    assert walked > 20


def test_skipping_finds_the_same_hits_with_fewer_evaluations(pruned_field):
    prog, fld = pruned_field
    _trace(fld, True)  # cells known from a first image
    _, d, skip = _trace(fld, True)
    _, _, plain = _trace(fld, False)
    assert skip.evaluations < 0.9 * plain.evaluations
    # the two sample rays differently, so they may differ only on rays that graze a
    # sliver thinner than the hit tolerance
    assert (skip.hit != plain.hit).mean() <= 0.005
    both = skip.hit & plain.hit
    assert (np.abs(skip.t[both] - plain.t[both]) <= 1e-8).mean() >= 0.995
    eps = trace_frame(fld).eps
    cam = _trace(fld, True)[0]
    for i in np.flatnonzero(skip.hit != plain.hit):
        t = np.linspace(0, 3 * np.linalg.norm(fld.bounds[1] - fld.bounds[0]), 200001)
        f = prog(cam.t + t[:, None] * d[i], backend="interp")
        assert f.min() > -eps  # a sliver: inside for less than the tolerance


def test_no_cells_for_short_or_posed_fields(pruned_field):
    prog, fld = pruned_field
    assert csdf.as_field(csdf.sphere(1)).empty_cells() is None
    posed = csdf.as_field(prog, pose=csdf.Pose.from_rotvec([0, 0, 0.3], [1, 0, 0]))
    assert posed.empty_cells() is None
