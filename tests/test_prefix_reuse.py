"""The parameter-only prefix of a lowered program is computed again only where a
parameter it reads changed (:meth:`csdf.backends.lowering.Lowered._prefix`), and the
fast backend keeps its uniform inputs per parameter vector: the results must be those
of a full computation, bit for bit."""

from __future__ import annotations

import numpy as np

import csdf
from csdf.backends import lowering, numpy_backend
from csdf.backends.lowering import lowered


def _bits(xs: list) -> list[bytes]:
    return [np.asarray(x, dtype=np.float64).tobytes() for x in xs]


def test_partial_prefix_equals_a_full_one_bit_for_bit(monkeypatch) -> None:
    prog = csdf.zoo.load("lamp").compile()
    low = lowered(prog)
    assert low.n_prefix > 5 and low._prefix_dep_mask.any(axis=0).sum() >= 3
    computed: list[int] = []
    run = numpy_backend.prefix_run

    def counting(prog_, pvals, n_prefix, tangents=True, keep=None, previous=None):
        computed.append(n_prefix if keep is None else int(n_prefix - np.sum(keep)))
        return run(prog_, pvals, n_prefix, tangents, keep, previous)

    monkeypatch.setattr(lowering, "prefix_run", counting)
    rng = np.random.default_rng(3)
    lo = np.array([p.lo for p in prog.params])
    hi = np.array([p.hi for p in prog.params])
    pv = np.array([p.default for p in prog.params])
    for step in range(40):
        pv = pv.copy()
        i = rng.integers(len(pv), size=1 + step % 3)  # one to three parameters move
        pv[i] = rng.uniform(lo[i], hi[i])
        if step == 30:
            pv[i[0]] = np.nan  # NaN in, NaN out: kept as such
        for tangents in (True, False):
            got_v, got_d = low._prefix(pv, tangents)
            want_v, want_d = numpy_backend.uniform_prefix(prog, pv, low.n_prefix, tangents)
            assert _bits(got_v) == _bits(want_v)
            assert _bits(got_d) == _bits(want_d)
    # something was reused: fewer instructions computed than 80 full runs
    assert sum(computed) < 0.8 * 80 * low.n_prefix


def test_fast_backend_values_follow_parameter_changes() -> None:
    shape = csdf.zoo.load("stool")
    prog = shape.compile()
    pts = np.random.default_rng(0).uniform(-0.4, 0.6, (300, 3))
    base = {p.name: p.default for p in prog.params}
    for name in list(base)[:3]:
        p = next(q for q in prog.params if q.name == name)
        changed = dict(base, **{name: 0.5 * (p.default + p.hi)})
        for pv in (changed, base):  # back to a vector seen before (kept inputs)
            f, g, J = prog.value_grad_param_jacobian(pts, pv, backend="fast")
            fr, gr, Jr = prog.value_grad_param_jacobian(pts, pv, backend="numpy")
            np.testing.assert_allclose(f, fr, atol=1e-9)
            np.testing.assert_allclose(J, Jr, atol=1e-7)


def test_param_values_of_a_solver_state_match_the_checked_path() -> None:
    """A dict of every parameter in order, as floats (the fit's state) takes a short
    path in :meth:`csdf.Program.param_values`: same vector as the checked one (given in
    another order), and what the checks refuse is still refused."""
    import pytest

    from csdf.errors import ParamError

    prog = csdf.zoo.load("chair").compile()
    names = prog.param_names
    vals = {n: np.float64(p.default) * 1.01 + i for i, (n, p) in
            enumerate(zip(names, prog.params))}
    fast = prog.param_values(vals, check_ranges=False)
    slow = prog.param_values(dict(reversed(list(vals.items()))), check_ranges=False)
    assert fast.tobytes() == slow.tobytes()
    assert fast.tobytes() == np.array([float(v) for v in vals.values()]).tobytes()
    with pytest.raises(ParamError):
        prog.param_values(dict(vals, **{names[0]: True}), check_ranges=False)
    with pytest.raises(ParamError):  # out of range: the fast path is unchecked only
        prog.param_values(dict(vals, **{names[0]: 1e9}))
