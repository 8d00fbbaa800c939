"""A picture of detections: the scan's points seen from the sensor, each detection's
model drawn over them in its own colour (surface samples of the posed model that face
the sensor), with its name. For ``csdf detect --picture``."""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import MeshWarning

__all__ = ["detections_picture", "PICTURE_SAMPLES", "PICTURE_RESOLUTION"]

#: surface samples drawn per detection
PICTURE_SAMPLES = 4000
#: voxels along a detection's longest side where it is meshed for its samples: fine
#: enough to keep a lamp's thinnest shade wall (1.5 mm), which the default for 4,000
#: samples lost
PICTURE_RESOLUTION = 128


def _project(P: np.ndarray, vp: np.ndarray | None, target: np.ndarray | None = None
             ) -> np.ndarray:
    """2D image coordinates ``(N, 2)`` of points ``P`` ``(N, 3)``.

    * A camera-frame cloud (every point in front of ``vp`` along +z, the convention of
      :func:`csdf.scan` without ``--world``: x right, y down): a pinhole at ``vp``.
    * A world-frame cloud with a viewpoint: a pinhole at ``vp`` looking at ``target``
      (``(3,)``, the scan's median point), with +z up in the picture (the zoo's up)
      unless the view is along z, where +y is up.
    * No viewpoint: an orthographic view down -z.
    """
    if vp is None:
        return P[:, :2].copy()
    z = P[:, 2] - vp[2]
    if target is None and len(P) and np.all(z > 1e-9):
        return np.stack([(P[:, 0] - vp[0]) / z, -(P[:, 1] - vp[1]) / z], axis=1)
    look = (np.zeros(3) if target is None else target) - vp
    n = np.linalg.norm(look)
    if n < 1e-12:
        return P[:, :2].copy()
    f = look / n
    up = np.array([0.0, 0.0, 1.0]) if abs(f[2]) < 0.95 else np.array([0.0, 1.0, 0.0])
    right = np.cross(f, up)
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    d = P - vp
    depth = np.maximum(d @ f, 1e-9)  # points behind the sensor pile up at its edge
    return np.stack([(d @ right) / depth, -(d @ down) / depth], axis=1)


def _samples(d, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``PICTURE_SAMPLES`` surface samples of the detection ``d``'s posed model and their
    normals, ``(n, 3)`` each (scan frame), from its mesh at ``PICTURE_RESOLUTION``."""
    from ..sample import sample_surface

    with warnings.catch_warnings():
        # a part thinner still is left out of the picture, not worth a warning
        warnings.simplefilter("ignore", MeshWarning)
        S, N = sample_surface(d.shape, PICTURE_SAMPLES, seed=seed, params=d.params,
                              resolution=PICTURE_RESOLUTION, check_ranges=False)
    return d.pose.apply(S), d.pose.apply_dirs(N)


def detections_picture(points, detections, viewpoint=None, size: tuple[int, int] = (960, 720)
                       ) -> np.ndarray:
    """An RGB image ``(H, W, 3)`` uint8 of the scan ``points`` ``(N, 3)`` (grey; the
    points a detection explains in its colour) and each :class:`Detection`'s posed model
    (surface samples facing ``viewpoint``, ``(3,)`` or None) with its name."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P = np.asarray(points, dtype=float)
    vp = None if viewpoint is None else np.asarray(viewpoint, dtype=float)
    w, h = size
    fig = plt.figure(figsize=(w / 100, h / 100), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_facecolor("white")
    target = None
    if vp is not None and len(P) and not np.all(P[:, 2] - vp[2] > 1e-9):
        target = np.median(P, axis=0)  # a world-frame cloud: look at its middle
    uv = _project(P, vp, target)
    ax.scatter(uv[:, 0], uv[:, 1], s=0.6, c="0.7", linewidths=0)
    colours = plt.get_cmap("tab10")
    for k, d in enumerate(detections):
        col = colours(k % 10)
        if len(d.inliers):
            q = _project(P[d.inliers], vp, target)
            ax.scatter(q[:, 0], q[:, 1], s=0.8, color=col, alpha=0.35, linewidths=0)
        S, N = _samples(d, k)
        if vp is not None:
            S = S[np.einsum("ij,ij->i", N, vp - S) > 0]
        if not len(S):
            continue
        q = _project(S, vp, target)
        ax.scatter(q[:, 0], q[:, 1], s=1.2, color=col, linewidths=0)
        top = q[np.argmax(q[:, 1])]
        ax.text(top[0], top[1], f" {d.model} {d.score:.2f}", color=col, fontsize=11,
                va="bottom", ha="center", weight="bold")
    ax.set_aspect("equal")
    ax.axis("off")
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return img
