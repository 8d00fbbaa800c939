"""``$CSDF_THREADS`` sets the threads csdf uses in a process (a Dask worker's share)."""

from __future__ import annotations

import os
import subprocess
import sys


def _threads(value: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "CSDF_THREADS": value}
    return subprocess.run([sys.executable, "-c", "import csdf.parallel as p; "
                           "print(p.N_THREADS)"], env=env, capture_output=True, text=True,
                          timeout=60)


def test_csdf_threads_sets_the_count():
    r = _threads("1")
    assert r.returncode == 0 and r.stdout.strip() == "1"
    r = _threads("3")
    assert r.returncode == 0 and r.stdout.strip() == "3"


def test_csdf_threads_rejects_nonsense():
    for bad in ("0", "-2", "two"):
        r = _threads(bad)
        assert r.returncode != 0 and "CSDF_THREADS must be a positive integer" in r.stderr
