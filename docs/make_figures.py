"""Make the README's figures: ``python docs/make_figures.py`` (needs the ``docs`` extra)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

import csdf  # noqa: E402

HERE = Path(__file__).parent


def csg_example() -> csdf.Shape:
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


def _draw(ax, mesh, title: str) -> None:
    tris = mesh.vertices[mesh.faces]
    n = mesh.face_normals
    light = np.array([0.4, -0.5, 0.8])
    shade = 0.25 + 0.75 * np.clip(n @ (light / np.linalg.norm(light)), 0, 1)
    colors = np.stack([0.35 * shade, 0.55 * shade, 0.85 * shade, np.ones_like(shade)], axis=1)
    ax.add_collection3d(Poly3DCollection(tris, facecolors=colors, edgecolors=(0, 0, 0, 0.15),
                                         linewidths=0.2))
    ax.set_xlim(-0.8, 0.8)
    ax.set_ylim(-0.8, 0.8)
    ax.set_zlim(-0.8, 0.8)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=28, azim=-52)
    ax.set_axis_off()
    ax.set_title(title, fontsize=11)


def meshing_figure(path: Path) -> None:
    shape = csg_example()
    fig = plt.figure(figsize=(10, 5), dpi=110)
    for i, method in enumerate(("mc", "dc")):
        m = csdf.mesh(shape, resolution=24, method=method, progress=False)
        name = "marching cubes" if method == "mc" else "dual contouring (exact-gradient QEF)"
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        _draw(ax, m, f"{name}\n{len(m.faces):,} triangles, watertight, genus 5")
    fig.suptitle("(sphere(1) & box(1.5)) - three cylinders, 24 voxels across", fontsize=12)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    meshing_figure(HERE / "meshing.png")
    print("wrote", HERE / "meshing.png")
