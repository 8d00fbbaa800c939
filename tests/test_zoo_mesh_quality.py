"""Mesh quality of the model zoo at its range ends (issue #15): every zoo model, meshed
at default settings (``csdf.mesh(shape, params=p)``), must be watertight (and
consistently wound), have the same number of connected components as at 4x the
resolution (a quarter of the default mesh's voxel size, same parameters), and a volume
within 2 % of the Monte Carlo volume of its field (whose relative standard error must be
at most 0.3 %). The checks are in ``tests/meshcheck.py``; ``benchmarks/zoo_mesh_quality.py``
prints the whole sweep as a table.

Cases: for each model, its defaults and each parameter at the low and at the high end of
its range with the others at their defaults (:func:`meshcheck.range_end_cases`).

* Normal run: the ``default`` case of every model, plus one range end per model,
  rotating through the list: the model at position ``i`` of ``zoo.names()`` gets range
  end number ``(i + ROTATION) mod (number of its range ends)``, ``ROTATION = 2``
  (``bookshelf``: ``depth=lo``, ``car``: ``cabin_height=hi``, ``chair``: ``leg=lo``,
  ``connector``: ``nut_length=hi``, ...). 26 cases, about 40 s (the offset keeps the
  two slowest cases, ``bookshelf board=lo`` and ``lamp wall=lo``, out of it).
* ``CSDF_ZOO_SWEEP=1``: every range end of every model (about 150 cases, minutes).
"""

from __future__ import annotations

import os

import pytest

from csdf import zoo

try:  # tests/ as a package or as a plain directory on sys.path
    from . import meshcheck
except ImportError:
    import meshcheck

#: the offset of the normal run's rotation through each model's range ends
ROTATION = 2
SWEEP = os.environ.get("CSDF_ZOO_SWEEP", "").strip() not in ("", "0")


def selected_cases(sweep: bool = SWEEP) -> list[tuple[str, str, dict[str, float]]]:
    """``(model, label, params)`` of the cases this run checks (see the module docs)."""
    out: list[tuple[str, str, dict[str, float]]] = []
    for i, model in enumerate(zoo.names()):
        cases = meshcheck.range_end_cases(model)
        if sweep:
            chosen = cases
        else:
            ends = cases[1:]
            chosen = [cases[0]] + ([ends[(i + ROTATION) % len(ends)]] if ends else [])
        out.extend((model, label, params) for label, params in chosen)
    return out


CASES = selected_cases()


def test_selection_is_deterministic():
    normal = selected_cases(sweep=False)
    assert normal == selected_cases(sweep=False)
    assert {m for m, _, _ in normal} == set(zoo.names())
    assert sum(label == "default" for _, label, _ in normal) == len(zoo.names())
    full = selected_cases(sweep=True)
    assert set((m, lab) for m, lab, _ in normal) <= set((m, lab) for m, lab, _ in full)


def test_range_end_cases_vary_one_parameter():
    for model in zoo.names():
        cases = meshcheck.range_end_cases(model)
        label, defaults = cases[0]
        assert label == "default"
        params = zoo.load(model).params
        assert defaults == {p.name: float(p.default) for p in params}
        for label, values in cases[1:]:
            changed = [k for k in values if values[k] != defaults[k]]
            name, end = label.split("=")
            assert changed in ([name], [])  # [] when the default is at a range end
            p = next(q for q in params if q.name == name)
            assert values[name] == float(p.lo if end == "lo" else p.hi)


@pytest.mark.parametrize("model,label,params",
                         [pytest.param(*c, id=f"{c[0]}-{c[1]}") for c in CASES])
def test_zoo_mesh_quality(model, label, params):
    r = meshcheck.check_case(model, label, params)
    assert r.passed, r.describe()
