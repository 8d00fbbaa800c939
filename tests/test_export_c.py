"""Models exported as C and as NumPy modules (issue 23): every shape of the conformance
catalogue as one C translation unit compiled by the system compiler (``cc``, strict
warnings), and as a NumPy module, compared with csdf's evaluators: values, gradients
and parameter derivatives in double, values in float."""

from __future__ import annotations

import ctypes
import importlib.util
import os
import shutil
import subprocess

import numpy as np
import pytest
from typer.testing import CliRunner

import csdf
from catalogue import catalogue, sample_box
from csdf.cli import app

RNG = np.random.default_rng(5)
N = 200


def _cases():
    out = []
    for i, (name, make) in enumerate(sorted(catalogue(mesh_calls=False).items())):
        prog = csdf.compile(make())
        lo, hi = sample_box(prog)
        pts = RNG.uniform(lo, hi, (N, 3)) if len(lo) == 3 else np.c_[
            RNG.uniform(lo, hi, (N, 2)), np.zeros(N)]
        out.append((f"m{i}", name, prog, np.ascontiguousarray(pts)))
    return out


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    cc = shutil.which("cc")
    if cc is None:
        if os.environ.get("CSDF_REQUIRE_TOOLS") == "1":
            pytest.fail("CSDF_REQUIRE_TOOLS=1 but there is no C compiler (cc)")
        pytest.skip("needs a C compiler (cc)")
    d = tmp_path_factory.mktemp("c_export")
    cases = _cases()
    unit = []
    for cname, _, prog, _ in cases:
        (d / f"{cname}.h").write_text(csdf.to_c(prog, cname))
        P = len(prog.params)
        unit += [f'#include "{cname}.h"',
                 f"void {cname}_run(int n, const double *p, const double *prm, double *v, "
                 f"double *g, double *dp, float *vf) {{",
                 f"  {cname}_params q = {cname}_defaults;",
                 f"  if ({P}) memcpy(&q, prm, sizeof(double) * {P});",
                 "  for (int i = 0; i < n; ++i) {",
                 f"    v[i] = {cname}_all(p + 3 * i, &q, g + 3 * i, dp + {max(P, 1)} * i);",
                 "    float pf[3] = {(float)p[3 * i], (float)p[3 * i + 1], (float)p[3 * i + 2]};",
                 f"    vf[i] = {cname}_f(pf, &q);",
                 "  }", "}"]
    (d / "unit.c").write_text("#include <string.h>\n" + "\n".join(unit) + "\n")
    lib = d / "unit.so"
    r = subprocess.run([cc, "-O1", "-std=c99", "-Wall", "-Wextra", "-Werror", "-shared",
                        "-fPIC", "-o", str(lib), str(d / "unit.c"), "-lm"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return ctypes.CDLL(str(lib)), cases


def test_c_matches_the_evaluators_for_the_whole_catalogue(compiled):
    lib, cases = compiled
    dbl = ctypes.POINTER(ctypes.c_double)
    flt = ctypes.POINTER(ctypes.c_float)
    for cname, name, prog, pts in cases:
        P = len(prog.params)
        pv = np.array([p.default for p in prog.params] or [0.0])
        v, g = np.empty(N), np.empty((N, 3))
        dp, vf = np.empty((N, max(P, 1))), np.empty(N, np.float32)
        getattr(lib, f"{cname}_run")(N, pts.ctypes.data_as(dbl), pv.ctypes.data_as(dbl),
                                    v.ctypes.data_as(dbl), g.ctypes.data_as(dbl),
                                    dp.ctypes.data_as(dbl), vf.ctypes.data_as(flt))
        q = pts if prog.dim == 3 else pts[:, :2]
        ref = prog(q)
        fin = np.isfinite(ref)
        scale = max(1.0, float(np.abs(ref[fin]).max(initial=0.0)))
        assert np.array_equal(np.isfinite(v), fin), name
        assert np.allclose(v[fin], ref[fin], rtol=0, atol=1e-12 * scale), name
        rg = np.asarray(prog.gradient(q))
        if prog.dim == 2:
            g = g[:, :2]
        ok = fin & np.all(np.isfinite(rg), axis=1)
        assert np.allclose(g[ok], rg[ok], rtol=1e-9, atol=1e-9), name
        if P:
            rj = np.asarray(prog.param_jacobian(q))
            okj = fin & np.all(np.isfinite(rj), axis=1)
            assert np.allclose(dp[okj], rj[okj], rtol=1e-9, atol=1e-9), name
        assert np.allclose(vf[fin], ref[fin], rtol=1e-4, atol=1e-5 * scale), name


def test_numpy_module_matches_the_evaluators(tmp_path):
    for i, (cname, name, prog, pts) in enumerate(_cases()):
        if i % 3:  # a third of the catalogue keeps this quick; C covers all of it
            continue
        path = tmp_path / f"{cname}.py"
        path.write_text(csdf.to_numpy(prog, cname))
        spec = importlib.util.spec_from_file_location(cname, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        q = pts if prog.dim == 3 else pts[:, :2]
        ref = prog(q)
        v, g = mod.value_and_grad(pts)
        fin = np.isfinite(ref)
        assert np.allclose(mod.value(pts)[fin], ref[fin], rtol=0, atol=1e-12), name
        assert np.allclose(v[fin], ref[fin], rtol=0, atol=1e-12), name
        rg = np.asarray(prog.gradient(q))
        ok = fin & np.all(np.isfinite(rg), axis=1)
        assert np.allclose(g[ok][:, :prog.dim], rg[ok], rtol=1e-9, atol=1e-9), name
        if prog.params:
            p0 = prog.params[0]
            other = dict(mod.PARAMS, **{p0.name: 0.5 * (p0.default + (p0.hi if np.isfinite(
                p0.hi) else p0.default))})
            assert np.allclose(mod.value(pts, **other)[fin],
                               prog(q, **other)[fin], atol=1e-12), name
            with pytest.raises(ValueError, match="unknown"):
                mod.value(pts, no_such_parameter=1.0)


def test_cli_export_c_and_numpy(tmp_path):
    model = tmp_path / "m.csdf"
    model.write_text("param r = 0.5 in [0.2, 1]\nexport sphere(r) - box(0.6)\n")
    out = tmp_path / "m.h"
    res = CliRunner().invoke(app, ["export", "--c", str(model), "--name", "part", "-o",
                                   str(out)])
    assert res.exit_code == 0, res.output
    text = out.read_text()
    assert "part_params" in text and "part_all_f" in text and "PART_NPARAMS 1" in text
    res = CliRunner().invoke(app, ["export", "--numpy", str(model)])
    assert res.exit_code == 0 and "def value_and_grad" in res.output
    for bad, msg in ((["--c", "--numpy"], "one export format"),
                     (["--c", "--name", "int"], "C identifier")):
        res = CliRunner().invoke(app, ["export", *bad, str(model)])
        assert res.exit_code != 0 and msg in res.output
