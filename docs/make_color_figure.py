"""Draw ``docs/color_blend.png``: colours mixed through a smooth union and a colour
field (the README's Colours section). Run: ``python docs/make_color_figure.py``."""

from __future__ import annotations

from pathlib import Path

import csdf
from csdf.expr import X, Z, sin
from csdf.render import auto_camera

MODEL = csdf.union(
    csdf.box(1).round(0.05).color_field((0.5 + 0.5 * sin(8 * X), 0.35, Z + 0.5)),
    csdf.sphere(0.45).translate((0.65, 0, 0.3)).color((0.1, 0.4, 0.9)),
    csdf.cylinder(0.2, 1.2).translate((-0.2, 0.0, 0.6)).color((0.95, 0.8, 0.2)),
    k=0.25)


OUT = Path(__file__).with_name("color_blend.png")


def main(path: Path = OUT) -> None:
    csdf.render(MODEL, auto_camera(MODEL, 480, 360)).save(path)
    print(path)


if __name__ == "__main__":
    main()
