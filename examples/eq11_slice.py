"""The first-order distance of the paper's Eq. 11 on the algebraic sphere: writes
``docs/eq11_slice.png``, the slice z = 0.6 of ``f / |grad f|`` for ``f = x^2 + y^2 + z^2 - 1``
(left: the field and its zero contour; right: ``|grad| - 1``, zero on the surface and
growing away from it, as Eq. 11 predicts).

Run: ``python examples/eq11_slice.py``.
"""

from __future__ import annotations

from pathlib import Path

import csdf
from csdf import x, y, z


def main() -> Path:
    alg = csdf.field(x * x + y * y + z * z - 1.0, bounds=((-2, -2, -2), (2, 2, 2)))
    out = Path(__file__).resolve().parent.parent / "docs" / "eq11_slice.png"
    return csdf.save_slice(alg.normalized(far=csdf.sphere(1.9)), out, axis="z", at=0.6,
                           extent=((-2, 2), (-2, 2)), resolution=300,
                           show_gradient_error=True)


if __name__ == "__main__":
    print(main())
