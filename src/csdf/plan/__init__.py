"""Planning on csdf models: robots read from URDF files, as one parametric model and as
spheres on their links, and trajectory optimisation on scenes."""

from .robot import Joint, Primitive, Robot, sphere_jacobian
from .trajectory import Check, Trajectory, check, optimize

__all__ = ["Robot", "Joint", "Primitive", "sphere_jacobian", "Trajectory", "Check",
           "optimize", "check"]
