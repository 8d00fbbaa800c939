"""Evaluators of compiled programs. ``numpy_backend`` is the reference."""
