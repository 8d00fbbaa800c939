"""The parameter-only prefix of a lowered program, computed by the compiled
interpreter (:meth:`csdf.backends.lowering.Lowered.prefix`), and the fast backend's
uniform inputs kept per parameter vector: the results must be those of the NumPy
reference, bit for bit."""

from __future__ import annotations

import numpy as np

import csdf
from csdf.backends import numpy_backend
from csdf.backends.lowering import lowered
from csdf.expr import param


def _same(got, want) -> bool:
    """Equal bit for bit, NaN where NaN (a NaN's payload may differ)."""
    got = np.asarray(got, dtype=np.float64).ravel()
    want = np.asarray(want, dtype=np.float64).ravel()
    nan = np.isnan(want)
    return got.shape == want.shape and bool(np.all(np.isnan(got) == nan)) and \
        got[~nan].tobytes() == want[~nan].tobytes()


def test_compiled_prefix_equals_the_numpy_reference_bit_for_bit() -> None:
    turned = csdf.zoo.load("chair").rotate(param("yaw_", 0.3, -7.0, 7.0), "z").translate(
        (param("dx_", 0.1, -1.0, 1.0), param("dy_", -0.2, -1.0, 1.0), 0.0))
    rng = np.random.default_rng(3)
    for shape in (csdf.zoo.load("lamp"), turned):
        prog = shape.compile()
        low = lowered(prog)
        assert low.n_prefix > 5
        lo = np.array([p.lo for p in prog.params])
        hi = np.array([p.hi for p in prog.params])
        for step in range(40):
            pv = rng.uniform(lo, hi)
            if step == 30:
                pv[step % len(pv)] = np.nan  # NaN in, NaN out
            for tangents in (True, False):
                got_v, got_d = low.prefix(pv, tangents)
                want_v, want_d = numpy_backend.uniform_prefix(prog, pv, low.n_prefix,
                                                              tangents)
                assert _same(got_v, want_v)
                if tangents:
                    assert _same(got_d, np.reshape(want_d, got_d.shape))


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
