"""Helpers for the GLSL tests: ``glslangValidator`` and a headless WebGL2 page.

:class:`WebGL2Runner` opens one headless Chromium page (Playwright, Debian's
``/usr/bin/chromium``; WebGL2 on the SwiftShader software rasteriser) and runs batches
of fragment shaders in it: each job draws one full-screen triangle into ``W x H``
RGBA32F colour attachments (``EXT_color_buffer_float``) with an optional RGBA32F input
texture ``csdf_points``, sets float/vec3 uniforms per run, and reads the attachments
back as float32. Nothing is served: the page is ``set_content`` with no network.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

CHROMIUM = os.environ.get("CSDF_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
    # WebGL on the software rasteriser (newer Chromium builds ask for this explicitly)
    "--enable-unsafe-swiftshader",
]

ES_PRELUDE = "#version 300 es\nprecision highp float;\nprecision highp int;\n"


# ---------------------------------------------------------------------------- glslang
def glslang() -> str | None:
    """Path of ``glslangValidator`` (None when not installed)."""
    return shutil.which("glslangValidator")


def validate(source: str, stage: str = "frag") -> tuple[bool, str]:
    """Compile ``source`` with glslangValidator as a ``stage`` shader: (ok, log)."""
    exe = glslang()
    if exe is None:
        raise RuntimeError("glslangValidator is not installed")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"shader.{stage}"
        path.write_text(source)
        res = subprocess.run([exe, str(path)], capture_output=True, text=True, timeout=60)
    return res.returncode == 0, res.stdout + res.stderr


# ---------------------------------------------------------------------------- WebGL2
_HARNESS = r"""
(jobs) => {
  const canvas = document.createElement('canvas');
  const gl = canvas.getContext('webgl2', {antialias: false});
  if (!gl) return {fatal: 'no WebGL2 context'};
  if (!gl.getExtension('EXT_color_buffer_float')) return {fatal: 'no EXT_color_buffer_float'};
  const dbg = gl.getExtension('WEBGL_debug_renderer_info');
  const renderer = gl.getParameter(dbg ? dbg.UNMASKED_RENDERER_WEBGL : gl.RENDERER);
  const vsSrc = '#version 300 es\nvoid main() {\n' +
    '  vec2 v = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));\n' +
    '  gl_Position = vec4(v * 2.0 - 1.0, 0.0, 1.0);\n}\n';
  const vs = gl.createShader(gl.VERTEX_SHADER);
  gl.shaderSource(vs, vsSrc);
  gl.compileShader(vs);
  // compile every fragment shader first (the driver may compile in parallel)
  const progs = jobs.map((job) => {
    const fs = gl.createShader(gl.FRAGMENT_SHADER);
    gl.shaderSource(fs, job.frag);
    gl.compileShader(fs);
    const p = gl.createProgram();
    gl.attachShader(p, vs);
    gl.attachShader(p, fs);
    gl.linkProgram(p);
    return [p, fs];
  });
  const results = [];
  for (let j = 0; j < jobs.length; j++) {
    const job = jobs[j];
    const [prog, fs] = progs[j];
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) {
      results.push({error: (gl.getShaderInfoLog(fs) || '') + (gl.getProgramInfoLog(prog) || '')});
      continue;
    }
    const W = job.width, H = job.height, K = job.outputs;
    gl.useProgram(prog);
    let tex = null;
    if (job.points) {
      tex = gl.createTexture();
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, tex);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, W, H, 0, gl.RGBA, gl.FLOAT,
                    new Float32Array(job.points));
      gl.uniform1i(gl.getUniformLocation(prog, 'csdf_points'), 0);
    }
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    const targets = [];
    const bufs = [];
    for (let k = 0; k < K; k++) {
      const t = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, W, H);
      gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0 + k, gl.TEXTURE_2D, t, 0);
      targets.push(t);
      bufs.push(gl.COLOR_ATTACHMENT0 + k);
    }
    if (tex) { gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, tex); }
    gl.drawBuffers(bufs);
    const status = gl.checkFramebufferStatus(gl.FRAMEBUFFER);
    if (status !== gl.FRAMEBUFFER_COMPLETE) {
      results.push({error: 'framebuffer incomplete: ' + status});
      continue;
    }
    gl.viewport(0, 0, W, H);
    const runs = [];
    for (const run of job.runs) {
      const missing = [];
      for (const [name, value] of Object.entries(run.uniforms || {})) {
        const loc = gl.getUniformLocation(prog, name);
        if (loc === null) { missing.push(name); continue; }
        if (Array.isArray(value)) gl.uniform3f(loc, value[0], value[1], value[2]);
        else gl.uniform1f(loc, value);
      }
      gl.drawArrays(gl.TRIANGLES, 0, 3);
      const outs = [];
      for (let k = 0; k < K; k++) {
        gl.readBuffer(gl.COLOR_ATTACHMENT0 + k);
        const buf = new Float32Array(4 * W * H);
        gl.readPixels(0, 0, W, H, gl.RGBA, gl.FLOAT, buf);
        outs.push(Array.from(buf));
      }
      runs.push({outputs: outs, missing: missing});
    }
    const err = gl.getError();
    results.push({runs: runs, glError: err});
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    for (const t of targets) gl.deleteTexture(t);
    if (tex) gl.deleteTexture(tex);
    gl.deleteFramebuffer(fb);
  }
  return {renderer: renderer, results: results};
}
"""


class WebGLUnavailable(RuntimeError):
    """Playwright, Chromium or WebGL2 float rendering is not available."""


class WebGL2Runner:
    """One headless Chromium page that runs batches of WebGL2 fragment shaders.

    Use as a context manager; :meth:`run` takes a list of jobs (dicts):

    * ``frag``: GLSL ES 3.00 fragment shader source with ``K`` ``out vec4`` outputs at
      ``layout(location = 0..K-1)``;
    * ``width``, ``height``: the render size; ``outputs``: ``K``;
    * ``points`` (optional): ``(height * width, 4)`` float32 texels for the
      ``uniform highp sampler2D csdf_points`` (row-major, row 0 = ``gl_FragCoord.y``
      0.5);
    * ``runs``: list of ``{'uniforms': {name: float or [x, y, z]}}``.

    Returns per job ``{'error': log}`` or ``{'runs': [{'outputs': [(H*W, 4) float32,
    ...], 'missing': [uniform names not found]}]}``.
    """

    def __init__(self) -> None:
        self._pw = None
        self._browser = None
        self.page = None
        self.renderer = ""

    def __enter__(self) -> WebGL2Runner:
        try:
            from playwright.sync_api import sync_playwright
        except ImportError as e:
            raise WebGLUnavailable("the Python package 'playwright' is not installed") from e
        if not os.path.exists(CHROMIUM):
            raise WebGLUnavailable(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
        self._pw = sync_playwright().start()
        try:
            self._browser = self._pw.chromium.launch(executable_path=CHROMIUM,
                                                     args=CHROMIUM_ARGS, timeout=60_000)
            self.page = self._browser.new_page()
            self.page.set_content("<!doctype html><html><body></body></html>")
        except Exception as e:
            self.__exit__(None, None, None)
            raise WebGLUnavailable(f"could not start headless Chromium: {e}") from e
        return self

    def __exit__(self, *exc) -> None:
        if self._browser is not None:
            self._browser.close()
            self._browser = None
        if self._pw is not None:
            self._pw.stop()
            self._pw = None

    def run(self, jobs: list[dict]) -> list[dict]:
        """Run the jobs in the page (see the class docstring)."""
        payload = []
        for job in jobs:
            j = {k: v for k, v in job.items() if k != "points"}
            if job.get("points") is not None:
                pts = np.asarray(job["points"], dtype=np.float32)
                j["points"] = pts.reshape(-1).astype(np.float64).tolist()
            payload.append(j)
        res = self.page.evaluate(_HARNESS, payload)
        if "fatal" in res:
            raise WebGLUnavailable(res["fatal"])
        self.renderer = res["renderer"]
        out = []
        for job, r in zip(jobs, res["results"]):
            if "error" in r:
                out.append(r)
                continue
            n = job["width"] * job["height"]
            runs = [
                {
                    "outputs": [np.asarray(o, dtype=np.float32).reshape(n, 4)
                                for o in run["outputs"]],
                    "missing": run["missing"],
                }
                for run in r["runs"]
            ]
            out.append({"runs": runs, "glError": r["glError"]})
        return out
