"""The live editor in a real browser: Playwright driving Debian's Chromium headless
(WebGL2 on the SwiftShader software rasteriser), against the editor's server run by
Uvicorn on 127.0.0.1 in a thread of the test.

* the page loads a zoo model and the preview is not blank: its silhouette matches a CPU
  render (:func:`csdf.render.render`) of the same camera;
* typing a change updates the preview; moving a slider changes the image without a
  shader recompile or a server round trip;
* a syntax error shows its line and column, and the last good preview stays;
* Save writes the file; Export STL returns a watertight mesh.

Skipped, with the reason, where Playwright or Chromium is absent; CI sets
``CSDF_REQUIRE_TOOLS=1`` and then they fail instead.
"""

from __future__ import annotations

import base64
import io
import os
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from PIL import Image

import csdf
from csdf import zoo
from glsl_runner import CHROMIUM, CHROMIUM_ARGS

REQUIRE_TOOLS = os.environ.get("CSDF_REQUIRE_TOOLS") == "1"
SIZE = 256
MODEL = "chair"
TIMEOUT_MS = 60_000


def _unavailable(why: str):
    if REQUIRE_TOOLS:
        pytest.fail(f"CSDF_REQUIRE_TOOLS=1 but the browser tests cannot run: {why}")
    pytest.skip(f"editor browser tests skipped: {why}")


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _unavailable("the Python package 'playwright' is not installed")
    if not os.path.exists(CHROMIUM):
        _unavailable(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    pw = sync_playwright().start()
    try:
        try:
            b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS,
                                   timeout=TIMEOUT_MS)
        except Exception as e:  # noqa: BLE001 - any launch failure means "no browser"
            _unavailable(f"could not start headless Chromium: {e}")
        yield b
        b.close()
    finally:
        pw.stop()


class _Server:
    """The editor's app under Uvicorn on 127.0.0.1 in a daemon thread."""

    def __init__(self, model_path) -> None:
        import uvicorn

        from csdf.editor.server import create_app, free_port

        self.port = free_port()
        config = uvicorn.Config(create_app(model_path), host="127.0.0.1", port=self.port,
                                log_level="warning", access_log=False)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                self.stop()
                raise RuntimeError("the editor server did not start")
            time.sleep(0.02)
        self.url = f"http://127.0.0.1:{self.port}/"

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)


@pytest.fixture
def model_file(tmp_path):
    p = tmp_path / f"{MODEL}.csdf"
    p.write_text(zoo.source(MODEL))
    return p


@pytest.fixture
def page(browser, model_file) -> Iterator:
    """A page of the editor on a fresh server, with the first preview drawn."""
    server = _Server(model_file)
    # bypass_csp: Playwright's wait_for_function evaluates strings, which the page's
    # Content-Security-Policy (script-src 'self') forbids
    context = browser.new_context(viewport={"width": 1100, "height": 760},
                                  accept_downloads=True, bypass_csp=True)
    pg = context.new_page()
    pg.set_default_timeout(TIMEOUT_MS)
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    try:
        pg.goto(f"{server.url}?canvas={SIZE}x{SIZE}")
        pg.wait_for_function("window.csdfEditor && window.csdfEditor.ready")
        yield pg
        assert not errors, errors
    finally:
        context.close()
        server.stop()


def _image(pg, mode: str = "shaded") -> np.ndarray:
    """The preview as an (H, W, 3) uint8 array (mode 'mask': the silhouette)."""
    url = pg.evaluate("(m) => window.csdfEditor.snapshot(m)", mode)
    data = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def _state(pg, key: str):
    return pg.evaluate(f"window.csdfEditor.{key}")


def _replace(pg, old: str, new: str) -> None:
    """Edit the text as the user would (a CodeMirror transaction)."""
    pg.evaluate(
        """([old, nu]) => {
            const v = window.csdfEditor.view;
            const i = v.state.doc.toString().indexOf(old);
            if (i < 0) throw new Error('text not found: ' + old);
            v.dispatch({changes: {from: i, to: i + old.length, insert: nu}});
        }""",
        [old, new],
    )


def test_preview_matches_cpu_render(page):
    from csdf.render import Camera, render

    shaded = _image(page)
    assert shaded.shape == (SIZE, SIZE, 3)
    assert shaded.std() > 10, "the preview is blank"
    mask_gpu = _image(page, "mask")[..., 0] > 127
    cam = _state(page, "camera()")
    camera = Camera.look_at(cam["eye"], cam["target"], fov=cam["fov"], width=SIZE, height=SIZE)
    r = render(zoo.load(MODEL), camera)
    inter = np.logical_and(mask_gpu, r.mask).sum()
    union = np.logical_or(mask_gpu, r.mask).sum()
    assert 0.05 < r.mask.mean() < 0.8
    assert inter / union >= 0.97, f"silhouette IoU {inter / union:.3f}"
    # exact normals: the GPU's (sdf_grad) against the CPU's where both hit
    both = mask_gpu & r.mask
    n_gpu = _image(page, "normals")[both].astype(float) / 255.0 * 2.0 - 1.0
    n_gpu /= np.linalg.norm(n_gpu, axis=1, keepdims=True)
    cos = np.sum(n_gpu * r.normals[both], axis=1)
    assert np.mean(cos > 0.99) > 0.95, f"normals agree at {np.mean(cos > 0.99):.1%} of pixels"
    # shaded pixels: the object differs from the background
    assert np.abs(shaded[r.mask].mean(0) - shaded[~r.mask].mean(0)).max() > 20
    # the info panel shows csdf info's figures
    prog = zoo.load(MODEL).compile()
    info = page.inner_text("#info")
    assert f"{len(prog)} instructions" in info and str(prog.nbytes) in info
    assert str(prog.exactness) in info


_COLOURED = {
    # a palette: each surface one colour
    "palette": ("export box(1).color((0.9, 0.15, 0.1)) - sphere(0.45).translate((0.5, 0, "
                "0.3)).color((0.1, 0.3, 0.95)) | cylinder(0.2, 1.4).translate((-0.8, 0, "
                "0)).color((0.1, 0.8, 0.2))\n"),
    # channel programs: the colours mix in the blends
    "channels": ("export union(box(1).color((0.9, 0.15, 0.1)), sphere(0.45).translate((0.6,"
                 " 0, 0.3)).color((0.1, 0.3, 0.95)), cylinder(0.2, 1.4).translate((-0.8, 0,"
                 " 0)).color((0.1, 0.8, 0.2)), k = 0.15)\n"),
}


@pytest.mark.parametrize("kind", sorted(_COLOURED))
def test_preview_draws_the_models_colours_as_the_cpu_render_does(page, kind):
    from csdf.render import Camera, render

    text = _COLOURED[kind]
    assert (csdf.loads(text).compile().colors[1] is None) == (kind == "channels")
    n = _state(page, "compileCount")
    page.evaluate("(t) => { const v = window.csdfEditor.view; v.dispatch({changes: "
                  "{from: 0, to: v.state.doc.length, insert: t}}); }", text)
    page.wait_for_function(f"window.csdfEditor.compileCount > {n}")
    assert _state(page, "lastError") is None
    gpu = _image(page).astype(int)
    mask = _image(page, "mask")[..., 0] > 127
    cam = _state(page, "camera()")
    camera = Camera.look_at(cam["eye"], cam["target"], fov=cam["fov"], width=SIZE, height=SIZE)
    cpu = render(csdf.loads(text), camera)
    both = mask & cpu.mask
    c = cpu.color[both].astype(int)
    g = gpu[both]
    # where the CPU render shows the red box, the blue cut or the green post, the
    # preview shows that colour too (the dominant channel; the lighting differs)
    for ch in range(3):
        others = [k for k in range(3) if k != ch]
        cpu_ch = (c[:, ch, None] > c[:, others] + 30).all(axis=1)
        assert cpu_ch.mean() > 0.01, ch
        gpu_ch = (g[cpu_ch, ch, None] > g[cpu_ch][:, others]).all(axis=1)
        assert gpu_ch.mean() > 0.95, (ch, gpu_ch.mean())


def test_typing_updates_the_preview(page):
    before = _image(page)
    n = _state(page, "compileCount")
    _replace(page, "let seat_t = 0.04", "let seat_t = 0.2")
    page.wait_for_function(f"window.csdfEditor.compileCount > {n}")
    after = _image(page)
    assert np.abs(after.astype(int) - before).max(-1).astype(bool).mean() > 0.005
    # real keystrokes too: a new parameter used by the model appears as a slider
    page.click(".cm-content")
    page.keyboard.press("Control+Home")
    page.keyboard.type("param extra = 0.1 in [0.05, 0.3]\n")
    page.keyboard.press("Control+End")
    page.keyboard.press("Backspace")
    page.keyboard.type(" | sphere(extra)\n")
    page.wait_for_selector("#param-u_extra")
    assert _state(page, "lastError") is None


def test_slider_changes_image_without_recompile(page):
    before = _image(page)
    compiles = _state(page, "compileCount")
    requests = _state(page, "requestCount")
    renders = _state(page, "renderCount")
    page.locator("#param-u_back_height").fill("0.6")
    page.locator("#param-u_seat_height").fill("0.55")
    page.wait_for_function(f"window.csdfEditor.renderCount > {renders}")
    after = _image(page)
    assert np.abs(after.astype(int) - before).max(-1).astype(bool).mean() > 0.005
    assert _state(page, "compileCount") == compiles
    assert _state(page, "requestCount") == requests
    assert _state(page, "params.back_height") == pytest.approx(0.6)


def test_syntax_error_shows_line_and_column(page):
    good = _image(page)
    n = _state(page, "requestCount")
    _replace(page, "let seat_t = 0.04", "let seat_t = (0.04 +")
    page.wait_for_function(f"window.csdfEditor.requestCount > {n}")
    line = zoo.source(MODEL).splitlines().index("let seat_t = 0.04                          "
                                                "# seat thickness") + 1
    err = _state(page, "lastError")
    assert err["line"] in (line, line + 1), err
    status = page.inner_text("#status")
    assert f"line {err['line']}, column {err['column']}" in status
    page.wait_for_selector(".cm-lintRange-error")
    # the last good preview stays
    assert np.array_equal(_image(page), good)


def test_save_writes_the_file(page, model_file):
    _replace(page, "let seat_t = 0.04", "let seat_t = 0.05")
    page.click("#save")
    page.wait_for_function("document.getElementById('status').textContent.startsWith('saved')")
    text = model_file.read_text()
    assert "let seat_t = 0.05" in text
    assert text == page.evaluate("window.csdfEditor.getText()")


def test_export_stl_is_watertight(page):
    import trimesh

    page.select_option("#resolution", "64")
    with page.expect_download() as dl:
        page.click("#export-stl")
    path = dl.value.path()
    assert dl.value.suggested_filename == f"{MODEL}.stl"
    m = trimesh.load(path, file_type="stl", force="mesh")
    assert m.is_watertight and m.is_winding_consistent
    # the chair at its defaults: the backrest's top at seat_height + back_height
    assert m.bounds[1][2] == pytest.approx(0.45 + 0.42, abs=0.02)


def test_camera_and_slice_plane(page):
    before = _image(page)
    eye = _state(page, "camera().eye")
    box = page.locator("#view").bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + 60, y + 20, steps=4)
    page.mouse.up()
    page.wait_for_function(f"window.csdfEditor.camera().eye[0] !== {eye[0]}")
    orbited = _image(page)
    assert np.abs(orbited.astype(int) - before).max(-1).astype(bool).mean() > 0.01
    cam = _state(page, "camera()")
    dist = np.linalg.norm(np.subtract(cam["eye"], cam["target"]))
    page.mouse.wheel(0, 300)
    page.wait_for_function(
        "(d) => { const c = window.csdfEditor.camera();"
        " return Math.hypot(...c.eye.map((v, i) => v - c.target[i])) > d * 1.1; }", arg=dist)
    page.dblclick("#view")
    page.wait_for_function(f"window.csdfEditor.camera().eye[0] === {eye[0]}")
    page.check("#slice-on")
    page.locator("#slice-at").fill("0.3")
    sliced = _image(page)
    changed = np.abs(sliced.astype(int) - before).max(-1).astype(bool)
    assert changed.mean() > 0.02


def test_export_shadertoy_uses_the_slider_values(page):
    page.locator("#param-u_seat_height").fill("0.5")
    with page.expect_download() as dl:
        page.click("#export-shadertoy")
    assert dl.value.suggested_filename == f"{MODEL}.shadertoy.glsl"
    with open(dl.value.path()) as f:
        src = f.read()
    assert "void mainImage(" in src and "const float u_seat_height = 0.5;" in src
