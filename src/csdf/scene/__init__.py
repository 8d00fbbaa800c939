"""Scenes: many posed instances of models, queried together (distance, gradient,
nearest instance, sphere clearance and collision), saved as readable text."""

from .scene import MAX_INSTANCES, Instance, Scene, SceneHits, SceneQuery

__all__ = ["Scene", "Instance", "SceneQuery", "SceneHits", "MAX_INSTANCES"]
