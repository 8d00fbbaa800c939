"""From a scan to a parametric model: ``csdf.infer`` finds csdf primitives in a point
cloud and the CSG tree that combines them (:mod:`.api`), by a beam search over trees
scored on the primitives' exact distances (:mod:`.search`, :mod:`.tree`)."""

from .api import SOLID_KINDS, InferResult, infer

__all__ = ["infer", "InferResult", "SOLID_KINDS"]
