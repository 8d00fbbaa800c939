"""Superquadric recovery (issue 23): ``csdf.fit`` of ``csdf.superquadric`` (pose and the
two shape exponents) to noisy surface samples, the task EMS (Liu et al., CVPR 2022,
probabilistic superquadric fitting) solves; EMS measured on this machine by the issue's
author: 417 ms and 0.04 degrees for 10k points.

Seeded cases: semi-axes 0.1-0.4 m, exponents e1, e2 uniform in [0.3, 1.5], a random
rotation and translation, 10k surface samples (``csdf.sample_surface``), Gaussian noise
of 0.3 % of the largest semi-axis. The fit starts from the cloud's centroid and
principal axes (the PCA frame; a superquadric's axes are its principal axes) with
exponents 1, 1, and estimates pose and exponents (semi-axes known, as in the issue's
comparison of exponents and pose); when that fit fails its own quality test
(``FitResult.success``: near-equal semi-axes leave the axes' order to the noise) the
other five assignments of the principal axes to the semi-axes are fitted too, and the
time counts them all. The rotation error is the smallest over the
superquadric's symmetries (half turns about its axes). Time: the median over cases of
the fit's wall time after one warm-up fit (kernels compiled).

Run: ``python benchmarks/bench_superquadric.py [--cases 20]``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

import csdf

_FLIPS = [np.diag(d) for d in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1))]


def _random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _rot_err(R_est: np.ndarray, R_true: np.ndarray) -> float:
    best = math.inf
    for F in _FLIPS:
        d = (R_est @ F).T @ R_true
        best = min(best, math.degrees(math.acos(np.clip((np.trace(d) - 1) / 2, -1, 1))))
    return best


def _pca_starts(Q: np.ndarray, radii: np.ndarray) -> list[dict]:
    """Starts from the principal axes: the axes matched to the radii by spread first,
    then the other five assignments (near-equal radii leave the order to the noise)."""
    import itertools

    c = Q.mean(axis=0)
    w, v = np.linalg.eigh(np.cov((Q - c).T))
    axes = v[:, np.argsort(-w)]  # largest spread first
    by_size = list(np.argsort(-radii))
    perms = [by_size] + [list(p) for p in itertools.permutations(range(3))
                         if list(p) != by_size]
    out = []
    for perm in perms:
        R = np.empty((3, 3))
        R[:, perm] = axes
        if np.linalg.det(R) < 0:
            R[:, 2] *= -1
        out.append({"rotation": R, "translation": c, "params": {"e1": 1.0, "e2": 1.0}})
    return out


def _fit(shape, Q: np.ndarray, radii: np.ndarray, f_scale: float, seed: int):
    """The PCA start's fit; when it fails its quality test, the best of the other axis
    assignments' fits (successful first, then the lowest cost)."""
    starts = _pca_starts(Q, radii)
    fits = []
    for init in starts:
        r = csdf.fit(shape, Q, init=init, estimate=("pose", "params"), f_scale=f_scale,
                     seed=seed)
        if r.success:
            return r
        fits.append(r)
    return min(fits, key=lambda r: r.cost)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=20)
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--verbose", action="store_true", help="print the cases not recovered")
    a = ap.parse_args()
    e1 = csdf.param("e1", 1.0, 0.1, 2.0)
    e2 = csdf.param("e2", 1.0, 0.1, 2.0)
    rng = np.random.default_rng(0)
    times, rot, expo, ok = [], [], [], 0
    for k in range(a.cases + 1):
        radii = np.sort(rng.uniform(0.1, 0.4, 3))[::-1][rng.permutation(3)]
        shape = csdf.superquadric(tuple(radii), e1, e2)
        truth = {"e1": float(rng.uniform(0.3, 1.5)), "e2": float(rng.uniform(0.3, 1.5))}
        P = csdf.sample_surface(shape, a.points, params=truth, seed=k)[0]
        R = _random_rotation(rng)
        t = rng.uniform(-0.5, 0.5, 3)
        Q = P @ R.T + t + rng.normal(0, 0.003 * radii.max(), P.shape)
        t0 = time.perf_counter()
        r = _fit(shape, Q, radii, 0.003 * radii.max(), k)
        dt = time.perf_counter() - t0
        if k == 0:
            continue  # the warm-up (compiles the kernels)
        times.append(dt)
        rot.append(_rot_err(r.rotation, R))
        expo.append(max(abs(r.params["e1"] - truth["e1"]), abs(r.params["e2"] - truth["e2"])))
        ok += rot[-1] < 1.0 and expo[-1] < 0.05
        if a.verbose and not (rot[-1] < 1.0 and expo[-1] < 0.05):
            print(f"case {k}: radii {np.round(radii, 3)} truth {truth} got {r.params} "
                  f"rotation error {rot[-1]:.1f} deg, success {r.success}")
    print(f"{a.cases} cases, {a.points} points each, noise 0.3 % of the largest semi-axis")
    print("| method | median ms (max) | median rotation error (deg) | median exponent error | "
          "recovered (< 1 deg, < 0.05) |")
    print("|---|---|---|---|---|")
    print(f"| csdf.fit (pose + e1, e2; PCA starts) | {1000 * statistics.median(times):.0f} "
          f"({1000 * max(times):.0f}) | "
          f"{statistics.median(rot):.3f} | {statistics.median(expo):.4f} | {ok}/{a.cases} |")
    print("| EMS (the issue's measurement on this machine) | 417 | 0.04 | - | - |")


if __name__ == "__main__":
    main()
