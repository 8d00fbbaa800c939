"""The slot file of a compiled program: where x, y, z, parameters, constants and
registers live.

Every instruction of a :class:`csdf.Program` reads and writes slots of one flat file::

    0 1 2 | 3 .. 3+P-1 | 3+P .. 3+P+C-1 | 3+P+C .. 3+P+C+R-1
    x y z | parameters | constants      | registers

(``P`` parameters sorted by name, ``C`` constants, ``R`` registers). This module is the
one place that knows that arithmetic; the compiler, the bytecode codecs and every
evaluator ask a :class:`SlotLayout` instead of writing ``3 + P + ...`` themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SlotLayout", "MAX_SLOTS", "MAX_PARAMS", "N_COORDS", "COLOR_CHANNELS"]

#: slots a program may use (slot numbers are 16-bit in the bytecode)
MAX_SLOTS = 65535
#: The most parameters a program may have. Bounding the count (rather than the
#: Jacobian's working size at evaluation time) keeps every consumer safe at once:
#: forward-mode differentiation carries one tangent of ``3 + P`` numbers per point and
#: live register and seeds the parameters with a ``(3 + P) x (3 + P)`` identity, so its
#: memory grows as ``P**2`` even for a single point (30,000 parameters would need
#: 7.2 GB); at 1024 that is 8 MB for the seeds and 8 MB per live register for a chunk of
#: 1024 points, and fitting and the editor stay interactive. Real models have tens of
#: parameters; one that needs more can make values that never vary constants.
MAX_PARAMS = 1024
#: the coordinate slots x, y, z come first
N_COORDS = 3


@dataclass(frozen=True)
class SlotLayout:
    """Slot numbering for ``n_params`` parameters, ``n_consts`` constants and
    ``n_regs`` registers (see the module docs)."""

    n_params: int
    n_consts: int
    n_regs: int = 0

    @property
    def param_base(self) -> int:
        """Slot of the first parameter."""
        return N_COORDS

    @property
    def const_base(self) -> int:
        """Slot of the first constant."""
        return N_COORDS + self.n_params

    @property
    def reg_base(self) -> int:
        """Slot of the first register (= :attr:`n_fixed`)."""
        return N_COORDS + self.n_params + self.n_consts

    @property
    def n_fixed(self) -> int:
        """Number of preloaded slots (coordinates, parameters, constants)."""
        return self.reg_base

    @property
    def n_slots(self) -> int:
        """Total number of slots."""
        return self.reg_base + self.n_regs

    def param(self, i: int) -> int:
        """Slot of parameter ``i``."""
        return N_COORDS + i

    def const(self, j: int) -> int:
        """Slot of constant ``j``."""
        return N_COORDS + self.n_params + j

    def reg(self, k: int) -> int:
        """Slot of register ``k``."""
        return self.reg_base + k

    def is_param(self, s: int) -> bool:
        return N_COORDS <= s < self.const_base

    def is_const(self, s: int) -> bool:
        return self.const_base <= s < self.reg_base

    def is_reg(self, s: int) -> bool:
        return self.reg_base <= s < self.n_slots

    def kind(self, s: int) -> str:
        """``'coord' | 'param' | 'const' | 'reg'`` for slot ``s`` (ValueError if out of
        range)."""
        if 0 <= s < N_COORDS:
            return "coord"
        if self.is_param(s):
            return "param"
        if self.is_const(s):
            return "const"
        if self.is_reg(s):
            return "reg"
        raise ValueError(f"slot {s} is outside the file of {self.n_slots} slots")

#: the channel programs of a colour section whose colours vary continuously (smooth
#: blends, colour fields): red, green, blue, alpha and the weight of uncoloured surfaces
COLOR_CHANNELS = 5
