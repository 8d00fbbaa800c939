"""The live editor's server: a Starlette app that serves the page and a small JSON API.

Endpoints (all JSON bodies must be ``application/json``; bodies over
:data:`MAX_BODY_BYTES` get 413):

``GET /``
    The page (``static/index.html``); ``/static/...`` its scripts and styles.
``GET /api/model``
    ``{'text', 'name', 'path'}``: the opened model's text (or the default model's).
``POST /api/compile`` ``{'text'}``
    ``{'ok': true, 'glsl', 'params', 'info', 'bounds', 'step'}`` with the GLSL of
    :func:`csdf.backends.glsl.to_glsl` (``sdf`` and ``sdf_grad``), the parameters of
    :func:`~csdf.backends.glsl.glsl_params`, the ``csdf info`` figures, the shape's box
    and the sphere-tracing step scale (an unbounded parameter range has ``lo``/``hi``
    null); or 422 ``{'ok': false, 'error': {'line',
    'column', 'message', 'hint', 'text'}}``.
``POST /api/save`` ``{'text', 'filename'?}``
    Atomic write of the text to the opened file. With no file opened, ``filename`` (a
    ``.csdf`` name inside the folder the editor started in) is required once; it then
    becomes the opened file. Anything outside that folder is refused (403).
``POST /api/export/mesh`` ``{'text', 'format': 'stl'|'obj', 'resolution'?, 'params'?}``
    The mesh file's bytes (marching cubes, at most :data:`MAX_EXPORT_RESOLUTION` voxels
    along the longest side).
``POST /api/export/shadertoy`` ``{'text', 'params'?}``
    The Shadertoy "Image" shader as text, with the given parameter values as constants.

Errors are JSON ``{'ok': false, 'error': ...}`` with a 4xx status: 400 for a malformed
request (not JSON, nested deeper than :data:`MAX_JSON_DEPTH`, a lone surrogate in a
string, numbers out of range, an unknown parameter or a value outside its parameter's
declared range), 403 for a refused origin or file, 413 for size, 415 for
the content type and 422 for a model that does not load, compile or mesh. Only a failing
disk (reading or writing the opened file) gives a 5xx.

Safety: the server reads and writes only the opened model file (or, without one, a new
``.csdf`` file in the start folder), evaluates nothing but the ``.csdf`` language (a
parser and a fixed set of shape functions; no code execution), rejects requests whose
``Host`` is not the loopback address (DNS rebinding) or whose ``Origin`` is not exactly
the origin the server serves (``http://127.0.0.1:PORT`` or ``http://localhost:PORT``;
``Origin: null`` is refused), and binds only 127.0.0.1.
"""

from __future__ import annotations

import json
import math
import re
import socket
import sys
import threading
import webbrowser
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, PlainTextResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from ..colors import albedo_glsl
from ..errors import CsdfError, ModelError, ParamError
from ..field import Field, as_field, glsl_float, glsl_params, shadertoy, to_glsl

__all__ = ["create_app", "serve", "free_port", "model_info", "MAX_BODY_BYTES",
           "MAX_EXPORT_RESOLUTION", "MAX_JSON_DEPTH", "DEFAULT_MODEL"]

#: largest accepted request body (the model text and a few fields), in bytes
MAX_BODY_BYTES = 256 * 1024
#: the preview's colour of uncoloured surfaces (RGB), as its shader has always drawn them
PREVIEW_ALBEDO = (0.80, 0.76, 0.70)
#: largest mesh export resolution (voxels along the longest side)
MAX_EXPORT_RESOLUTION = 256
#: deepest accepted nesting of arrays and objects in a request body
MAX_JSON_DEPTH = 32
#: the zoo model the editor opens when no file is given
DEFAULT_MODEL = "chair"

STATIC_DIR = Path(__file__).with_name("static")
_LOOPBACK = ["127.0.0.1", "localhost"]
_FILENAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\- ]{0,120}\.csdf")
_SURROGATE = re.compile("[\ud800-\udfff]")
_SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
        "img-src 'self' data: blob:; connect-src 'self'; object-src 'none'; "
        "base-uri 'none'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}


class _ApiError(Exception):
    """An HTTP error with a JSON message."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


# ---------------------------------------------------------------------------- helpers
def model_info(model, shape=None) -> dict[str, Any]:
    """The figures ``csdf info`` prints, as a JSON-ready dict, for a
    :class:`csdf.field.Field`, a Shape or a Program (``shape``: where the Program's own
    box comes from, for programs compiled without one).

    Returns:
        ``{'instructions', 'params', 'exactness', 'lipschitz', 'levels': {'expanded' |
        'primitive': {'bytes', 'add', 'mul', 'div', 'call', 'branch'}}, 'bounds'}``
        (``lipschitz`` is None when infinite; ``bounds`` None when unknown).
    """
    fld = as_field(model if shape is None else shape, what="model_info")
    prog = fld.program
    levels = {}
    for level, size in (("expanded", prog.nbytes), ("primitive", prog.compact_nbytes())):
        c = prog.counts(level)
        levels[level] = {"bytes": int(size),
                         **{k: int(c[k]) for k in ("add", "mul", "div", "call", "branch")}}
    lip = float(prog.lipschitz)
    return {
        "instructions": len(prog),
        "params": len(prog.params),
        "exactness": str(prog.exactness),
        "lipschitz": lip if math.isfinite(lip) else None,
        "levels": levels,
        "bounds": _bounds(fld),
    }


def _bounds(fld: Field) -> list[list[float]] | None:
    """The field's own 3D box as nested lists, or None when it has none (or an infinite
    one): the analytic box, with no interval search."""
    b = fld.own_bounds
    if b is None or b.shape != (2, 3):
        return None
    return [[float(v) for v in row] for row in b]


def _step_scale(prog) -> float:
    """Sphere-tracing step scale: ``1 / L`` for a Lipschitz bound ``L > 1``, 0.5 if
    unbounded, else 1 (the rule of :func:`csdf.backends.glsl.shadertoy`)."""
    lip = float(prog.lipschitz)
    if not math.isfinite(lip):
        return 0.5
    return 1.0 / lip if lip > 1.0 else 1.0


def _error_json(exc: CsdfError) -> dict[str, Any]:
    """A model error as the page shows it (line and column are 1-based, 0 if unknown)."""
    if isinstance(exc, ModelError):
        return {"line": exc.line, "column": exc.column, "message": exc.message,
                "hint": exc.hint, "width": exc.width, "text": str(exc)}
    return {"line": 0, "column": 0, "message": str(exc), "hint": "", "width": 1,
            "text": str(exc)}


def _load_text(text: str, name: str) -> Field:
    """Parse and compile ``text`` into its :class:`csdf.field.Field`; raises CsdfError."""
    from ..lang import loads

    shape = loads(text, file=name)
    if getattr(shape, "dim", 3) != 3:
        raise CsdfError("the editor previews 3D models; this model is 2D (extrude or "
                        "revolve it)")
    return as_field(shape, what="the editor")


def _params(value: Any, prog) -> dict[str, float]:
    """Validated ``{name: value}`` for the program's parameters: unknown names, values
    that are not finite numbers and values outside their parameter's declared range
    (a slider left from an edit that narrowed it) are refused with 400 and a message
    naming the parameter (and the range)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _ApiError(400, "params must be an object {name: number}")
    names = {p.name for p in prog.params}
    out: dict[str, float] = {}
    for k, v in value.items():
        if k not in names:
            raise _ApiError(400, f"unknown parameter {k!r}")
        bad = _ApiError(400, f"parameter {k!r} must be a finite number")
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise bad
        try:
            f = float(v)  # an integer beyond the float range overflows
        except OverflowError:
            raise bad from None
        if not math.isfinite(f):
            raise bad
        out[k] = f
    try:
        prog.param_values(out, range_hint="")
    except ParamError as exc:
        raise _ApiError(400, str(exc)) from None
    return out


#: what a hostile model may make numeric code raise (beside CsdfError): the model's
#: fault, answered with 422, not a server error
_MODEL_FAILURES = (ValueError, ArithmeticError, MemoryError, RecursionError)


def _json_safe(v: Any) -> Any:
    """``v`` with every non-finite float replaced by None (JSON has no infinity: an
    unbounded parameter range is sent as ``lo``/``hi`` null)."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    return v


def _describe(exc: BaseException) -> str:
    """A short message for an unexpected failure on a model (type and first line)."""
    text = str(exc).splitlines()[0][:200] if str(exc) else ""
    if isinstance(exc, MemoryError):
        return "out of memory" + (f" ({text})" if text else "")
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _own_origins(request: Request, hosts: list[str]) -> set[str]:
    """The exact ``Origin`` values of this server's own page: ``http://HOST:PORT`` for
    each accepted host name and the port the server listens on (also without ``:80``
    for port 80). Any other scheme, host or port, and ``null``, is another origin."""
    server = request.scope.get("server")
    port = server[1] if server and server[1] is not None else request.url.port or 80
    out = {f"http://{h}:{port}" for h in hosts}
    if port == 80:
        out |= {f"http://{h}" for h in hosts}
    return out


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that is free on ``host`` now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


# ---------------------------------------------------------------------------- the app
class _Editor:
    """State of one editor session: the opened file (or None) and its folder."""

    def __init__(self, model_path: str | Path | None, root: str | Path | None = None):
        if model_path is None:
            self.path: Path | None = None
            self.root = Path(root if root is not None else Path.cwd()).resolve()
        else:
            p = Path(model_path).expanduser().resolve()
            if p.suffix.lower() != ".csdf":
                raise CsdfError(f"{model_path}: the editor opens .csdf models")
            if not p.parent.is_dir():
                raise CsdfError(f"{model_path}: folder {p.parent} does not exist")
            self.path = p
            self.root = p.parent
        self.lock = threading.Lock()

    # -------------------------------------------------------------- files
    def name(self) -> str:
        return self.path.name if self.path is not None else f"{DEFAULT_MODEL}.csdf"

    def read(self) -> str:
        """The opened model's text; a default zoo model without a file; an empty model
        with a comment for a new file."""
        from .. import zoo

        if self.path is None:
            return zoo.source(DEFAULT_MODEL)
        if not self.path.exists():
            return "# a new model\nparam r = 0.5 in [0.1, 1]\nexport sphere(r)\n"
        try:
            data = self.path.read_bytes()
        except OSError as exc:
            raise _ApiError(500, f"cannot read {self.path.name}: {exc.strerror}") from None
        try:
            return data.decode("utf-8")
        except UnicodeDecodeError:
            raise _ApiError(400, f"{self.path.name} is not UTF-8 text") from None

    def target(self, filename: Any) -> Path:
        """The file a save writes: the opened one, or a new ``.csdf`` in the root folder."""
        if self.path is not None:
            if filename not in (None, "", self.path.name):
                raise _ApiError(403, f"this editor saves only {self.path.name}")
            return self.path
        if not isinstance(filename, str) or not filename:
            raise _ApiError(400, "no file is open: give a filename (NAME.csdf) to save as")
        if not _FILENAME.fullmatch(filename) or "/" in filename or "\\" in filename:
            raise _ApiError(403, "filename must be a plain NAME.csdf in the editor's folder "
                                 "(letters, digits, '_', '-', '.', spaces; no folders)")
        p = (self.root / filename).resolve()
        if p.parent != self.root:
            raise _ApiError(403, "filename must be inside the editor's folder")
        return p

    def save(self, text: str, filename: Any) -> Path:
        from ..io import atomic_path

        with self.lock:
            p = self.target(filename)
            try:
                with atomic_path(p) as tmp:
                    tmp.write_text(text, encoding="utf-8")
            except OSError as exc:
                raise _ApiError(500, f"cannot write {p.name}: {exc.strerror}") from None
            except CsdfError as exc:  # atomic_path's wrapped OSError
                raise _ApiError(500, str(exc)) from None
            self.path = p
        return p


async def _json_body(request: Request) -> dict[str, Any]:
    """The request's JSON object, with the size and content-type checks."""
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype != "application/json":
        raise _ApiError(415, "send application/json")
    declared = request.headers.get("content-length")
    if declared is not None:
        try:
            if int(declared) > MAX_BODY_BYTES:
                raise _ApiError(413, f"request over {MAX_BODY_BYTES} bytes")
        except ValueError:
            raise _ApiError(400, "bad Content-Length") from None
    chunks = []
    size = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY_BYTES:
            raise _ApiError(413, f"request over {MAX_BODY_BYTES} bytes")
        chunks.append(chunk)
    try:
        body = json.loads(b"".join(chunks).decode("utf-8"))
    except RecursionError:
        raise _ApiError(400, f"the JSON is nested too deeply (limit {MAX_JSON_DEPTH} "
                             "levels)") from None
    except UnicodeDecodeError:
        raise _ApiError(400, "the body is not JSON (not UTF-8 text)") from None
    except ValueError as exc:  # JSONDecodeError, or an integer with too many digits
        detail = "" if isinstance(exc, json.JSONDecodeError) else f" ({exc})"
        raise _ApiError(400, f"the body is not JSON{detail}"[:200]) from None
    if not isinstance(body, dict):
        raise _ApiError(400, "the body must be a JSON object")
    _check_json(body)
    return body


def _check_json(body: Any) -> None:
    """Refuse bodies nested deeper than :data:`MAX_JSON_DEPTH` and strings (values or
    keys) holding a lone surrogate (``"\\ud800"`` is valid JSON but not Unicode text:
    it can be neither saved as UTF-8 nor echoed back in an error)."""
    stack: list[tuple[Any, int]] = [(body, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, str):
            m = _SURROGATE.search(v)
            if m is not None:
                raise _ApiError(400, f"a string holds a lone surrogate "
                                     f"({ascii(m.group())[1:-1]} at index {m.start()}): "
                                     "not valid Unicode text")
        elif isinstance(v, (dict, list)):
            if depth > MAX_JSON_DEPTH:
                raise _ApiError(400, f"the JSON is nested too deeply (limit "
                                     f"{MAX_JSON_DEPTH} levels)")
            items = [*v.keys(), *v.values()] if isinstance(v, dict) else v
            stack.extend((x, depth + 1) for x in items)


def _text(body: dict[str, Any]) -> str:
    text = body.get("text")
    if not isinstance(text, str):
        raise _ApiError(400, "'text' (the model source) is required")
    return text


def create_app(model_path: str | Path | None = None, *, root: str | Path | None = None,
               allowed_hosts: list[str] | None = None) -> Starlette:
    """The editor's Starlette application.

    Args:
        model_path: the ``.csdf`` file to edit (created on the first save if missing);
            None opens the default zoo model, and save then asks for a file name in
            ``root``.
        root: the folder a new file may be saved in when ``model_path`` is None
            (default the current directory).
        allowed_hosts: accepted ``Host`` names (default the loopback names).

    Raises:
        CsdfError: ``model_path`` is not a ``.csdf`` path or its folder does not exist.
    """
    ed = _Editor(model_path, root)
    hosts = list(allowed_hosts) if allowed_hosts is not None else list(_LOOPBACK)
    origin_hosts = [h for h in hosts if "*" not in h]

    def guard(handler):
        async def endpoint(request: Request) -> Response:
            origin = request.headers.get("origin")
            if origin is not None and origin not in _own_origins(request, origin_hosts):
                return JSONResponse({"ok": False, "error": "cross-origin request refused: "
                                     "only this editor's own page may call its API"}, 403)
            try:
                return await handler(request)
            except _ApiError as exc:
                return JSONResponse({"ok": False, "error": exc.message}, exc.status)

        return endpoint

    async def index(request: Request) -> Response:
        return FileResponse(STATIC_DIR / "index.html", headers=_SECURITY_HEADERS)

    async def get_model(request: Request) -> Response:
        text = await run_in_threadpool(ed.read)
        return JSONResponse({"text": text, "name": ed.name(),
                             "path": str(ed.path) if ed.path is not None else None,
                             "max_bytes": MAX_BODY_BYTES,
                             "max_resolution": MAX_EXPORT_RESOLUTION})

    def _compile(text: str) -> tuple[int, dict[str, Any]]:
        try:
            fld = _load_text(text, ed.name())
            prog = fld.program
            glsl = to_glsl(prog)
            # the surface colours (the model's color() nodes; else the preview's grey)
            glsl += albedo_glsl(fld.shape if fld.shape is not None else prog,
                                declared=glsl, default=PREVIEW_ALBEDO)
            info = model_info(fld)
        except CsdfError as exc:
            return 422, {"ok": False, "error": _error_json(exc)}
        except _MODEL_FAILURES as exc:
            err = CsdfError(f"the model cannot be previewed: {_describe(exc)}")
            return 422, {"ok": False, "error": _error_json(err)}
        return 200, _json_safe({"ok": True, "glsl": glsl, "params": glsl_params(prog),
                                "info": info, "bounds": info["bounds"],
                                "step": _step_scale(prog)})

    async def compile_(request: Request) -> Response:
        text = _text(await _json_body(request))
        status, data = await run_in_threadpool(_compile, text)
        return JSONResponse(data, status)

    async def save(request: Request) -> Response:
        body = await _json_body(request)
        text = _text(body)
        p = await run_in_threadpool(ed.save, text, body.get("filename"))
        return JSONResponse({"ok": True, "name": p.name, "bytes": len(text.encode("utf-8"))})

    def _mesh(text: str, fmt: str, resolution: int, params: Any) -> bytes:
        from ..mesh.api import mesh

        try:
            fld = _load_text(text, ed.name())
        except CsdfError as exc:
            raise _ApiError(422, str(exc)) from None
        except _MODEL_FAILURES as exc:
            raise _ApiError(422, f"the model cannot be loaded: {_describe(exc)}") from None
        pv = _params(params, fld.program)
        try:
            m = mesh(fld, resolution=resolution, params=pv, progress=False)
            if len(m.faces) == 0:
                raise CsdfError(f"the mesh is empty at resolution {resolution}: the shape "
                                "has no surface there, or only parts thinner than a voxel")
            data = m.export(file_type=fmt)
        except CsdfError as exc:
            raise _ApiError(422, str(exc)) from None
        except _MODEL_FAILURES as exc:
            raise _ApiError(422, f"the model cannot be meshed: {_describe(exc)}") from None
        return data.encode() if isinstance(data, str) else data

    async def export_mesh(request: Request) -> Response:
        body = await _json_body(request)
        text = _text(body)
        fmt = body.get("format", "stl")
        if fmt not in ("stl", "obj"):
            raise _ApiError(400, "format must be 'stl' or 'obj'")
        res = body.get("resolution", 96)
        if isinstance(res, bool) or not isinstance(res, int) or not \
                8 <= res <= MAX_EXPORT_RESOLUTION:
            raise _ApiError(400, f"resolution must be an integer in [8, {MAX_EXPORT_RESOLUTION}]")
        data = await run_in_threadpool(_mesh, text, fmt, res, body.get("params"))
        stem = Path(ed.name()).stem
        media = "model/stl" if fmt == "stl" else "model/obj"
        return Response(data, media_type=media, headers={
            "Content-Disposition": f'attachment; filename="{stem}.{fmt}"'})

    def _shadertoy(text: str, params: Any) -> str:
        try:
            fld = _load_text(text, ed.name())
        except CsdfError as exc:
            raise _ApiError(422, str(exc)) from None
        except _MODEL_FAILURES as exc:
            raise _ApiError(422, f"the model cannot be loaded: {_describe(exc)}") from None
        prog = fld.program
        pv = _params(params, prog)
        try:
            src = shadertoy(fld.shape)
        except CsdfError as exc:
            raise _ApiError(422, str(exc)) from None
        except _MODEL_FAILURES as exc:
            raise _ApiError(422, f"the model cannot be exported: {_describe(exc)}") from None
        for p in glsl_params(prog):
            if p["name"] in pv:
                src = re.sub(rf"^const float {re.escape(p['uniform'])} = [^;]*;",
                             f"const float {p['uniform']} = {glsl_float(pv[p['name']])};",
                             src, count=1, flags=re.MULTILINE)
        return src

    async def export_shadertoy(request: Request) -> Response:
        body = await _json_body(request)
        src = await run_in_threadpool(_shadertoy, _text(body), body.get("params"))
        return PlainTextResponse(src)

    async def favicon(request: Request) -> Response:
        return Response(status_code=204)

    routes = [
        Route("/", index),
        Route("/favicon.ico", favicon),
        Route("/api/model", guard(get_model)),
        Route("/api/compile", guard(compile_), methods=["POST"]),
        Route("/api/save", guard(save), methods=["POST"]),
        Route("/api/export/mesh", guard(export_mesh), methods=["POST"]),
        Route("/api/export/shadertoy", guard(export_shadertoy), methods=["POST"]),
        Mount("/static", app=StaticFiles(directory=STATIC_DIR), name="static"),
    ]
    app = Starlette(routes=routes,
                    middleware=[Middleware(TrustedHostMiddleware, allowed_hosts=hosts)])
    app.state.editor = ed
    return app


def serve(model_path: str | Path | None = None, *, port: int = 0, open_browser: bool = True,
          log_level: str = "warning") -> None:
    """Run the editor until interrupted (Ctrl-C): Uvicorn on 127.0.0.1.

    Args:
        model_path: the ``.csdf`` file to edit, or None for the default model.
        port: the TCP port (0: a free one).
        open_browser: open the page with :mod:`webbrowser` when a browser is available.
        log_level: Uvicorn's log level.

    Raises:
        CsdfError: a bad model path, or ``port`` already in use.
    """
    import uvicorn

    app = create_app(model_path)
    if port:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError as exc:
                raise CsdfError(f"cannot listen on 127.0.0.1:{port}: {exc.strerror}") from None
    port = port or free_port()
    url = f"http://127.0.0.1:{port}/"
    config = uvicorn.Config(app, host="127.0.0.1", port=port, log_level=log_level,
                            access_log=False)
    server = uvicorn.Server(config)
    print(f"csdf editor: {url}  (Ctrl-C to stop)", flush=True)
    if open_browser:
        def _open() -> None:
            try:
                webbrowser.open(url)
            except webbrowser.Error:  # pragma: no cover - no browser
                print("no browser found; open the URL above", file=sys.stderr)

        threading.Timer(0.5, _open).start()
    server.run()
