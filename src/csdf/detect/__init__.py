"""Detection in point clouds (paper §4.4): primitives by an Efficient-RANSAC search
scored with csdf's exact distances (:func:`detect_primitives`), and known models in
cluttered scans (:func:`detect`), each refined by :func:`csdf.fit`.

Modules in the order of the data flow: ``neighbours`` (normals, spacing, noise, the
neighbour graph), ``surfaces`` (minimal-set hypotheses and their distances),
``solids`` (the csdf primitives detections become), ``primitives``
(:func:`detect_primitives`), ``objects`` (:func:`detect`, :func:`detections_to_scene`).
"""

from .neighbours import estimate_normals
from .objects import Detection, detect, detections_to_scene
from .primitives import PrimitiveDetection, detect_primitives

__all__ = ["detect_primitives", "PrimitiveDetection", "estimate_normals", "detect",
           "Detection", "detections_to_scene"]
