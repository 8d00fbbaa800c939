"""The live editor's server (:mod:`csdf.editor.server`) through Starlette's TestClient:
compile (GLSL, parameters, info; errors with line and column), the request size limit,
save (atomic, only the opened file or a new file in the start folder), mesh export
(watertight) and the Shadertoy export, and the ``csdf edit`` command's wiring."""

from __future__ import annotations

import io
import os
import signal
import stat
import subprocess
import sys
import time

import pytest
import trimesh

pytest.importorskip("starlette")
pytest.importorskip("httpx")

from starlette.testclient import TestClient  # noqa: E402

from csdf import zoo  # noqa: E402
from csdf.editor import server as srv  # noqa: E402
from csdf.editor.server import MAX_BODY_BYTES, create_app  # noqa: E402

CHAIR = zoo.source("chair")
SMALL = "param r = 0.5 in [0.2, 1]\nexport box((r, r, r)) | sphere(r / 2).translate((0, 0, r))\n"


def _client(model=None, **kw) -> TestClient:
    return TestClient(create_app(model, **kw), base_url="http://127.0.0.1")


@pytest.fixture
def model(tmp_path):
    p = tmp_path / "chair.csdf"
    p.write_text(CHAIR)
    return p


def test_page_and_static_files(model):
    c = _client(model)
    r = c.get("/")
    assert r.status_code == 200
    assert "csdf editor" in r.text and "/static/app.js" in r.text
    assert "default-src 'self'" in r.headers["content-security-policy"]
    for path in ("/static/app.js", "/static/editor.css", "/static/vendor/codemirror.min.js"):
        assert c.get(path).status_code == 200, path
    m = c.get("/api/model").json()
    assert m["text"] == CHAIR and m["name"] == "chair.csdf" and m["path"] == str(model)


def test_compile_ok(model):
    r = _client(model).post("/api/compile", json={"text": CHAIR})
    assert r.status_code == 200
    d = r.json()
    assert d["ok"] is True
    assert "float sdf(vec3 p)" in d["glsl"] and "vec4 sdf_grad(vec3 p)" in d["glsl"]
    names = {p["name"]: p for p in d["params"]}
    assert names["seat_height"]["uniform"] == "u_seat_height"
    assert names["seat_height"]["lo"] == 0.38 and names["seat_height"]["hi"] == 0.55
    assert "uniform float u_seat_height;" in d["glsl"]
    info = d["info"]
    prog = zoo.load("chair").compile()
    assert info["instructions"] == len(prog)
    assert info["levels"]["expanded"]["bytes"] == prog.nbytes
    assert info["levels"]["primitive"]["bytes"] == prog.compact_nbytes()
    assert info["levels"]["expanded"]["add"] == prog.counts("expanded")["add"]
    assert info["exactness"] == str(prog.exactness)
    assert d["bounds"][1][2] == pytest.approx(1.15)
    assert 0 < d["step"] <= 1


def test_compile_error_has_line_and_column(model):
    text = "param r = 0.5 in [0.1, 1]\nlet a = 2\nexport sphere(r +)\n"
    r = _client(model).post("/api/compile", json={"text": text})
    assert r.status_code == 422
    e = r.json()["error"]
    assert (e["line"], e["column"]) == (3, 18)
    assert "unexpected" in e["message"]
    # a name error points at the name
    r = _client(model).post("/api/compile", json={"text": "export spere(1)\n"})
    e = r.json()["error"]
    assert (e["line"], e["column"]) == (1, 8) and "sphere" in e["hint"]


def test_size_limit_413(model):
    c = _client(model)
    big = "# " + "x" * MAX_BODY_BYTES + "\nexport sphere(1)\n"
    for path in ("/api/compile", "/api/save", "/api/export/mesh", "/api/export/shadertoy"):
        assert c.post(path, json={"text": big}).status_code == 413, path
    assert model.read_text() == CHAIR


def test_only_json_and_same_origin(model):
    c = _client(model)
    # a cross-site form post (text/plain, no CORS preflight) is refused
    r = c.post("/api/save", content=b'{"text": "x"}', headers={"content-type": "text/plain"})
    assert r.status_code == 415
    r = c.post("/api/save", json={"text": "x"}, headers={"origin": "http://evil.example"})
    assert r.status_code == 403
    # DNS rebinding: another Host name
    assert c.get("/api/model", headers={"host": "evil.example"}).status_code == 400
    assert model.read_text() == CHAIR
    ok = c.post("/api/compile", json={"text": SMALL}, headers={"origin": "http://127.0.0.1"})
    assert ok.status_code == 200


def test_save_writes_atomically(model, monkeypatch):
    c = _client(model)
    mode = stat.S_IMODE(os.stat(model).st_mode)
    r = c.post("/api/save", json={"text": SMALL})
    assert r.status_code == 200 and r.json()["name"] == "chair.csdf"
    assert model.read_text() == SMALL
    assert stat.S_IMODE(os.stat(model).st_mode) == mode
    assert sorted(p.name for p in model.parent.iterdir()) == ["chair.csdf"]  # no temp left
    # a failing write leaves the old file whole and no temporary behind
    real_replace = os.replace

    def failing_replace(a, b):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", failing_replace)
    r = c.post("/api/save", json={"text": CHAIR})
    monkeypatch.setattr(os, "replace", real_replace)
    assert r.status_code == 500
    assert model.read_text() == SMALL
    assert sorted(p.name for p in model.parent.iterdir()) == ["chair.csdf"]


def test_save_refuses_other_files(model, tmp_path):
    c = _client(model)
    for name in ("../evil.csdf", "other.csdf", "/etc/passwd", "sub/x.csdf"):
        r = c.post("/api/save", json={"text": SMALL, "filename": name})
        assert r.status_code == 403, name
    assert model.read_text() == CHAIR
    assert not (tmp_path.parent / "evil.csdf").exists()


def test_no_model_requires_a_filename_inside_the_folder(tmp_path):
    c = _client(None, root=tmp_path)
    m = c.get("/api/model").json()
    assert m["path"] is None and m["text"] == zoo.source(srv.DEFAULT_MODEL)
    assert c.post("/api/save", json={"text": SMALL}).status_code == 400
    for name in ("../evil.csdf", "..", "a/b.csdf", "x.txt", ".hidden.csdf", "/tmp/x.csdf",
                 "..\\x.csdf", "a\x00.csdf"):
        r = c.post("/api/save", json={"text": SMALL, "filename": name})
        assert r.status_code == 403, name
    assert list(tmp_path.iterdir()) == []
    r = c.post("/api/save", json={"text": SMALL, "filename": "mine.csdf"})
    assert r.status_code == 200
    assert (tmp_path / "mine.csdf").read_text() == SMALL
    # that file is now the opened one
    assert c.get("/api/model").json()["name"] == "mine.csdf"
    assert c.post("/api/save", json={"text": SMALL, "filename": "two.csdf"}).status_code == 403


def test_new_file_is_created_on_save(tmp_path):
    p = tmp_path / "new.csdf"
    c = _client(p)
    assert "export" in c.get("/api/model").json()["text"]
    assert c.post("/api/save", json={"text": SMALL}).status_code == 200
    assert p.read_text() == SMALL


@pytest.mark.parametrize("fmt", ["stl", "obj"])
def test_export_mesh_is_watertight(model, fmt):
    r = _client(model).post("/api/export/mesh", json={
        "text": SMALL, "format": fmt, "resolution": 40, "params": {"r": 0.6}})
    assert r.status_code == 200
    assert f'filename="chair.{fmt}"' in r.headers["content-disposition"]
    m = trimesh.load(io.BytesIO(r.content), file_type=fmt, force="mesh")
    assert m.is_watertight and m.is_winding_consistent
    assert m.bounds[1][2] == pytest.approx(0.9, abs=0.03)  # sphere top: r + r / 2


def test_export_mesh_limits(model):
    c = _client(model)
    bad = [{"format": "ply"}, {"resolution": srv.MAX_EXPORT_RESOLUTION + 1},
           {"resolution": "64"}, {"params": {"nope": 1}}, {"params": {"r": "x"}}]
    for extra in bad:
        r = c.post("/api/export/mesh", json={"text": SMALL, "resolution": 32, **extra})
        assert r.status_code == 400, extra
    r = c.post("/api/export/mesh", json={"text": "export sphere(", "resolution": 32})
    assert r.status_code == 422


def test_shadertoy(model):
    c = _client(model)
    r = c.post("/api/export/shadertoy", json={"text": SMALL, "params": {"r": 0.75}})
    assert r.status_code == 200
    src = r.text
    assert "void mainImage(out vec4 fragColor, in vec2 fragCoord)" in src
    assert "const float u_r = 0.75;" in src
    r = c.post("/api/export/shadertoy", json={"text": SMALL})
    assert "const float u_r = 0.5;" in r.text


def test_bad_requests(model):
    c = _client(model)
    assert c.post("/api/compile", content=b"[1]",
                  headers={"content-type": "application/json"}).status_code == 400
    assert c.post("/api/compile", content=b"{nope",
                  headers={"content-type": "application/json"}).status_code == 400
    assert c.post("/api/compile", json={"text": 3}).status_code == 400
    r = c.post("/api/compile", json={"text": "export rectangle((1, 1))\n"})
    assert r.status_code == 422 and "2D" in r.json()["error"]["message"]
    assert c.get("/static/../server.py").status_code == 404


def test_create_app_checks_the_path(tmp_path):
    from csdf.errors import CsdfError

    with pytest.raises(CsdfError, match=".csdf"):
        create_app(tmp_path / "x.txt")
    with pytest.raises(CsdfError, match="does not exist"):
        create_app(tmp_path / "missing" / "x.csdf")


def test_cli_edit(monkeypatch, tmp_path):
    from typer.testing import CliRunner

    from csdf import cli

    calls = []
    monkeypatch.setattr(srv, "serve", lambda *a, **kw: calls.append((a, kw)))
    p = tmp_path / "m.csdf"
    res = CliRunner().invoke(cli.app, ["edit", str(p), "--no-browser", "--port", "8123"])
    assert res.exit_code == 0, res.output
    assert calls == [((p,), {"port": 8123, "open_browser": False})]
    res = CliRunner().invoke(cli.app, ["edit", "--help"])
    assert "--no-browser" in res.output


def test_csdf_edit_serves_on_loopback(tmp_path):
    """The real command: prints its URL, serves the page on 127.0.0.1, stops on SIGINT."""
    import httpx

    p = tmp_path / "m.csdf"
    p.write_text(SMALL)
    port = srv.free_port()
    code = "from csdf.cli import main; main()"
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "edit", str(p), "--no-browser", "--port", str(port)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = proc.stdout.readline()
        assert f"http://127.0.0.1:{port}/" in line, line
        url = f"http://127.0.0.1:{port}/api/model"
        for _ in range(200):
            try:
                r = httpx.get(url, timeout=5)
                break
            except httpx.TransportError:
                time.sleep(0.05)
        else:
            pytest.fail("the editor did not answer")
        assert r.json()["text"] == SMALL
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)


def test_serve_refuses_a_busy_port(tmp_path):
    import socket

    from csdf.errors import CsdfError

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        busy = s.getsockname()[1]
        with pytest.raises(CsdfError, match=f"127.0.0.1:{busy}"):
            srv.serve(tmp_path / "m.csdf", port=busy, open_browser=False)
