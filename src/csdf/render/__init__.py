"""Rendering: a pinhole :class:`Camera` (OpenCV frame), vectorised sphere tracing with
over-relaxation and exact normals, Lambert shading with optional soft shadows and
ambient occlusion, and PNG output. See :func:`render`."""

from __future__ import annotations

from .camera import MAX_PIXELS, MAX_SIDE, Camera
from .image import Render, auto_camera, render
from .trace import Field, TraceResult, sphere_trace

__all__ = ["Camera", "Render", "render", "auto_camera", "Field", "TraceResult", "sphere_trace",
           "MAX_SIDE", "MAX_PIXELS"]
