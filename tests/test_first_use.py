"""What a new user meets first (issue 15, "First use"): ``csdf.zoo`` after ``import
csdf``, the lazily loaded public names, the word about kernel compilation in the
mesher's progress display, and the one-line message when matplotlib is missing.

The import-time targets themselves are measured (``benchmarks/STARTUP_NOTES.md``), not
tested; what is tested is that ``import csdf`` leaves the heavy modules unloaded.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import csdf
from csdf.field import numba_available

ROOT = Path(__file__).resolve().parents[1]


def _python(code: str, env: dict[str, str] | None = None, timeout: float = 300
            ) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter (so that nothing is imported yet)."""
    full = dict(os.environ)
    full.update(env or {})
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=full, timeout=timeout, cwd=ROOT)


# ------------------------------------------------------------------ item 1: namespace
def test_zoo_after_import_csdf():
    r = _python("import csdf\n"
                "shape = csdf.zoo.load('chair')\n"
                "print(type(shape).__name__, 'chair' in csdf.zoo.names())")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["Shape", "True"]


def test_import_csdf_leaves_heavy_modules_unloaded():
    heavy = ["numba", "scipy", "trimesh", "matplotlib", "lark", "rich", "typer",
             "csdf.fit", "csdf.mesh", "csdf.io", "csdf.render", "csdf.backends.fast"]
    r = _python("import sys, json, csdf\n"
                f"print(json.dumps([m for m in {heavy!r} if m in sys.modules]))")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == []


def test_every_public_name_resolves():
    for name in [*csdf.__all__, "slice", "zoo"]:
        assert getattr(csdf, name) is not None, name
    assert set(csdf.__all__) <= set(dir(csdf))
    with pytest.raises(AttributeError):
        csdf.no_such_name  # noqa: B018


def test_from_csdf_import_and_star_in_a_fresh_process():
    r = _python("from csdf import mesh, fit, render, scan, zoo, Field, slice, load\n"
                "import csdf.mesh.api, csdf.fit.api, csdf.render, csdf.scan, csdf.zoo\n"
                "import csdf\n"
                "print(all(callable(f) for f in (csdf.mesh, csdf.fit, csdf.render,"
                " csdf.scan, mesh, fit, render, scan, slice, load)),"
                " csdf.mesh is mesh, csdf.zoo is zoo, csdf.Field is Field)\n"
                "ns = {}\n"
                "exec('from csdf import *', ns)\n"
                "print(sorted(set(csdf.__all__) - set(ns)))")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].split() == ["True"] * 4
    assert lines[1] == "[]"


def test_submodules_as_attributes_after_import_csdf():
    r = _python("import csdf\n"
                "print(csdf.Field.__module__ == 'csdf.field' and callable(csdf.field),"
                " callable(csdf.backends.select),"
                " csdf.lang.loads is csdf.loads, csdf.sample.sample_surface is"
                " csdf.sample_surface)\n"
                "try:\n"
                "    csdf.no_such_module\n"
                "except AttributeError:\n"
                "    print('AttributeError')")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["True"] * 4 + ["AttributeError"]


def test_function_names_survive_a_later_subpackage_import():
    # the subpackage imported first (as the CLI does), the public name read afterwards:
    # csdf.mesh is still the function, not the package
    r = _python("import csdf.mesh.api, csdf.fit, csdf.render, csdf.scan, csdf.field, csdf\n"
                "print(csdf.mesh.__module__, csdf.fit.__module__, csdf.render.__module__,"
                " csdf.scan.__module__, csdf.field.__module__)")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["csdf.mesh.api", "csdf.fit.api", "csdf.render.image",
                                "csdf.scan", "csdf.shapes.userfield"]
    for name in ("mesh", "fit", "render", "scan", "field"):
        assert callable(getattr(csdf, name))


# ------------------------------------------------------------ item 2: first-use notice
_MESH = ("import csdf\n"
         "m = csdf.mesh(csdf.sphere(0.7) | csdf.box(0.5).translate((0.9, 0, 0)),"
         " resolution=10)\n"
         "print(len(m.faces))")


def test_progress_says_kernels_are_compiling_then_cached(tmp_path):
    if not numba_available():
        pytest.skip("no Numba: nothing is compiled")
    cache = tmp_path / "kernels"
    env = {"CSDF_CACHE_DIR": str(cache)}
    cold = _python(_MESH, env)
    assert cold.returncode == 0, cold.stderr
    assert int(cold.stdout.split()[-1]) > 0
    assert "compiling kernels (first use only; cached in" in cold.stderr
    assert str(cache) in cold.stderr
    assert list(cache.glob("k_*.py")) and list(cache.rglob("*.nbi"))
    warm = _python(_MESH, env)  # a second process finds every kernel on disk
    assert warm.returncode == 0, warm.stderr
    assert warm.stdout == cold.stdout
    assert "compiling kernels" not in warm.stderr


def test_no_notice_without_progress(tmp_path):
    if not numba_available():
        pytest.skip("no Numba: nothing is compiled")
    r = _python(_MESH.replace("resolution=10)", "resolution=10, progress=False)"),
                {"CSDF_CACHE_DIR": str(tmp_path / "kernels")})
    assert r.returncode == 0, r.stderr
    assert "compiling" not in r.stderr


def test_field_kernels_ready_and_cache_dir(tmp_path, monkeypatch):
    from csdf.field import kernel_cache_dir

    monkeypatch.setenv("CSDF_CACHE_DIR", str(tmp_path / "k"))
    assert kernel_cache_dir() == tmp_path / "k"
    fld = csdf.as_field(csdf.sphere(1.0), backend="numpy")
    assert fld.kernels_ready(("value", "grad"))  # nothing to compile


# ------------------------------------------------------------ item 3: matplotlib extra
_NO_MPL = "import sys\nsys.modules['matplotlib'] = None\n"


def test_slice_without_matplotlib_names_the_extra(tmp_path):
    out = tmp_path / "s.png"
    r = _python(_NO_MPL + "import csdf\n"
                "for call in (lambda: csdf.slice(csdf.sphere(1)),"
                f" lambda: csdf.save_slice(csdf.sphere(1), {str(out)!r})):\n"
                "    try:\n"
                "        call()\n"
                "    except csdf.CsdfError as exc:\n"
                "        print(exc)\n")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["csdf slice needs matplotlib: pip install 'csdf[plot]'"] * 2
    assert not out.exists()


def test_cli_slice_without_matplotlib(tmp_path):
    model = tmp_path / "m.csdf"
    model.write_text("export sphere(1)\n")
    out = tmp_path / "s.png"
    r = _python(_NO_MPL + "from csdf.cli import main\n"
                f"sys.argv = ['csdf', 'slice', {str(model)!r}, '-o', {str(out)!r}]\n"
                "main()\n")
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "pip install 'csdf[plot]'" in r.stderr
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_cli_help_and_other_commands_without_matplotlib(tmp_path):
    model = tmp_path / "m.csdf"
    model.write_text("export sphere(1)\n")
    r = _python(_NO_MPL + "from csdf.cli import main\n"
                f"sys.argv = ['csdf', 'info', {str(model)!r}]\n"
                "main()\n")
    assert r.returncode == 0, r.stderr
    assert "instructions" in r.stdout


def test_plot_extra_declared():
    import tomllib

    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    assert any(d.startswith("matplotlib") for d in extras["plot"])
