"""The live editor: ``csdf edit [MODEL.csdf]``.

A small local web application (Starlette + Uvicorn, bound to 127.0.0.1) that serves one
page: the model's text in a CodeMirror 6 editor, a WebGL2 canvas sphere-tracing the GLSL
the compiler generates (:func:`csdf.backends.glsl.to_glsl`), one slider per parameter
(a uniform, never a recompile), inline parse errors, an info panel, and buttons to save,
export a mesh and export the Shadertoy shader. See :mod:`csdf.editor.server`.
"""

from __future__ import annotations

from .server import MAX_BODY_BYTES, MAX_EXPORT_RESOLUTION, create_app, serve

__all__ = ["create_app", "serve", "MAX_BODY_BYTES", "MAX_EXPORT_RESOLUTION"]
