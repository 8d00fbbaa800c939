"""Planning on csdf models: robots read from URDF files, as one parametric model and as
spheres on their links (trajectory optimisation is to come)."""

from .robot import Joint, Primitive, Robot

__all__ = ["Robot", "Joint", "Primitive"]
