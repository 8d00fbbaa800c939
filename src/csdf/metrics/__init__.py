"""BOP 2019 pose-error metrics on csdf models: VSD, MSSD, MSPD, ADD, ADD-S, recall and
average recall (the definitions of ``shared/specs/bop-metrics.md``; Hodaň et al.,
"BOP Challenge 2020 on 6D Object Localization", and Hinterstoisser et al. 2012).

Conventions

* Poses are **model-to-camera**: a :class:`csdf.Pose` or a ``(4, 4)`` matrix mapping a
  model point ``x`` to the camera frame (OpenCV: x right, y down, z forward). A camera
  (:class:`csdf.Camera`) contributes its intrinsics and image size only; its own pose is
  not used.
* **Units**: every length (points, translations, depths, errors, diameters, ``delta``,
  ``tau``) is in the model's units, metres for csdf models. BOP states its thresholds in
  millimetres: VSD's ``delta`` of 15 mm is ``delta=0.015`` for a model in metres
  (:data:`VSD_DELTA_MM`). Thresholds relative to the diameter (VSD's tau, MSSD's theta,
  ADD's 10 %) carry over unchanged. MSPD is in pixels.
* **Symmetries** are rigid transforms of the model frame, ``(K, 3, 3)`` rotations or
  ``(K, 4, 4)`` transforms, the identity added when missing; :func:`symmetries` finds
  them on the model's exact field.
* **Model points** are the vertices of the model's mesh (:func:`model_points`) or any
  ``(N, 3)`` points; :func:`diameter` is their largest pairwise distance.

Functions: :func:`vsd`, :func:`mssd`, :func:`mspd`, :func:`add`, :func:`adds`,
:func:`recall`, :func:`average_recall`, :func:`bop_average_recall`, :func:`auc`,
:func:`visible_fraction`, :func:`symmetries`, :func:`model_points`, :func:`farthest_points`,
:func:`diameter`.
"""

from __future__ import annotations

from .model import diameter, farthest_points, model_points
from .pose_error import add, adds, mspd, mssd
from .recall import (
    ADD_THRESHOLD,
    MSPD_REFERENCE_WIDTH,
    MSPD_THETAS,
    MSSD_THETAS,
    VSD_DELTA_MM,
    VSD_THETAS,
    auc,
    average_recall,
    bop_average_recall,
    recall,
)
from .symmetry import symmetries
from .visibility import VSD_TAUS, visible_fraction, vsd

__all__ = [
    "vsd", "mssd", "mspd", "add", "adds", "recall", "average_recall",
    "bop_average_recall", "auc", "visible_fraction", "symmetries", "model_points",
    "farthest_points",
    "diameter", "VSD_TAUS", "VSD_THETAS", "MSSD_THETAS", "MSPD_THETAS",
    "MSPD_REFERENCE_WIDTH", "VSD_DELTA_MM", "ADD_THRESHOLD",
]
