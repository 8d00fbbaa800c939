"""A stop request raised inside a compiled kernel's call (a ``SystemError`` whose context
is the ``KeyboardInterrupt``) is found and re-raised, never taken for a failed kernel."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.errors import interrupt_in


def _wrapped() -> SystemError:
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as inner:
            raise SystemError("returned a result with an exception set") from inner
    except SystemError as exc:
        return exc


def test_interrupt_in_finds_the_interrupt_in_the_chain():
    exc = _wrapped()
    assert isinstance(interrupt_in(exc), KeyboardInterrupt)
    assert interrupt_in(ValueError("x")) is None
    loop = ValueError("a")
    loop.__context__ = loop  # (a cycle ends the walk)
    assert interrupt_in(loop) is None


def test_the_field_does_not_fall_back_on_an_interrupt(monkeypatch):
    field = csdf.as_field(csdf.sphere(1.0))
    prog = field.program

    def broken(*_args, **_kwargs):
        raise _wrapped()

    monkeypatch.setattr(type(prog), "__call__", broken)
    with pytest.raises(KeyboardInterrupt):
        field.value(np.zeros((4, 3)))
    assert field.backend == "fast" or not field._auto  # (no silent switch)
