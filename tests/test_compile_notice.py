"""The command line's word about kernel compilation: ``csdf render``, ``scan``,
``slice`` and ``fit`` print "csdf: compiling kernels (first use only; cached in DIR)"
on stderr, as the mesher does, when the compiled kernels they will use are not built
yet, and say nothing once they are (cached on disk, ``$CSDF_CACHE_DIR``).

Each first run compiles (seconds to tens of seconds on a small machine), so the runs
are arranged to compile as little as possible (a command after another that built some
of its kernels compiles only the rest). The whole file is one test of a few processes;
it is skipped without Numba (nothing is compiled then).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from csdf.field import numba_available

ROOT = Path(__file__).resolve().parents[1]
NOTICE = "csdf: compiling kernels (first use only; cached in"
MODEL = "param r = 1.0 in [0.5, 2]\nexport sphere(r) | box(0.8).translate((0.9, 0, 0))\n"

pytestmark = pytest.mark.skipif(not numba_available(), reason="no Numba: nothing compiles")


def _csdf(args: list[str], cache: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, CSDF_CACHE_DIR=str(cache))
    r = subprocess.run([sys.executable, "-m", "csdf.cli", *args], capture_output=True,
                       text=True, cwd=ROOT, env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    return r


def _says_compiling(r: subprocess.CompletedProcess, cache: Path) -> bool:
    lines = [ln for ln in r.stderr.splitlines() if NOTICE in ln]
    assert len(lines) <= 1, r.stderr  # one line at most
    if lines:
        assert str(cache) in r.stderr.replace("\n", ""), r.stderr
    return bool(lines)


def test_first_run_says_compiling_then_not(tmp_path):
    pytest.importorskip("matplotlib")
    model = tmp_path / "part.csdf"
    model.write_text(MODEL)
    cloud = tmp_path / "scan.ply"
    a, b = tmp_path / "cache_a", tmp_path / "cache_b"

    # cache A: render compiles (values and gradients); scan then finds them on disk
    r = _csdf(["render", str(model), "-o", str(tmp_path / "r.png"), "--size", "32x24"], a)
    assert _says_compiling(r, a)
    r = _csdf(["scan", str(model), "-o", str(cloud), "--size", "128x96", "--seed", "1"], a)
    assert not _says_compiling(r, a)

    # cache B: slice needs only values; fit with parameters then lacks the others; a
    # second fit, and slice again, find everything on disk
    r = _csdf(["slice", str(model), "-o", str(tmp_path / "s.png"), "-r", "16"], b)
    assert _says_compiling(r, b)
    fit = ["fit", str(model), str(cloud), "-o", str(tmp_path / "f.json"), "--estimate",
           "pose,params", "--no-escape"]
    r = _csdf(fit, b)
    assert _says_compiling(r, b)
    r = _csdf(fit, b)
    assert not _says_compiling(r, b)
    r = _csdf(["slice", str(model), "-o", str(tmp_path / "s2.png"), "-r", "16"], b)
    assert not _says_compiling(r, b)
