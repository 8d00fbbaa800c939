"""The editor server under bad input: every request gets a clear 4xx JSON error, never a
5xx (lone surrogates, deeply nested JSON, huge integers, models that fail to mesh), the
origin check accepts only the exact origin the server serves, and a seeded fuzz test of
the API (300 requests, a few seconds; ``CSDF_FUZZ=1`` for 10^5, about 7 minutes;
``CSDF_FUZZ_N=<n>`` for n; a failure names the request's index in the seeded sequence)."""

from __future__ import annotations

import importlib
import json
import os
import random
import string

import pytest

pytest.importorskip("starlette")
pytest.importorskip("httpx")

from starlette.testclient import TestClient  # noqa: E402

from csdf.editor.server import create_app  # noqa: E402

SMALL = "param r = 0.5 in [0.2, 1]\nexport box((r, r, r)) | sphere(r / 2).translate((0, 0, r))\n"
API = ["/api/compile", "/api/save", "/api/export/mesh", "/api/export/shadertoy"]
JSON = {"content-type": "application/json"}


def _client(tmp_path, port: int = 80, model: bool = True) -> TestClient:
    path = tmp_path / "m.csdf" if model else None
    if path is not None and not path.exists():
        path.write_text(SMALL)
    base = "http://127.0.0.1" if port == 80 else f"http://127.0.0.1:{port}"
    return TestClient(create_app(path, root=tmp_path), base_url=base,
                      raise_server_exceptions=False)


def _post(c: TestClient, path: str, body: bytes | str, **headers):
    data = body.encode("utf-8", "surrogatepass") if isinstance(body, str) else body
    return c.post(path, content=data, headers={**JSON, **headers})


def _is_json_error(r, status: int | None = None) -> dict:
    assert 400 <= r.status_code < 500, (r.status_code, r.text[:300])
    if status is not None:
        assert r.status_code == status, (r.status_code, r.text[:300])
    d = r.json()
    assert d["ok"] is False and d["error"]
    return d


@pytest.mark.parametrize("path", API)
def test_lone_surrogate_in_the_text_is_a_400(tmp_path, path):
    c = _client(tmp_path)
    body = '{"text": "export sphere(1)\\ud800", "format": "stl", "filename": "m.csdf"}'
    d = _is_json_error(_post(c, path, body), 400)
    assert "surrogate" in json.dumps(d)
    assert (tmp_path / "m.csdf").read_text() == SMALL


def test_lone_surrogate_elsewhere_in_the_body_is_a_400(tmp_path):
    c = _client(tmp_path)
    body = json.dumps({"text": SMALL, "params": {"\ud800": 1}})
    _is_json_error(_post(c, "/api/export/shadertoy", body), 400)
    raw = b'{"text": "export sphere(1)\xed\xa0\x80"}'  # a surrogate encoded in UTF-8
    _is_json_error(_post(c, "/api/compile", raw), 400)


@pytest.mark.parametrize("path", API)
def test_deeply_nested_json_is_a_400(tmp_path, path):
    c = _client(tmp_path)
    for body in (b"[" * 100_000 + b"]" * 100_000,
                 b'{"text": ' + b'{"a": ' * 30_000 + b"1" + b"}" * 30_001):
        d = _is_json_error(_post(c, path, body), 400)
        assert "nested" in d["error"]


def test_huge_numbers_are_400(tmp_path):
    c = _client(tmp_path)
    body = json.dumps({"text": SMALL, "params": {"r": 10 ** 400}, "resolution": 16})
    for path in ("/api/export/mesh", "/api/export/shadertoy"):
        d = _is_json_error(_post(c, path, body), 400)
        assert "'r'" in d["error"]
    # more digits than Python converts by default
    _is_json_error(_post(c, "/api/compile", b'{"text": "x", "n": ' + b"9" * 5000 + b"}"), 400)
    big = json.dumps({"text": SMALL, "resolution": 10 ** 400})
    _is_json_error(_post(c, "/api/export/mesh", big), 400)


def test_a_model_that_fails_to_mesh_is_a_422(tmp_path, monkeypatch):
    c = _client(tmp_path)
    for text in ("export sphere(0)\n", "export sphere(1) & sphere(1).translate((5, 0, 0))\n"):
        r = c.post("/api/export/mesh", json={"text": text, "resolution": 16})
        _is_json_error(r, 422)
    # whatever the mesher raises on a hostile model is the model's fault, not a 500
    mesh_api = importlib.import_module("csdf.mesh.api")  # csdf.mesh is also a function

    for exc in (ValueError("cannot convert float NaN to integer"), OverflowError("big"),
                MemoryError()):
        def boom(*a, _exc=exc, **kw):
            raise _exc

        monkeypatch.setattr(mesh_api, "mesh", boom)
        r = c.post("/api/export/mesh", json={"text": SMALL, "resolution": 16})
        d = _is_json_error(r, 422)
        assert "mesh" in d["error"]


def test_an_empty_mesh_is_a_422_not_an_empty_file(tmp_path):
    c = _client(tmp_path)
    r = c.post("/api/export/mesh", json={"text": "param r = 0.5\nexport sphere(r)\n",
                                         "resolution": 16, "params": {"r": 5e-324}})
    _is_json_error(r, 422)


@pytest.mark.parametrize("origin", [
    "null", "file://127.0.0.1", "https://127.0.0.1", "ftp://127.0.0.1", "ws://127.0.0.1",
    "http://127.0.0.1:8080", "http://localhost:81", "http://127.0.0.1.evil.example",
    "http://evil.example", "http://127.0.0.1/", "http://user@127.0.0.1", "HTTP://127.0.0.1",
    "", "http://[::1]", "http://127.0.0.1:80:80",
])
def test_origin_must_be_exactly_the_servers_own(tmp_path, origin):
    c = _client(tmp_path)
    r = c.post("/api/save", json={"text": "export sphere(1)\n"}, headers={"origin": origin})
    assert r.status_code == 403, origin
    assert r.json()["ok"] is False
    assert c.get("/api/model", headers={"origin": origin}).status_code == 403
    assert (tmp_path / "m.csdf").read_text() == SMALL


def test_the_servers_own_origin_is_accepted(tmp_path):
    c = _client(tmp_path)
    for origin in ("http://127.0.0.1", "http://127.0.0.1:80", "http://localhost",
                   "http://localhost:80"):
        r = c.post("/api/compile", json={"text": SMALL}, headers={"origin": origin})
        assert r.status_code == 200, origin
    assert c.post("/api/compile", json={"text": SMALL}).status_code == 200  # no Origin
    c = _client(tmp_path, port=8123)
    for origin in ("http://127.0.0.1:8123", "http://localhost:8123"):
        r = c.post("/api/compile", json={"text": SMALL}, headers={"origin": origin})
        assert r.status_code == 200, origin
    for origin in ("http://127.0.0.1", "http://127.0.0.1:8124", "https://127.0.0.1:8123"):
        r = c.post("/api/compile", json={"text": SMALL}, headers={"origin": origin})
        assert r.status_code == 403, origin


# ------------------------------------------------------------------ fuzzing
_MODELS = [SMALL, "export sphere(1)\n", "export sphere(", "export rectangle((1, 1))\n",
           "param r = 0.5\nexport sphere(r)\n", "export sphere(0)\n", "",
           "export sphere(1).repeat(0.5, count=3)\n"]
_ATOMS = [0, 1, -1, 8, 16, 257, 10 ** 400, 1e308, -0.0, 0.5, True, None, "", "stl", "obj",
          "ply", "r", "\ud800", "m.csdf", "../x.csdf", [], {}, [1, 2], {"r": 0.5}]
_KEYS = ["text", "format", "resolution", "params", "filename", "r", "x", ""]


def _random_value(rng: random.Random, depth: int = 0):
    k = rng.random()
    if depth > 3 or k < 0.45:
        return rng.choice(_ATOMS)
    if k < 0.6:
        return rng.choice(_MODELS)
    if k < 0.7:
        return "".join(rng.choice(string.printable) for _ in range(rng.randint(0, 30)))
    if k < 0.85:
        return [_random_value(rng, depth + 1) for _ in range(rng.randint(0, 3))]
    return {rng.choice(_KEYS): _random_value(rng, depth + 1) for _ in range(rng.randint(0, 3))}


def _random_body(rng: random.Random) -> bytes:
    k = rng.random()
    if k < 0.6:
        body: dict = {"text": rng.choice(_MODELS)} if rng.random() < 0.8 else {}
        for _ in range(rng.randint(0, 4)):
            body[rng.choice(_KEYS)] = _random_value(rng)
        if rng.random() < 0.3 and isinstance(body.get("text"), str):
            t = body["text"]
            i = rng.randint(0, len(t))
            body["text"] = t[:i] + rng.choice(string.printable + "\ud800\x00") + t[i + 1:]
        if "resolution" in body and rng.random() < 0.7:
            body["resolution"] = rng.choice([8, 12, 16])  # keep the meshing cheap
        data = json.dumps(body, allow_nan=True).encode("utf-8", "surrogatepass")
    elif k < 0.8:
        data = json.dumps(_random_value(rng)).encode("utf-8", "surrogatepass")
    else:
        data = bytes(rng.randrange(256) for _ in range(rng.randint(0, 40)))
    if rng.random() < 0.1 and data:  # truncate or corrupt
        data = data[: rng.randrange(len(data))]
    return data


def _fuzz_count(default: int) -> int:
    """Requests per run: ``CSDF_FUZZ_N``, else 10^5 under ``CSDF_FUZZ=1``, else
    ``default`` (the convention of the other fuzzers, ``tests/fuzzing.py``)."""
    n = os.environ.get("CSDF_FUZZ_N", "").strip()
    if n:
        return int(n)
    return 100_000 if os.environ.get("CSDF_FUZZ", "").strip() not in ("", "0") else default


def test_fuzzing_the_api_never_gives_a_5xx(tmp_path, monkeypatch):
    n = _fuzz_count(300)
    rng = random.Random(20261202)
    monkeypatch.chdir(tmp_path)
    c = _client(tmp_path)
    (tmp_path / "new").mkdir()
    c2 = _client(tmp_path / "new", model=False)  # no file opened: save needs a filename
    origins = [None, None, None, "http://127.0.0.1", "null", "http://evil.example"]
    ctypes = ["application/json"] * 8 + ["text/plain", "", "application/json; charset=utf-8"]
    seen: set[int] = set()
    for i in range(n):
        client = c2 if i % 5 == 0 else c
        path = rng.choice(API + ["/api/model"])
        headers = {"content-type": rng.choice(ctypes)}
        origin = rng.choice(origins)
        if origin is not None:
            headers["origin"] = origin
        if path == "/api/model":
            r = client.get(path, headers=headers)
        else:
            r = client.post(path, content=_random_body(rng), headers=headers)
        seen.add(r.status_code)
        assert r.status_code < 500, (i, path, r.status_code, r.text[:300])
        if r.status_code >= 400:
            assert r.headers["content-type"].startswith("application/json")
            assert r.json()["ok"] is False
    assert {200, 400, 422}.issubset(seen)


def test_unbounded_parameters_compile_to_json_nulls(tmp_path):
    c = _client(tmp_path)
    r = c.post("/api/compile", json={"text": "param r = 0.5\nparam q = 1 in [0, inf]\n"
                                             "export sphere(r + q)\n"})
    assert r.status_code == 200, r.text[:300]
    p = {x["name"]: x for x in r.json()["params"]}
    assert p["r"]["lo"] is None and p["r"]["hi"] is None
    assert p["q"]["lo"] == 0 and p["q"]["hi"] is None


@pytest.mark.parametrize("path", ["/api/compile", "/api/export/mesh", "/api/export/shadertoy"])
def test_an_exponential_let_chain_is_refused_quickly(tmp_path, path):
    """One request with a model that expands exponentially must not tie the server up:
    the build budget of the shapes layer applies (a 4xx within a second)."""
    import time

    lines = ["let a0 = sphere(0.1)"]
    for i in range(1, 18):
        lines.append(f"let a{i} = a{i - 1}.translate((0.{i}1, 0, 0)) "
                     f"| a{i - 1}.translate((0, 0.{i}2, 0))")
    lines.append("export a17")
    c = _client(tmp_path)
    t0 = time.perf_counter()
    r = _post(c, path, json.dumps({"text": "\n".join(lines)}))
    assert time.perf_counter() - t0 < 2.0
    assert 400 <= r.status_code < 500, (r.status_code, r.text[:300])
    assert "expands to more than" in r.text
