"""Planning on csdf models: robots read from URDF files, as one parametric model and as
spheres on their links, and trajectory optimisation on scenes."""

from .descriptions import example_robot, example_robot_files
from .robot import Joint, Primitive, Robot, read_srdf, sphere_jacobian
from .trajectory import Check, Trajectory, check, optimize

__all__ = ["Robot", "Joint", "Primitive", "sphere_jacobian", "read_srdf", "Trajectory",
           "Check", "optimize", "check", "example_robot", "example_robot_files"]
