"""Recovering pose, scale and shape from point clouds (``solve.py``), with a global
initialisation (``init.py``) and the ICP baseline (``icp.py``)."""

from .icp import icp
from .solve import FitResult, fit

__all__ = ["fit", "icp", "FitResult"]
