"""``csdf mesh`` stops promptly on SIGINT and SIGTERM (issue 15): exit status 130 / 143,
no output and no temporary file left beside the target."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self") or os.name != "posix",
                                reason="needs POSIX signals and /proc")

MODEL = "export sphere(1) | box((0.5, 2, 0.5)).translate((1, 0, 0))\n"
# a mesh that takes many seconds (tens of millions of triangles), so the signal lands
# while the mesher (or the writer) is at work
RESOLUTION = "2400"
START_S = 6.0  # seconds to wait for the command's signal handlers


def _caught(pid: int, sig: int) -> bool:
    """The process has a handler installed for ``sig`` (from /proc/PID/status)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    for line in text.splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    return False


def _start(args: list[str], cwd: Path, ignore_sigint: bool = False) -> subprocess.Popen:
    # signals at their defaults in the child, whatever this test runner inherited; or
    # SIGINT ignored, as a shell starts a background job (``csdf mesh ... &``), where an
    # explicit ``kill -INT`` must still stop it
    def defaults() -> None:
        signal.signal(signal.SIGINT, signal.SIG_IGN if ignore_sigint else signal.SIG_DFL)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)

    return subprocess.Popen(args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=defaults)


def _wait_until_running(proc: subprocess.Popen, settle: float) -> None:
    """Until the command has installed its handlers (SIGTERM caught; at most
    :data:`START_S`, for a command that installs none), then ``settle`` seconds more, so
    that it is meshing."""
    deadline = time.monotonic() + START_S
    while not _caught(proc.pid, signal.SIGTERM) and time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    time.sleep(settle)
    assert proc.poll() is None, "the mesh finished before the signal; make it larger"


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    """The model, meshed once small first, so that the compiled kernels are in the
    on-disk cache and the signal does not land in a first-use compilation."""
    path = tmp_path_factory.mktemp("model") / "m.csdf"
    path.write_text(MODEL)
    subprocess.run([sys.executable, "-m", "csdf.cli", "mesh", str(path), "-o",
                    str(path.with_suffix(".stl")), "-r", "16", "-q"], check=True,
                   capture_output=True, timeout=600)
    return path


@pytest.mark.parametrize("sig, status, ignore_sigint", [
    (signal.SIGINT, 130, False), (signal.SIGINT, 130, True), (signal.SIGTERM, 143, False)])
def test_mesh_stops_promptly_and_cleans_up(tmp_path, model, sig, status, ignore_sigint):
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    target = out_dir / "big.stl"
    proc = _start([sys.executable, "-m", "csdf.cli", "mesh", str(model), "-o", str(target),
                   "-r", RESOLUTION, "-q"], tmp_path, ignore_sigint)
    try:
        _wait_until_running(proc, 1.5)
        t0 = time.monotonic()
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=30)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == status, stderr.decode(errors="replace")
    assert took < 10.0, f"took {took:.1f} s to stop"  # (0.3-3.5 s measured; CI margin)
    assert signal.Signals(sig).name in stderr.decode(), stderr
    assert list(out_dir.iterdir()) == []  # neither the mesh nor a temporary file


def _run_go(go_body: str, cwd: Path) -> tuple[subprocess.Popen, str, float]:
    """Run ``def go(): <go_body>`` through the CLI's ``_run`` in a fresh process: the
    process, its stderr and the seconds it took."""
    script = textwrap.dedent("""
        import os, signal, sys, time
        import typer
        from csdf.cli import _run
        from csdf.io import atomic_path

        def go():
    """) + textwrap.indent(textwrap.dedent(go_body), "    ") + textwrap.dedent("""
        try:
            _run(go)
        except typer.Exit as exc:
            sys.exit(exc.exit_code)
    """)
    proc = _start([sys.executable, "-c", script], cwd)
    t0 = time.monotonic()
    _, stderr = proc.communicate(timeout=60)
    return proc, stderr.decode(errors="replace"), time.monotonic() - t0


def test_sigterm_during_an_atomic_write_removes_the_temporary_file(tmp_path):
    target = tmp_path / "out.bin"
    proc, stderr, _ = _run_go(f"""
        with atomic_path({str(target)!r}) as tmp:
            tmp.write_bytes(b"partial")
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(30)
    """, tmp_path)
    assert proc.returncode == 143, stderr
    assert list(tmp_path.iterdir()) == []


def test_a_swallowed_stop_that_ends_in_another_error_is_reported_as_the_stop(tmp_path):
    # trimesh's import, interrupted by SIGINT under load, swallowed the stop and then
    # failed with a TypeError of its own: the command must still stop cleanly
    proc, stderr, _ = _run_go("""
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)
        except BaseException:
            pass  # swallowed
        raise TypeError("unsupported operand type(s) for |")
    """, tmp_path)
    assert proc.returncode == 130, stderr
    assert "SIGINT" in stderr and "Traceback" not in stderr and "TypeError" not in stderr


def test_a_swallowed_stop_is_sent_again(tmp_path):
    # code that takes the stop for some other failure (trimesh imports its optional
    # packages under ``except BaseException``) must not keep the command running
    proc, stderr, took = _run_go("""
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)
        except BaseException:
            pass  # swallowed
        time.sleep(60)
    """, tmp_path)
    assert proc.returncode == 143, stderr
    assert "SIGTERM" in stderr
    assert took < 30.0  # (the resend is after 1 s; 60 s without it)
