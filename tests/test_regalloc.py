"""The one register allocator (``csdf.compiler.regalloc.linear_scan``)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csdf.compiler.regalloc import linear_scan


def test_operand_register_is_reused_by_its_consumer():
    # 0: a   1: b   2: a + b   3: c   4: (a + b) * c
    regs, n = linear_scan([[], [], [0, 1], [], [2, 3]], live_out=[4])
    assert regs == [0, 1, 0, 1, 0] and n == 2


def test_lowest_free_register_first_and_repeated_reads():
    # 0, 1, 2 live together; 3 = f(2, 2) frees r2 only; 4 = g(0, 1) frees r0, r1
    regs, n = linear_scan([[], [], [], [2, 2], [0, 1], [3, 4]], live_out=[5])
    assert regs == [0, 1, 2, 2, 0, 0] and n == 3


def test_live_out_and_unread_values_keep_their_registers():
    regs, n = linear_scan([[], [0], []], live_out=[1])
    assert regs == [0, 0, 1] and n == 2
    regs, n = linear_scan([[], [], [1]])  # 0 is never read and keeps r0
    assert regs == [0, 1, 1] and n == 2
    assert linear_scan([]) == ([], 0)


def test_reads_must_refer_to_earlier_instructions():
    with pytest.raises(ValueError, match="instruction 1 reads instruction 1"):
        linear_scan([[], [1]])


@st.composite
def tapes(draw):
    n = draw(st.integers(1, 40))
    reads = [draw(st.lists(st.integers(0, i - 1), max_size=2)) if i else [] for i in range(n)]
    return reads, draw(st.lists(st.integers(0, n - 1), max_size=2))


@settings(max_examples=300, deadline=None)
@given(case=tapes())
def test_no_live_value_is_overwritten(case):
    """Simulate: a value must still be in its register whenever it is read, and at the
    end for live_out; the count is the peak number of registers in use."""
    reads, live_out = case
    regs, n = linear_scan(reads, live_out)
    holder: dict[int, int] = {}  # register -> instruction whose value it holds
    for i, srcs in enumerate(reads):
        for j in srcs:
            assert holder[regs[j]] == j, f"instruction {i} reads {j}, clobbered"
        holder[regs[i]] = i
    for j in live_out:
        assert holder[regs[j]] == j
    assert sorted(set(regs)) == list(range(n))
