"""Test configuration: Hypothesis explores freely on developer machines and replays a
fixed, derandomised set of examples in CI (CI=true), so a CI run is reproducible."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")
