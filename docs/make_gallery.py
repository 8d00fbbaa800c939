"""``make gallery``: render every zoo model (default parameters) and a row of chair
variations into ``docs/gallery.png``."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from PIL import Image, ImageDraw

import csdf
from csdf import zoo
from csdf.render import auto_camera

TILE_W, TILE_H = 320, 240
COLS = 5
CHAIR_VARIATIONS = [
    ("chair", {}),
    ("low, wide", {"seat_height": 0.38, "seat_width": 0.6, "back_height": 0.3}),
    ("tall back", {"back_height": 0.6, "leg": 0.025}),
    ("armchair", {"arm_height": 0.25, "leg": 0.05}),
    ("bar height", {"seat_height": 0.55, "seat_depth": 0.36, "back_height": 0.35}),
]


def tile(shape, label: str, params: dict | None = None) -> Image.Image:
    cam = auto_camera(shape, TILE_W, TILE_H, fov=35.0, params=params or {})
    img = csdf.render(shape, cam, params=params, ao=True)
    im = Image.fromarray(img.color)
    ImageDraw.Draw(im).text((8, 6), label, fill=(30, 30, 30))
    return im


def main(path: Path) -> None:
    t0 = time.perf_counter()
    tiles = [tile(zoo.load(name), name) for name in zoo.names()]
    chair = zoo.load("chair")
    variations = [tile(chair, label, params) for label, params in CHAIR_VARIATIONS]
    rows = -(-len(tiles) // COLS) + 1
    sheet = Image.new("RGB", (COLS * TILE_W, rows * TILE_H), (255, 255, 255))
    for i, im in enumerate(tiles):
        sheet.paste(im, ((i % COLS) * TILE_W, (i // COLS) * TILE_H))
    for i, im in enumerate(variations):
        sheet.paste(im, (i * TILE_W, (rows - 1) * TILE_H))
    with csdf.io.atomic_path(path) as tmp:
        sheet.save(tmp, format="PNG")
    print(f"wrote {path}: {len(tiles)} models and {len(variations)} chair variations, "
          f"{time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent / "gallery.png")
