"""Recycled result memory of the fast backend (``csdf.memory``): memory is only
reused once no array or view of an earlier result uses it, and the pool stays bounded."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf import memory as reuse

MB = 1 << 20


@pytest.fixture(autouse=True)
def small_pool(monkeypatch):
    """Pool results from 1 MB up (cheap tests), starting and ending empty."""
    monkeypatch.setattr(reuse, "MIN_BYTES", MB)
    reuse.release_memory()
    yield
    reuse.release_memory()


def _address(a: np.ndarray) -> int:
    return a.__array_interface__["data"][0]


def test_small_results_are_ordinary_arrays():
    a = reuse.result_array((1000,), np.float64)
    assert a.base is None and a.flags.owndata


def test_a_dropped_result_is_reused_and_a_held_one_never():
    a = reuse.result_array((MB // 8 * 2,), np.float64)
    assert a.flags.writeable and a.flags.c_contiguous and a.dtype == np.float64
    first = _address(a)
    a[:] = 1.0
    b = reuse.result_array((MB // 8 * 2,), np.float64)  # a is held: new memory
    assert _address(b) != first
    b[:] = 2.0
    assert np.all(a == 1.0)
    del a
    c = reuse.result_array((MB // 8 * 2,), np.float64)  # a was dropped: its memory
    assert _address(c) == first
    assert np.all(b == 2.0)


def test_a_view_keeps_the_memory_in_use():
    a = reuse.result_array((2 * MB // 8, 2), np.float64)
    a[:] = 3.0
    column = a[:, 1]  # a view outlives the result
    del a
    b = reuse.result_array((2 * MB // 8, 2), np.float64)
    b[:] = -1.0
    assert np.all(column == 3.0)


def test_the_pool_is_bounded_and_can_be_released():
    held = [reuse.result_array((MB,), np.uint8) for _ in range(reuse.MAX_MAPS + 2)]
    pooled = [a for a in held if a.base is not None]
    assert len(pooled) == reuse.MAX_MAPS  # the others are plain np.empty arrays
    del held, pooled
    other = reuse.result_array((3 * MB,), np.uint8)  # a new size drops the idle maps
    assert len(reuse._maps) == 1
    del other
    assert reuse.release_memory() == 3 * MB
    assert reuse._maps == []


def test_out_of_range_sizes_are_not_pooled(monkeypatch):
    monkeypatch.setattr(reuse, "MAX_BYTES", 2 * MB)
    a = reuse.result_array((4 * MB,), np.uint8)
    assert a.flags.owndata and reuse._maps == []


def test_repeated_fast_evaluations_stay_independent():
    pytest.importorskip("numba")
    prog = csdf.sphere(1.0).compile()
    pts = np.random.default_rng(0).uniform(-2, 2, (200_000, 3))  # 1.6 MB results: pooled
    expect = np.linalg.norm(pts, axis=1) - 1.0
    d1 = prog(pts, backend="fast")
    d2 = prog(pts * 0.5, backend="fast")  # d1 is held: its memory is not touched
    assert d1.base is not None and d2.base is not None  # both on pooled maps
    np.testing.assert_allclose(d1, expect, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d2, np.linalg.norm(pts * 0.5, axis=1) - 1.0, rtol=0,
                               atol=1e-12)
    addr = _address(d1)
    del d1
    d3 = prog(pts * 2.0, backend="fast")  # d1's memory, with the new values
    assert _address(d3) == addr
    np.testing.assert_allclose(d3, np.linalg.norm(pts * 2.0, axis=1) - 1.0, rtol=0,
                               atol=1e-12)
    del d2, d3
    g = prog.gradient(pts, backend="fast")  # (another size: the idle maps make way)
    np.testing.assert_allclose(g, pts / np.linalg.norm(pts, axis=1)[:, None], atol=1e-12)


def test_nothing_is_pooled_where_the_in_use_check_fails(monkeypatch):
    assert reuse._WORKS  # (Linux: mremap tells held maps from free ones)
    monkeypatch.setattr(reuse, "_WORKS", False)
    a = reuse.result_array((2 * MB,), np.uint8)
    assert a.flags.owndata and reuse._maps == []
