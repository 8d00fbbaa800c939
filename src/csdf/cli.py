"""The ``csdf`` command line (Typer + Rich).

Models are ``.csdf`` files, or compiled programs (``.csdfb`` bytecode, ``.csdft`` text
listings). A ``--param name=value`` outside the parameter's declared range is refused
(the message names the range) unless ``--no-check-ranges`` is given. Commands whose
evaluator must first be compiled say so on stderr ("csdf: compiling kernels (first use
only; cached in DIR)"). Every error is printed as one clear message (with file, line and column for
model errors; with the file's name for errors in compiled programs) and exits with
status 2; outputs are written atomically. SIGINT and SIGTERM stop a command promptly
(no partial output or temporary file is left) with status 130 and 143.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from . import __version__
from .errors import CsdfError, MeshWarning, interrupt_in

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Continuous signed distance functions: inspect, compile, mesh, render, scan, fit "
         "and edit .csdf models.",
)
out = Console()
err = Console(stderr=True)


def _load(path: Path):
    """A Shape (from .csdf, Fidget's .vm, OpenSCAD's .csg/.scad, or a zoo model's name:
    no suffix, no such file) or a Program (from .csdfb/.csdft)."""
    from .io.model import load_model

    if not path.suffix and not path.exists():
        from . import zoo

        if str(path) in zoo.names():
            return zoo.load(str(path))
        raise CsdfError(f"{path}: no such file, and not a zoo model (csdf zoo list)")
    return load_model(path)


def _field(model):
    """The :class:`csdf.field.Field` of a loaded model (its program, own box and
    parameters at their defaults)."""
    from .field import as_field

    return as_field(model, what="csdf")


def _positive(value: float | None) -> float | None:
    """Option callback: None, or a finite number > 0 (the error names the option)."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"must be a positive number, got {value:g}")
    return value


def _non_negative(value: float | None) -> float | None:
    """Option callback: None, or a finite number >= 0 (the error names the option)."""
    if value is not None and not (math.isfinite(value) and value >= 0):
        raise typer.BadParameter(f"must be a finite number >= 0, got {value:g}")
    return value


def _prefer(value: str | None) -> str | None:
    """``csdf infer --prefer``'s callback: None or one of ``csdf.infer``'s choices
    (imported only when a value is given: the CLI starts without the search)."""
    if value is not None:
        from .infer.api import PREFER

        if value not in PREFER:
            raise typer.BadParameter(f"must be one of {', '.join(PREFER)}, got {value!r}")
    return value


#: the end of a range error's message on the command line
_RANGE_HINT = "pass --no-check-ranges to use it anyway"
_NO_CHECK_HELP = ("Accept --param values outside their parameters' declared ranges (the "
                  "model's distance and bounds are then not promised).")


def _checked_params(model, values: list[str], no_check_ranges: bool) -> dict[str, float]:
    """The ``--param`` values for a loaded model: names and numbers validated and,
    unless ``--no-check-ranges``, each inside its parameter's declared range.

    Raises:
        ParamError: an unknown name, or a value outside its range (the message names
            the range and the flag).
    """
    params = _params(values)
    _field(model).program.param_values(params, check_ranges=not no_check_ranges,
                                       range_hint=_RANGE_HINT)
    return params


def _param_field(model, values: list[str], no_check_ranges: bool):
    """The :class:`csdf.field.Field` of a loaded model with its ``--param`` values
    (:func:`_checked_params`), for consumers that take a field as it is."""
    return _field_with(model, _checked_params(model, values, no_check_ranges))


def _field_with(model, params: dict[str, float]):
    """The field of a loaded model with parameter values already checked
    (:func:`_checked_params`)."""
    from .field import as_field

    return as_field(model, params, what="csdf", check_ranges=False)


def _note_compiling(*jobs: tuple[Any, tuple[str, ...]]) -> None:
    """Say on stderr, once and as the mesher does, that compiled kernels a command will
    use are not built yet (their first use on this machine takes seconds to a minute).

    Args:
        jobs: ``(field, modes)`` pairs: a :class:`csdf.field.Field` made as the
            consumer makes it (same backend policy) and the evaluation modes it uses
            (:meth:`csdf.field.Field.kernels_ready`).
    """
    from .field import kernel_cache_dir

    if not all(fld.kernels_ready(modes) for fld, modes in jobs):
        err.print(f"csdf: compiling kernels (first use only; cached in {kernel_cache_dir()})",
                  markup=False, highlight=False, soft_wrap=True)


def _fit_modes(estimate: str, solver: str, multistart: bool, debias: bool | None
               ) -> tuple[str, ...]:
    """The evaluation modes a ``csdf fit`` run certainly uses (so that the compiling
    notice is not repeated for a kernel that is never built): residual values; with
    ``lm``, gradients for the pose (parameter Jacobians too when parameters are
    estimated, and gradients again for the noise-bias correction and the multistart
    search); ``scipy`` uses the full Jacobian."""
    params = "params" in estimate
    if solver == "scipy":
        return ("value", "all")
    if not params:
        return ("value", "grad")
    return ("value", "all", "grad") if multistart or debias is not False else ("value", "all")


def _params(values: list[str]) -> dict[str, float]:
    out_: dict[str, float] = {}
    for item in values:
        name, sep, val = item.partition("=")
        if not sep or not name:
            raise CsdfError(f"--param expects name=value, got {item!r}")
        try:
            out_[name.strip()] = float(val)
        except ValueError:
            raise CsdfError(f"--param {name}: {val!r} is not a number") from None
    return out_


class Stopped(KeyboardInterrupt):
    """A command stopped by SIGINT or SIGTERM (raised on the main thread by the handlers
    that :func:`_signals` installs; a ``KeyboardInterrupt``, so that every ``finally``
    and atomic write cleans up on the way out).

    Attributes:
        signum: the signal's number.
    """

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum

    @property
    def status(self) -> int:
        """The shell's exit status for death by this signal: 128 + its number (130 for
        SIGINT, 143 for SIGTERM)."""
        return 128 + self.signum


#: seconds between re-deliveries of a stop request that some code swallowed (a library
#: that imports its optional dependencies under ``except BaseException``, as trimesh
#: does, takes a ``Stopped`` raised during that import for a missing package)
RESEND_S = 1.0
#: set by :func:`main`: the process is the ``csdf`` command, which exits at once after
#: a stop (its own clean-up done) instead of waiting for worker threads to finish
_AS_SCRIPT = False


class _StopRequest:
    """The stop request of one command run: the signal, and a daemon thread that sends
    it again every :data:`RESEND_S` seconds to the main thread until the command's
    :func:`_signals` block is left (by the ``Stopped`` exception, the normal way)."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.done = False
        self.lock = threading.Lock()
        self.main = threading.main_thread().ident

    def received(self, signum: int) -> None:
        with self.lock:
            first = self.signum is None
            self.signum = signum
        if first:
            threading.Thread(target=self._resend, name="csdf-stop", daemon=True).start()

    def _resend(self) -> None:
        while True:
            time.sleep(RESEND_S)
            with self.lock:  # (so the handlers are not restored between test and send)
                if self.done or self.signum is None:
                    return
                signal.pthread_kill(self.main, self.signum)

    def finish(self) -> None:
        with self.lock:
            self.done = True


@contextmanager
def _signals() -> Iterator[_StopRequest | None]:
    """While a command runs, SIGINT and SIGTERM raise :class:`Stopped` on the main
    thread (even where the process was started with them ignored, as a shell does for
    background jobs: a long ``csdf mesh`` must stop when asked), so that the work in
    progress stops at the main thread's next Python instruction (the mesher then drops
    the work queued on its threads), temporary files are removed, and the exit status
    says which signal it was. Where some code swallows the ``Stopped`` (it is raised
    wherever the main thread happens to be), the signal is sent again every
    :data:`RESEND_S` seconds until it stops the command. Yields the stop request
    (None off the main thread (tests, embedding), where nothing is installed)."""
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    wanted = [signal.SIGINT] + ([signal.SIGTERM] if hasattr(signal, "SIGTERM") else [])
    request = _StopRequest()

    def stop(signum: int, _frame: Any) -> None:
        request.received(signum)
        raise Stopped(signum)

    old = {}
    try:
        for sig in wanted:
            old[sig] = signal.signal(sig, stop)
        yield request
    finally:
        request.finish()
        for sig, handler in old.items():
            signal.signal(sig, handler)


def _run(fn: Callable[[], None]) -> None:
    """Run a command: a :class:`csdf.CsdfError` (or a stray ``OSError``) is printed as
    one message and exits with status 2; SIGINT and SIGTERM stop it cleanly with status
    130 or 143."""
    request = None
    try:
        with _signals() as request:
            fn()
    except CsdfError as exc:
        err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, markup=True,
                  soft_wrap=True)
        raise typer.Exit(2) from None
    except OSError as exc:  # (csdf's own writes and reads say CsdfError; a safety net)
        where = f"{exc.filename}: " if exc.filename else ""
        err.print(f"[bold red]error:[/] {escape(where + str(exc.strerror or exc))}",
                  highlight=False, markup=True, soft_wrap=True)
        raise typer.Exit(2) from None
    except Exception as exc:
        # a signal raised inside a compiled kernel's call comes out as a SystemError
        # ("returned a result with an exception set") caused by the Stopped
        stop = _stopped_by(exc)
        if stop is None and request is not None and request.signum is not None:
            # code that swallowed the Stopped then failed for want of what it was
            # doing (trimesh's import, interrupted, raised a TypeError of its own):
            # the failure is the signal's
            stop = Stopped(request.signum)
        if stop is None:
            raise
        _report_stop(stop)
    except Stopped as exc:
        _report_stop(exc)


def _stopped_by(exc: BaseException) -> Stopped | None:
    """The :class:`Stopped` in ``exc``'s chain of causes, or None."""
    stop = interrupt_in(exc)
    return stop if isinstance(stop, Stopped) else None


def _report_stop(stop: Stopped) -> None:
    """Say which signal stopped the command, and exit with its status (130, 143)."""
    name = signal.Signals(stop.signum).name
    err.print(f"[bold red]stopped:[/] {name} received; no partial output file was left",
              highlight=False, markup=True, soft_wrap=True)
    if _AS_SCRIPT:
        # the command's own clean-up is done (temporary files removed on the way out);
        # exit now rather than wait at shutdown for jobs already running on worker
        # threads, which may take many seconds (or a kernel's compilation)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(stop.status)
    raise typer.Exit(stop.status) from None


def _version(value: bool) -> None:
    if value:
        out.print(f"csdf {__version__}")
        raise typer.Exit()


@app.callback()
def main_options(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """csdf command line."""


@app.command()
def info(model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name.")):
    """Parameters, exactness, Lipschitz bound, bytecode sizes and Table-1 counts."""

    def go():
        fld = _field(_load(model))
        prog = fld.program
        out.print(f"[bold]{model.name}[/]: {len(prog)} instructions, "
                  f"{len(prog.params)} parameter(s), {prog.exactness}, "
                  f"Lipschitz {prog.lipschitz:g}")
        if prog.params:
            t = Table("parameter", "default", "range", title="parameters")
            for p in prog.params:
                rng = "unbounded" if math.isinf(p.lo) and math.isinf(p.hi) else \
                    f"[{p.lo:g}, {p.hi:g}]"
                t.add_row(p.name, f"{p.default:g}", rng)
            out.print(t)
        t = Table("level", "bytes", "add", "mul", "div", "call", "branch",
                  title="size and instruction counts (paper Table 1)")
        for level, size in (("expanded", prog.nbytes), ("primitive", prog.compact_nbytes())):
            c = prog.counts(level)
            t.add_row(level, str(size), *(str(c[k]) for k in ("add", "mul", "div", "call",
                                                               "branch")))
        out.print(t)
        bounds = fld.own_bounds
        if bounds is not None:
            out.print(f"bounds: {bounds[0].round(6).tolist()} .. {bounds[1].round(6).tolist()}")

    _run(go)


_SCHEDULER_HELP = ("Run on the Dask cluster at this scheduler address (tcp://host:8786; "
                   "needs the dask extra: pip install 'csdf[dask]').")
_WORKERS_HELP = "Run on a local Dask cluster of N worker processes (the dask extra)."


@contextmanager
def _cluster(scheduler: str | None, workers: int | None):
    """A Dask client for ``--scheduler``/``--workers`` (None when neither is given),
    closed afterwards."""
    if scheduler is None and workers is None:
        yield None
        return
    if scheduler is not None and workers is not None:
        raise CsdfError("give --scheduler or --workers, not both")
    from .distributed import connect, disconnect

    client = connect(scheduler=scheduler, workers=workers)
    try:
        yield client
    finally:
        disconnect(client)


@app.command()
def mesh(
    model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name."),
    output: Path = typer.Option(..., "-o", "--output", help="Mesh file: .stl .obj .ply .glb"),
    resolution: int | None = typer.Option(
        None, "--resolution", "-r", min=2, help="Voxels along the longest side (default: 128, "
        "or finer where the shape has thin parts, up to --max-resolution)."),
    voxel_size: float | None = typer.Option(None, "--voxel-size", callback=_positive,
                                            help="Voxel edge length."),
    method: str = typer.Option("mc", "--method", help="mc (marching cubes) or dc (dual "
                               "contouring: keeps sharp edges)."),
    max_resolution: int = typer.Option(1024, "--max-resolution", min=2,
                                       help="The finest default resolution."),
    min_feature: float | None = typer.Option(
        None, "--min-feature", callback=_positive,
        help="Thinnest part or gap to look for (model units; "
        "default 1/4 voxel)."),
    check_thin: bool = typer.Option(True, "--check-thin/--no-check-thin",
                                    help="Look for parts thinner than a voxel."),
    param: list[str] = typer.Option([], "--param", "-p", help="name=value (repeatable)."),
    no_check_ranges: bool = typer.Option(False, "--no-check-ranges", help=_NO_CHECK_HELP),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    scheduler: str | None = typer.Option(None, "--scheduler", help=_SCHEDULER_HELP + " "
                                         "Marching cubes only; no thin-part search; .ply "
                                         "and .stl are written by the workers (in a folder "
                                         "they see, else through the client)."),
    workers: int | None = typer.Option(None, "--workers", min=1, help=_WORKERS_HELP),
    colors: bool = typer.Option(False, "--colors", help="Vertex colours from the model's "
                                "color() nodes (kept by .ply, .glb and .obj)."),
    super_brick: int | None = typer.Option(None, "--super-brick", min=1, help="With --scheduler/"
                                           "--workers: voxels along every task's cube (a "
                                           "power of two; default: cubes of similar work, "
                                           "8 tasks per worker thread)."),
    fit_bounds: bool = typer.Option(False, "--fit-bounds", help="Sample planes a fiftieth "
                                    "of a voxel inside each face of the bounds, so that "
                                    "parts thinner than a voxel lying on them (a flange "
                                    "on a CAD part's cap) are kept."),
):
    """Mesh a model to a watertight triangle mesh."""

    def go():
        from . import io
        from .mesh import mesh as mesh_fn

        m = _param_field(_load(model), param, no_check_ranges)  # with the --param values
        t0 = time.perf_counter()
        if scheduler is not None or workers is not None:
            if fit_bounds:
                raise CsdfError("--fit-bounds meshes in this process; leave out "
                                "--scheduler/--workers")
            _mesh_on_cluster(m, t0)
            return
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeshWarning)
            result = mesh_fn(m, resolution=resolution, voxel_size=voxel_size,
                             method=method,
                             progress=not quiet and err.is_terminal,
                             max_resolution=max_resolution, min_feature=min_feature,
                             check_thin=check_thin, colors=colors,
                             fit_bounds=fit_bounds)
        dt = time.perf_counter() - t0
        for w in caught:
            if issubclass(w.category, MeshWarning):
                err.print(f"warning: {w.message}", soft_wrap=True, markup=False,
                          highlight=False)
            else:
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        if len(result.faces) == 0:
            raise CsdfError(f"{model}: the mesh is empty (no surface inside the bounds, or "
                            "only parts thinner than a voxel); nothing written")
        io.write_mesh(result, output)
        out.print(f"{output}: {len(result.faces):,} triangles, {len(result.vertices):,} "
                  f"vertices, watertight={result.is_watertight}, {dt:.2f} s "
                  f"(voxel {result.metadata['csdf']['voxel_size']:.4g})", soft_wrap=True)

    def _mesh_on_cluster(m, t0):
        from . import io
        from .distributed import mesh as dmesh

        if method != "mc":
            raise CsdfError("--scheduler/--workers mesh with marching cubes only (--method "
                            "mc)")
        stream = output.suffix.lower() in (".ply", ".stl")
        if output.suffix.lower() not in io.MESH_FORMATS:
            raise CsdfError(f"cannot tell the mesh format of {output.name!r}; use one of "
                            f"{', '.join(sorted(io.MESH_FORMATS))}")
        with _cluster(scheduler, workers) as client:
            result = dmesh(m, resolution=resolution, voxel_size=voxel_size, client=client,
                           out=output if stream else None, super_brick=super_brick,
                           progress=not quiet and err.is_terminal)
        dt = time.perf_counter() - t0
        if stream:
            tasks, faces, verts = result.tasks, result.faces, result.vertices
        else:
            if len(result.faces):
                io.write_mesh(result, output)
            tasks = result.metadata["csdf"]["tasks"]
            faces, verts = len(result.faces), len(result.vertices)
        if faces == 0:
            if stream:
                output.unlink(missing_ok=True)
            raise CsdfError(f"{model}: the mesh is empty (no surface inside the bounds, or "
                            "only parts thinner than a voxel); nothing written")
        out.print(f"{output}: {faces:,} triangles, {verts:,} vertices, {tasks} tasks, "
                  f"{dt:.2f} s", soft_wrap=True)

    _run(go)


@app.command(name="import")
def import_(
    model: Path = typer.Argument(..., help="An OpenSCAD .scad (needs the openscad program) "
                                 "or .csg file."),
    output: Path = typer.Option(..., "-o", "--output", help="The .csdf model to write."),
    facets: str = typer.Option("ideal", "--facets", help="ideal (true spheres, cylinders "
                               "and cones) or openscad (OpenSCAD's facets, from $fn, $fa "
                               "and $fs)."),
):
    """Convert an OpenSCAD model to a readable .csdf model (shapes used more than once
    bound with let)."""

    def go():
        from .io import atomic_path
        from .lang import dumps
        from .lang.csg import load_csg, load_scad

        suffix = model.suffix.lower()
        if suffix not in (".scad", ".csg"):
            raise CsdfError(f"{model}: csdf import reads .scad or .csg files")
        if output.suffix.lower() != ".csdf":
            raise CsdfError(f"{output}: the output must end in .csdf")
        shape = load_scad(model, facets) if suffix == ".scad" else load_csg(model, facets)
        text = f"# imported from {model.name} by csdf import\n" + dumps(shape)
        with atomic_path(output) as tmp:
            tmp.write_text(text, encoding="utf-8")
        out.print(f"{output}: {shape.exactness} distance, "
                  f"{len(shape.compile())} instructions", soft_wrap=True)

    _run(go)


@app.command()
def compile(  # noqa: A001 - the verb users type
    model: Path = typer.Argument(..., help="A .csdf model (or .vm field)."),
    output: Path = typer.Option(..., "-o", "--output", help=".csdfb (bytecode), .csdft "
                                "(text listing) or .vm (Fidget's format)."),
):
    """Compile a model to bytecode (.csdfb), a readable listing (.csdft) or Fidget's .vm."""

    def go():
        from .io import atomic_path

        prog = _field(_load(model)).program
        suffix = output.suffix.lower()
        if suffix not in (".csdfb", ".csdft", ".vm"):
            raise CsdfError(f"{output}: the output must end in .csdfb, .csdft or .vm")
        if suffix == ".vm":
            from .io import save_vm

            save_vm(prog, output)
            out.print(f"{output}: {len(prog)} instructions as Fidget .vm", soft_wrap=True)
            return
        with atomic_path(output) as tmp:
            if suffix == ".csdfb":
                tmp.write_bytes(prog.to_bytes())
            else:
                tmp.write_text(prog.disassemble())
        out.print(f"{output}: {len(prog)} instructions, {prog.nbytes} bytes", soft_wrap=True)

    _run(go)


@app.command()
def export(
    model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name."),
    glsl: bool = typer.Option(False, "--glsl", help="A Shadertoy-ready GLSL image shader."),
    c: bool = typer.Option(False, "--c", help="A self-contained C header: value, and value "
                           "with gradient and parameter derivatives, in double and float."),
    numpy: bool = typer.Option(False, "--numpy", help="A Python module that needs NumPy "
                               "only: value(points) and value_and_grad(points)."),
    name: str = typer.Option("sdf", "--name", help="With --c/--numpy: the function and "
                             "type name prefix (a C identifier)."),
    snippet: bool = typer.Option(False, "--snippet", help="With --glsl: only the sdf "
                                 "function and its uniforms, for your own shader."),
    output: Path | None = typer.Option(None, "-o", "--output", help="File (default: "
                                          "standard output)."),
):
    """Export a model for other tools (--glsl: Shadertoy; --c: a C header; --numpy: a
    NumPy module)."""

    def go():
        from .field import shadertoy, to_c, to_glsl, to_numpy
        from .io import atomic_path

        if sum((glsl, c, numpy)) != 1:
            raise CsdfError("choose one export format: --glsl, --c or --numpy")
        m = _load(model)
        if glsl:
            text, what = (to_glsl(m) if snippet else shadertoy(m)), "GLSL"
        elif c:
            text, what = to_c(m, name), "C"
        else:
            text, what = to_numpy(m, name), "Python (NumPy)"
        if output is None:
            sys.stdout.write(text)
            return
        with atomic_path(output) as tmp:
            tmp.write_text(text)
        err.print(f"{output}: {len(text.splitlines())} lines of {what}", soft_wrap=True)

    _run(go)


@app.command()
def fit(
    model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name."),
    scan: Path = typer.Argument(..., help="The point cloud (.ply), or a folder of them "
                                "(every *.ply in it, fitted one task each; the result "
                                "file then lists them)."),
    output: Path = typer.Option(..., "-o", "--output", help="Result file (.json)."),
    estimate: str = typer.Option("pose", "--estimate", help="pose, pose,scale or "
                                 "pose,scale,params"),
    multistart: bool = typer.Option(False, "--multistart", help="Search all rotations "
                                    "first (for large initial errors)."),
    loss: str = typer.Option("auto", "--loss", help="auto (Huber, then Cauchy when many "
                             "points are outliers), huber, cauchy, soft_l1, arctan, linear."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the multistart subsampling."),
    viewpoint: str | None = typer.Option(None, "--viewpoint", help="x,y,z: the sensor "
                                         "position of a single-view scan (0,0,0 for "
                                         "camera-frame clouds); points are then matched to "
                                         "surfaces facing it. Default: the position the "
                                         "PLY header records ('comment csdf viewpoint X Y "
                                         "Z', written by csdf scan); 'none' ignores it."),
    solver: str = typer.Option("lm", "--solver", help="lm (robust Levenberg-Marquardt) or "
                               "scipy (least_squares)."),
    escape: bool = typer.Option(True, "--escape/--no-escape", help="Test turns about the "
                                "model's and the cloud's axes for a lower minimum."),
    debias: bool | None = typer.Option(None, "--debias/--no-debias", help="Correct the noise "
                                       "bias of estimated parameters (default: on when "
                                       "parameters are estimated)."),
    param: list[str] = typer.Option([], "--param", "-p", help="Initial name=value "
                                    "(repeatable)."),
    no_check_ranges: bool = typer.Option(False, "--no-check-ranges", help=_NO_CHECK_HELP),
    overlay: Path | None = typer.Option(None, "--overlay", help="Also write a PNG of the "
                                        "fitted model with the points drawn over it "
                                        "(green: inliers, red: outliers)."),
    scheduler: str | None = typer.Option(None, "--scheduler", help=_SCHEDULER_HELP + " "
                                         "For a folder of scans."),
    workers: int | None = typer.Option(None, "--workers", min=1, help=_WORKERS_HELP),
):
    """Recover the model's pose (and scale, parameters) from a point cloud."""

    def many():
        import json

        from .distributed import FitFailure, fit_many
        from .io import atomic_path, read_point_cloud

        if overlay is not None:
            raise CsdfError("--overlay draws one fit; give one scan, not a folder")
        scans = sorted(p for p in scan.iterdir() if p.suffix.lower() == ".ply")
        if not scans:
            raise CsdfError(f"{scan}: the folder holds no .ply point clouds")
        m = _load(model)
        init_params = _checked_params(m, param, no_check_ranges)
        clouds = []
        for path in scans:  # read here: the workers need not share this file system
            try:
                clouds.append(read_point_cloud(path))
            except CsdfError as exc:
                clouds.append(exc)
        kwargs = dict(init={"params": init_params} if param else None, estimate=estimate,
                      multistart=multistart, loss=loss, seed=seed, solver=solver,
                      escape=escape, debias=debias, check_ranges=not no_check_ranges)
        if viewpoint is not None:  # else each scan's recorded viewpoint
            kwargs["viewpoint"], _ = _cloud_viewpoint(viewpoint, None, scan)
        good = [c for c in clouds if not isinstance(c, CsdfError)]
        if scheduler is None and workers is None:
            from .distributed.tasks import fit_task
            from .field import as_field

            blob = as_field(m).program.to_bytes()
            raw = [fit_task(blob, c, kwargs) for c in good]
            results = [FitFailure(i, "point cloud", *r) if isinstance(r, tuple) else r
                       for i, r in enumerate(raw)]
        else:
            with _cluster(scheduler, workers) as client:
                results = fit_many(m, good, client=client, progress=err.is_terminal,
                                   **kwargs)
        it = iter(results)
        records, ok = [], 0
        for path, c in zip(scans, clouds):
            r = FitFailure(0, str(path), "CsdfError", str(c)) if isinstance(
                c, CsdfError) else next(it)
            if isinstance(r, FitFailure):
                records.append({"scan": str(path), "error": r.error, "message": r.message})
                out.print(f"{path}: failed: {r.message}", soft_wrap=True, markup=False)
                continue
            ok += bool(r.success)
            records.append({"scan": str(path), **r.to_dict()})
        with atomic_path(output) as tmp:
            tmp.write_text(json.dumps({"model": str(model), "fits": records}, indent=2))
        out.print(f"{output}: {len(scans)} scans, {ok} fitted with success", soft_wrap=True)

    def go():
        import json

        if scan.is_dir():
            many()
            return

        from .field import as_field
        from .fit import check_fit
        from .fit import fit as fit_fn
        from .io import atomic_path, read_point_cloud
        from .render.trace import trace_field

        if overlay is not None and overlay.suffix.lower() != ".png":
            raise CsdfError(f"{overlay}: the overlay must end in .png")
        m = _load(model)
        init_params = _checked_params(m, param, no_check_ranges)
        cloud = read_point_cloud(scan)
        pts = cloud.points
        vp, source = _cloud_viewpoint(viewpoint, cloud, scan)
        # solver='scipy' has no visibility term: the viewpoint then serves the success
        # test only
        fit_vp = vp if solver != "scipy" or source == "--viewpoint" else None
        fld = as_field(m, backend="auto", work=len(pts), what="csdf")  # as fit makes it
        jobs = [(fld, _fit_modes(estimate, solver, multistart, debias))]
        if vp is not None:  # the success test traces the model's visible surface (a sweep)
            jobs.append((trace_field(m, init_params, what="fit", check_ranges=False),
                         ("value", "grad")))
        _note_compiling(*jobs)
        res = fit_fn(m, pts, init={"params": init_params} if param else None,
                     estimate=estimate, multistart=multistart, loss=loss, seed=seed,
                     viewpoint=fit_vp, solver=solver, escape=escape, debias=debias,
                     check_ranges=not no_check_ranges)
        if vp is not None and fit_vp is None:
            res = check_fit(m, pts, res, viewpoint=vp)
        record = res.to_dict()
        record["viewpoint"] = None if vp is None else list(vp)
        record["viewpoint_source"] = source
        if not res.success:
            record["warning"] = ("the fit does not explain the cloud: "
                                 + "; ".join(res.quality.get("reasons", [])))
        with atomic_path(output) as tmp:
            tmp.write_text(json.dumps(record, indent=2))
        if vp is None:
            out.print(f"viewpoint: {source}", soft_wrap=True, markup=False)
        else:
            where = ",".join(f"{v:g}" for v in vp)
            out.print(f"viewpoint: {where} (from {source})", soft_wrap=True, markup=False)
        out.print(f"{output}: rmse {res.rmse:.3g}, inliers {res.inlier_fraction:.1%}, "
                  f"scale {res.scale:.4g}, {res.iterations} evaluations, "
                  f"{res.seconds * 1e3:.0f} ms, converged={res.converged}, "
                  f"success={res.success}", soft_wrap=True)
        for note in res.notes:
            out.print(f"note: {note}", soft_wrap=True)
        if not res.success:
            out.print(f"warning: {record['warning']}", soft_wrap=True, markup=False)
            if not multistart:
                out.print("hint: one start (the model unrotated, centred on the cloud) can "
                          "end in a wrong minimum; try --multistart", soft_wrap=True,
                          markup=False)
        if overlay is not None:
            from .render.overlay import fit_overlay

            _write_png(overlay, fit_overlay(m, pts, res, check_ranges=not no_check_ranges))
            out.print(f"{overlay}: overlay of the fit", soft_wrap=True)

    _run(go)


@app.command()
def sample(
    model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name."),
    output: Path = typer.Option(..., "-o", "--output", help="Point cloud file (.ply)."),
    count: int = typer.Option(100_000, "-n", "--count", min=0, help="Number of points."),
    volume: bool = typer.Option(False, "--volume", help="Points in and around the shape "
                                "with a 'distance' property (default: surface points "
                                "with normals)."),
    near: float = typer.Option(0.5, "--near", min=0.0, max=1.0,
                               help="With --volume: fraction of points "
                               "near the surface."),
    sigma: float | None = typer.Option(None, "--sigma", callback=_non_negative,
                                       help="With --volume: offset "
                                       "standard deviation (default 1% of the "
                                       "bounding-box diagonal)."),
    seed: int | None = typer.Option(None, "--seed", min=0, help="Random seed."),
    ascii_: bool = typer.Option(False, "--ascii", help="Write ASCII PLY."),
    param: list[str] = typer.Option([], "--param", "-p", help="name=value (repeatable)."),
    no_check_ranges: bool = typer.Option(False, "--no-check-ranges", help=_NO_CHECK_HELP),
    scheduler: str | None = typer.Option(None, "--scheduler", help=_SCHEDULER_HELP + " "
                                         "Tasks of --chunk points, from child seeds of "
                                         "--seed."),
    workers: int | None = typer.Option(None, "--workers", min=1, help=_WORKERS_HELP),
    chunk: int = typer.Option(1_000_000, "--chunk", min=1, help="With --scheduler/--workers: "
                              "points per task."),
):
    """Sample points uniformly on a model's surface (with normals), or in its volume
    (with field values)."""

    def go():
        from .io import write_points
        from .sample import sample_surface, sample_volume

        if output.suffix.lower() != ".ply":
            raise CsdfError(f"{output}: the output must end in .ply")
        m = _load(model)
        params = _checked_params(m, param, no_check_ranges)
        t0 = time.perf_counter()
        if scheduler is not None or workers is not None:
            from . import distributed as dist

            with _cluster(scheduler, workers) as client:
                if volume:
                    a, b = dist.sample_volume(m, count, near_surface=near, sigma=sigma,
                                              seed=seed, params=params, chunk=chunk,
                                              check_ranges=False)
                else:
                    a, b = dist.sample_surface(m, count, seed=seed, params=params,
                                               chunk=chunk, check_ranges=False)
                pts, other = client.compute([a, b], sync=True)
            if volume:
                write_points(output, pts, scalars={"distance": other}, ascii=ascii_)
            else:
                write_points(output, pts, other, ascii=ascii_)
        elif volume:
            pts, d = sample_volume(m, count, near_surface=near, sigma=sigma, seed=seed,
                                   params=params, check_ranges=False)  # checked above
            write_points(output, pts, scalars={"distance": d}, ascii=ascii_)
        else:
            pts, nrm = sample_surface(m, count, seed=seed, params=params,
                                      check_ranges=False)
            write_points(output, pts, nrm, ascii=ascii_)
        out.print(f"{output}: {len(pts):,} {'volume' if volume else 'surface'} points, "
                  f"{time.perf_counter() - t0:.2f} s", soft_wrap=True)

    _run(go)


@app.command(name="slice")
def slice_(
    model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name."),
    output: Path = typer.Option(..., "-o", "--output", help="Image: .png .pdf .svg"),
    axis: str = typer.Option("z", "--axis", help="Normal of the plane: x, y or z."),
    at: float = typer.Option(0.0, "--at", help="Coordinate of the plane along the axis."),
    resolution: int = typer.Option(400, "--resolution", "-r",
                                   help="Samples along the longer side."),
    gradient_error: bool = typer.Option(False, "--gradient-error",
                                        help="Add a panel of |grad f| - 1."),
    param: list[str] = typer.Option([], "--param", "-p", help="name=value (repeatable)."),
    no_check_ranges: bool = typer.Option(False, "--no-check-ranges", help=_NO_CHECK_HELP),
):
    """Plot the distance field on a plane: filled values, isolines, the surface in bold."""

    def go():
        from .slicing import save_slice

        m = _load(model)
        params = _checked_params(m, param, no_check_ranges)
        # the field as slice makes it (a sweep)
        _note_compiling((_field_with(m, params),
                         ("value", "grad") if gradient_error else ("value",)))
        save_slice(m, output, axis=axis, at=at, resolution=resolution,
                   show_gradient_error=gradient_error, params=params,
                   check_ranges=False)  # checked above
        out.print(f"{output}: slice {axis} = {at:g}", soft_wrap=True)

    _run(go)


@app.command()
def raster(
    model: Path = typer.Argument(..., help="A 2D model: .csdf, .vm, .csdfb or .csdft."),
    output: Path = typer.Option(..., "-o", "--output", help="Image: .png"),
    size: str = typer.Option("1024x1024", "--size", help="WIDTHxHEIGHT in pixels."),
    bounds: str | None = typer.Option(None, "--bounds", help="x0,y0,x1,y1 the image "
                                      "covers (default: the shape's own box)."),
    param: list[str] = typer.Option([], "--param", "-p", help="name=value (repeatable)."),
    no_check_ranges: bool = typer.Option(False, "--no-check-ranges", help=_NO_CHECK_HELP),
):
    """Rasterise a 2D field: black where it is negative (inside), white elsewhere; row 0
    at the top of the bounds (a quadtree of tiles with shortened programs)."""

    def go():
        import numpy as np
        from PIL import Image

        from .io import atomic_path
        from .raster import raster as raster_fn

        if output.suffix.lower() != ".png":
            raise CsdfError(f"{output}: the output must end in .png")
        w, h = _size(size)
        v = _numbers(bounds, "--bounds", "x0,y0,x1,y1")
        box = None if v is None else ((v[0], v[1]), (v[2], v[3]))
        fld = _param_field(_load(model), param, no_check_ranges)
        t0 = time.perf_counter()
        inside = raster_fn(fld, w, h, box)
        dt = time.perf_counter() - t0
        with atomic_path(output) as tmp:
            Image.fromarray(np.where(inside, 0, 255).astype(np.uint8)).save(tmp, "PNG")
        out.print(f"{output}: {w}x{h}, {inside.mean():.1%} inside, {dt:.2f} s",
                  soft_wrap=True)

    _run(go)


@app.command()
def plan(
    scene: Path = typer.Argument(..., help="A scene file (.json, csdf.Scene.save)."),
    robot: Path = typer.Argument(..., help="The robot: a URDF file."),
    start: str = typer.Option(..., "--start", help="Joint positions q1,q2,... (rad, m)."),
    goal: str = typer.Option(..., "--goal", help="Joint positions q1,q2,... (rad, m)."),
    output: Path = typer.Option(..., "-o", "--output", help="The trajectory: .json"),
    waypoints: int = typer.Option(32, "--waypoints", min=2, help="Waypoints, both ends included."),
    margin: float = typer.Option(0.05, "--margin", callback=_non_negative,
                                 help="Clearance asked of the robot (m)."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the restarts' detours."),
    srdf: Path | None = typer.Option(None, "--srdf", help="An SRDF whose "
                                     "disabled collisions self-collision leaves out."),
    lock: list[str] = typer.Option([], "--lock", help="joint=value: hold a joint still "
                                   "(repeatable; e.g. a gripper's finger)."),
):
    """Plan a robot's path between two joint positions among a scene's objects
    (csdf.plan.optimize) and write it as JSON: waypoints, success, clearance, time."""

    def go():
        import json

        from .io import atomic_path
        from .plan import Robot, optimize
        from .scene import Scene

        if output.suffix.lower() != ".json":
            raise CsdfError(f"{output}: the output must end in .json")
        sc = Scene.load(scene)
        held = {}
        for item in lock:
            name, eq, value = item.partition("=")
            try:
                held[name.strip()] = float(value)
            except ValueError:
                eq = ""
            if not eq or not name.strip():
                raise CsdfError(f"--lock {item!r}: expected joint=value")
        bot = Robot.from_urdf(robot, srdf=srdf, lock=held)
        names = ",".join(f"q{k + 1}" for k in range(bot.dof))
        qs = _numbers(start, "--start", names)
        qg = _numbers(goal, "--goal", names)
        tr = optimize(sc, bot, qs, qg, n_waypoints=waypoints, margin=margin, seed=seed)
        doc = {"robot": bot.name, "joints": bot.joint_names, "success": tr.success,
               "min_clearance": tr.min_clearance, "seconds": tr.seconds,
               "attempts": tr.attempts, "length": tr.length, "q": tr.q.tolist()}
        with atomic_path(output) as tmp:
            tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        verdict = "clear" if tr.success else "NOT clear (best attempt written)"
        out.print(f"{output}: {len(tr.q)} waypoints, {verdict}, min clearance "
                  f"{tr.min_clearance:.4f} m, {tr.seconds:.2f} s", soft_wrap=True)
        if not tr.success:
            raise typer.Exit(1)

    _run(go)


def _camera_file(path: Path, size: tuple[int, int] | None):
    """A camera from JSON: ``{"fx", "fy", "cx", "cy", "width", "height"}`` or
    ``{"cam_K": [9 numbers], "width", "height"}`` (size default: the frames')."""
    import json

    from .render import Camera

    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CsdfError(f"cannot read {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise CsdfError(f"{path}: line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
    if not isinstance(doc, dict):
        raise CsdfError(f"{path}: a camera must be a JSON object")
    try:
        if "cam_K" in doc:
            K = [float(v) for v in doc["cam_K"]]
            if len(K) != 9:
                raise ValueError
            fx, fy, cx, cy = K[0], K[4], K[2], K[5]
        else:
            fx, fy, cx, cy = (float(doc[k]) for k in ("fx", "fy", "cx", "cy"))
        w = int(doc.get("width", size[0] if size else 0))
        h = int(doc.get("height", size[1] if size else 0))
    except (KeyError, TypeError, ValueError):
        raise CsdfError(f"{path}: a camera needs fx, fy, cx, cy (or cam_K, 9 numbers) and "
                        "width, height") from None
    return Camera(fx, fy, cx, cy, w, h)


def _bop_pose(entry: dict, where: str, mm_per_unit: float):
    import numpy as np

    from .pose import Pose

    try:
        R = np.asarray([float(v) for v in entry["cam_R_m2c"]]).reshape(3, 3)
        t = np.asarray([float(v) for v in entry["cam_t_m2c"]]) / mm_per_unit
        if t.shape != (3,) or not (np.isfinite(R).all() and np.isfinite(t).all()):
            raise ValueError
    except (KeyError, TypeError, ValueError):
        raise CsdfError(f"{where}: needs cam_R_m2c (9 finite numbers, row-major) and "
                        "cam_t_m2c (3, mm)") from None
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-3 or np.linalg.det(R) < 0:
        raise CsdfError(f"{where}: cam_R_m2c is not a rotation (orthonormal, determinant +1)")
    return Pose.nearest(np.block([[R, t[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]),
                        where)


@app.command()
def track(
    model: Path = typer.Argument(..., help="A .csdf model (or program), or a zoo name."),
    frames: Path = typer.Argument(..., help="A BOP-layout scene folder: scene_camera.json, "
                                  "depth/*.png, optional mask_visib/ (csdf.io.write_bop)."),
    output: Path = typer.Option(..., "-o", "--output", help="The poses: .json"),
    camera: Path | None = typer.Option(None, "--camera", help="Intrinsics (JSON: fx, fy, "
                                       "cx, cy or cam_K); default scene_camera.json's."),
    init: Path | None = typer.Option(None, "--init", help="The first frame's pose: JSON "
                                     "with cam_R_m2c and cam_t_m2c (mm), or a BOP "
                                     "scene_gt.json (its first image). Default: a search "
                                     "over rotations (multistart) on the first frame."),
    masks: bool = typer.Option(True, "--masks/--no-masks", help="Use mask_visib/ (the "
                               "silhouette term) when the folder has it."),
    estimate: str = typer.Option("pose", "--estimate", help="pose or pose,params"),
    mm_per_unit: float = typer.Option(1000.0, "--mm-per-unit", callback=_positive,
                                      help="Millimetres per "
                                      "model unit (1000: a model in metres)."),
    colors: bool = typer.Option(True, "--colors/--no-colors", help="Use rgb/ (the "
                                "region-based colour term) when the folder has it."),
):
    """Track a model through depth frames (csdf.track) and write each frame's
    model-to-camera pose (BOP conventions: cam_R_m2c row-major, cam_t_m2c in mm)."""

    def go():
        import json

        import numpy as np

        from .fit import track as track_fn
        from .io import atomic_path
        from .io.bop import read_frames, read_rgb

        if output.suffix.lower() != ".json":
            raise CsdfError(f"{output}: the output must end in .json")
        m = _load(model)
        depth, mk, cam, ids = read_frames(frames, mm_per_unit=mm_per_unit)
        if camera is not None:
            cam = _camera_file(camera, (cam.width, cam.height))
            if (cam.width, cam.height) != (depth.shape[2], depth.shape[1]):
                raise CsdfError(f"{camera}: {cam.width}x{cam.height} pixels, but the "
                                f"frames are {depth.shape[2]}x{depth.shape[1]}")
        if init is None:
            from .fit import fit_depth

            first = fit_depth(m, depth[0], cam, mask=None if mk is None or not masks
                              else mk[0], multistart=True)
            start = first
        else:
            try:
                doc = json.loads(init.read_text(encoding="utf-8"))
            except (OSError, json.JSONDecodeError) as exc:
                raise CsdfError(f"{init}: not readable JSON ({exc})") from None
            if isinstance(doc, dict) and "cam_R_m2c" not in doc and doc:
                key = sorted(doc, key=lambda k: int(k) if str(k).isdigit() else 0)[0]
                entry = doc[key][0] if isinstance(doc[key], list) and doc[key] else doc[key]
                where = f"{init}: image {key!r}"
            else:
                entry, where = doc, str(init)
            if not isinstance(entry, dict):
                raise CsdfError(f"{where}: a pose must be a JSON object with cam_R_m2c "
                                "(9 numbers) and cam_t_m2c (3, mm)")
            start = _bop_pose(entry, where, mm_per_unit)
        run = track_fn(m, list(depth), cam, start,
                       masks=None if mk is None or not masks else list(mk),
                       estimate=estimate,
                       colors=read_rgb(frames, ids, (cam.width, cam.height)) if colors
                       else None)
        doc = {"model": str(model), "frames": []}
        for k, fr in zip(ids, run.frames):
            doc["frames"].append({
                "image_id": k, "cam_R_m2c": fr.pose.rotation.ravel().tolist(),
                "cam_t_m2c": (fr.pose.translation * mm_per_unit).tolist(),
                "success": fr.success, "lost": fr.lost,
                "reinitialised": fr.reinitialised, "rmse": fr.rmse,
                "params": fr.params, "seconds": fr.seconds})
        with atomic_path(output) as tmp:
            tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        ok = run.success
        out.print(f"{output}: {len(run)} frames, {ok.mean():.0%} explained, "
                  f"{sum(f.lost for f in run.frames)} lost, median "
                  f"{np.median(run.seconds) * 1e3:.1f} ms a frame", soft_wrap=True)

    _run(go)


@app.command()
def infer(
    scan: Path = typer.Argument(..., help="The point cloud (.ply) of one object."),
    output: Path = typer.Option(..., "-o", "--output", help="The inferred model (.csdf)."),
    max_primitives: int = typer.Option(8, "--max-primitives", min=1, max=32,
                                       help="The most primitives "
                                       "in the tree."),
    time_limit: float = typer.Option(30.0, "--time-limit", callback=_positive,
                                     help="Seconds for the "
                                     "structure search (the best tree found by then)."),
    kinds: str = typer.Option("box,cylinder,sphere,cone,torus", "--kinds",
                              help="The primitive kinds to use."),
    viewpoint: str | None = typer.Option(None, "--viewpoint", help="x,y,z: the sensor "
                                         "position of a single-view scan. Default: the PLY "
                                         "header's record (csdf scan writes it); 'none' "
                                         "ignores it."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every random choice."),
    prefer: str | None = typer.Option(None, "--prefer", callback=_prefer,
                                      help="Of the trees the points "
                                      "cannot tell apart: 'local' (trims and cuts reach "
                                      "the fewest primitives) or 'global' (the most). "
                                      "Default: the search's own."),
):
    """Infer a CSG model of csdf primitives (csdf.infer) from a point cloud and write it
    as a .csdf model with named parameters."""

    def go():
        from .infer import infer as infer_fn
        from .io import atomic_path, check_writable, read_point_cloud

        if output.suffix.lower() != ".csdf":
            raise CsdfError(f"{output}: the output must end in .csdf")
        check_writable(output)
        cloud = read_point_cloud(scan)
        P, N = _cloud_arrays(cloud, scan)
        vp, source = _cloud_viewpoint(viewpoint, cloud, scan)
        res = infer_fn(P, N, max_primitives=max_primitives,
                       kinds=kinds, viewpoint=vp, time_limit=time_limit, seed=seed,
                       prefer=prefer)
        others = [a for a in res.alternatives if a != res.tree]
        header = (f"# inferred by csdf infer from {scan.name}: {len(res.primitives)} "
                  f"primitives, rmse {res.rmse:.4g}, {res.inlier_fraction:.1%} of the "
                  f"points within the noise\n# structure: {res.tree}\n" +
                  "".join(f"# or, the points cannot tell: {a}\n" for a in others))
        with atomic_path(output) as tmp:
            tmp.write_text(header + res.text)
        out.print(f"{output}: {res.tree}", soft_wrap=True, markup=False)
        out.print(f"{len(res.primitives)} primitives from {res.candidates} candidates, "
                  f"rmse {res.rmse:.4g}, {res.inlier_fraction:.1%} inliers, "
                  f"{res.seconds:.1f} s (viewpoint: {source})", soft_wrap=True,
                  markup=False)
        if res.inlier_fraction < INFER_FEW_INLIERS:
            out.print(f"note: the model explains only {res.inlier_fraction:.0%} of the "
                      "points" + ("; a single-view scan needs --viewpoint (its hidden side "
                                  "is otherwise taken for free space)" if vp is None
                                  else ""), soft_wrap=True, markup=False)

    _run(go)


@app.command()
def detect(
    scan: Path = typer.Argument(..., help="The point cloud (.ply), e.g. from csdf scan."),
    models: str = typer.Option(..., "--models", help="Comma-separated zoo names or .csdf "
                               "files to look for, e.g. chair,table,stool."),
    output: Path = typer.Option(..., "-o", "--output", help="The scene file (.json): one "
                                "instance per detection, readable by csdf.Scene.load."),
    viewpoint: str | None = typer.Option(None, "--viewpoint", help="x,y,z: the sensor "
                                         "position (0,0,0 for camera-frame clouds). "
                                         "Default: the PLY header's record (csdf scan "
                                         "writes it); 'none' ignores it."),
    max_instances: int | None = typer.Option(None, "--max-instances", min=1, help="Stop after "
                                             "this many detections."),
    noise: float | None = typer.Option(None, "--noise", callback=_positive,
                                       help="The scan's noise standard "
                                       "deviation (default: estimated)."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of every random choice."),
    picture: Path | None = typer.Option(None, "--picture", help="Also write a PNG: the "
                                        "scan with each detection's model drawn over it."),
    keep_unsettled: bool = typer.Option(False, "--keep-unsettled", help="Also keep the "
                                        "detections whose turn about the floor's normal "
                                        "(or their own up axis) the scan does not "
                                        "settle (a lamp whose spokes were not seen, a "
                                        "bookshelf seen side-on): the object is there, "
                                        "its turn a guess."),
):
    """Find known models in a cluttered scan (csdf.detect) and write them as a scene."""

    def go():
        from .detect import detect as detect_fn
        from .detect import detections_to_scene
        from .io import check_writable, read_point_cloud

        if output.suffix.lower() != ".json":
            raise CsdfError(f"{output}: the output must end in .json")
        if picture is not None and picture.suffix.lower() != ".png":
            raise CsdfError(f"{picture}: the picture must end in .png")
        check_writable(output)
        if picture is not None:
            check_writable(picture)
        cloud = read_point_cloud(scan)
        if len(cloud.points) == 0:
            raise CsdfError(f"{scan}: the scan has no points")
        P, N = _cloud_arrays(cloud, scan)
        vp, _ = _cloud_viewpoint(viewpoint, cloud, scan)
        t0 = time.perf_counter()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            dets = detect_fn(P, models, normals=N, viewpoint=vp,
                             max_instances=max_instances, seed=seed, noise=noise,
                             keep_unsettled=True)
        seconds = time.perf_counter() - t0
        unsettled = sum(not d.settled for d in dets)
        if not keep_unsettled:
            dets = [d for d in dets if d.settled]
        img = None
        if picture is not None:
            from .detect.picture import detections_picture

            img = detections_picture(cloud.points, dets, vp)
        detections_to_scene(dets).save(output)
        table = Table("model", "position", "score", "points", "turn")
        for d in dets:
            table.add_row(d.model, ", ".join(f"{v:.3f}" for v in d.pose.translation),
                          f"{d.score:.2f}", str(len(d.inliers)),
                          "settled" if d.settled else "unsettled")
        out.print(table)
        out.print(f"{output}: {len(dets)} detections in {seconds:.2f} s"
                  + ("" if vp is not None else " (no viewpoint: free space not checked; "
                     "give --viewpoint for a single-view scan)"), soft_wrap=True)
        if unsettled and not keep_unsettled:
            out.print(f"note: {unsettled} more detection(s) left out: the scan does not "
                      f"settle their turn (--keep-unsettled keeps them)", soft_wrap=True)
        for w in caught:
            if str(w.message).startswith("detect found nothing"):
                out.print(f"note: {w.message}", soft_wrap=True, markup=False)
            else:
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        if picture is not None:
            _write_png(picture, img)
            out.print(f"{picture}: the scan with the detections", soft_wrap=True)

    _run(go)


@app.command()
def metrics(
    model: Path = typer.Argument(..., help="A .csdf model (or program), or a zoo name."),
    truth: Path = typer.Argument(..., help="A BOP-layout scene folder with scene_gt.json "
                                 "(and depth/ for VSD)."),
    estimates: Path = typer.Argument(..., help="Poses: csdf track's JSON, or a BOP "
                                     "scene_gt.json of estimates."),
    output: Path | None = typer.Option(None, "-o", "--output", help="Also write the "
                                       "errors and recalls as JSON."),
    mm_per_unit: float = typer.Option(1000.0, "--mm-per-unit", callback=_positive,
                                      help="Millimetres per "
                                      "model unit (1000: a model in metres)."),
    vsd: bool = typer.Option(True, "--vsd/--no-vsd", help="Compute VSD (renders the model "
                             "twice per image)."),
):
    """Score pose estimates against ground truth with the BOP 2019 metrics (VSD, MSSD,
    MSPD and their average recalls) and ADD-S (csdf.metrics)."""

    def go():
        import json

        import numpy as np

        from . import metrics as M
        from .io import atomic_path
        from .io.bop import read_bop

        m = _load(model)
        seq = read_bop(truth, mm_per_unit=mm_per_unit)
        try:
            doc = json.loads(estimates.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise CsdfError(f"{estimates}: not readable JSON ({exc})") from None
        if isinstance(doc, dict) and isinstance(doc.get("frames"), list):
            est = {int(f["image_id"]): _bop_pose(f, f"{estimates}: image {f.get('image_id')}",
                                                 mm_per_unit)
                   for f in doc["frames"] if isinstance(f, dict) and "image_id" in f}
        elif isinstance(doc, dict):
            est = {}
            for key, entries in doc.items():
                if not str(key).isdigit():
                    raise CsdfError(f"{estimates}: key {key!r} is not an image id; expected "
                                    "csdf track's JSON or a scene_gt.json (image id -> "
                                    "[{cam_R_m2c, cam_t_m2c}])")
                e = entries[0] if isinstance(entries, list) and entries else entries
                if not isinstance(e, dict):
                    raise CsdfError(f"{estimates}: image {key!r}: expected an object with "
                                    "cam_R_m2c and cam_t_m2c")
                est[int(key)] = _bop_pose(e, f"{estimates}: image {key!r}", mm_per_unit)
        else:
            raise CsdfError(f"{estimates}: expected csdf track's JSON or a scene_gt.json")
        gt_ids = sorted(json.loads((truth / "scene_gt.json").read_text()), key=int)
        extra = sorted(set(est) - {int(k) for k in gt_ids})
        if extra:
            err.print(f"warning: {estimates} has poses for images the truth does not list "
                      f"({', '.join(map(str, extra[:5]))}{' ...' if len(extra) > 5 else ''}"
                      "); they are not scored", soft_wrap=True, markup=False)
        if not set(est) & {int(k) for k in gt_ids}:
            raise CsdfError(f"{estimates}: no pose for any image of {truth}")
        if isinstance(doc, dict) and isinstance(doc.get("model"), str) \
                and Path(doc["model"]).stem != model.stem:
            err.print(f"warning: {estimates} was made with model {doc['model']!r}, scored "
                      f"here with {str(model)!r}", soft_wrap=True, markup=False)
        pts = M.model_points(m, 2000)
        diam = M.diameter(pts)
        try:
            syms = M.symmetries(m)
        except CsdfError:  # a sphere-like model: no discrete set
            syms = None
        rows = []
        for k, key in enumerate(gt_ids):
            gt = seq.poses[k]
            e = est.get(int(key))
            if e is None:
                rows.append({"image_id": int(key), "missing": True})
                continue
            row = {"image_id": int(key),
                   "mssd": M.mssd(pts, e, gt, syms), "mspd": M.mspd(pts, e, gt, seq.camera,
                                                                    syms),
                   "adds": M.adds(pts, e, gt)}
            if vsd:
                row["vsd"] = M.vsd(m, e, gt, seq.depth[k], seq.camera,
                                   delta=15.0 / mm_per_unit, diameter=diam).tolist()
            rows.append(row)
        have = [r for r in rows if not r.get("missing")]
        inf = float("inf")
        get = {name: np.array([r.get(name, inf) if not r.get("missing") else inf
                               for r in rows]) for name in ("mssd", "mspd", "adds")}
        visib = seq.visib_fract if np.isfinite(seq.visib_fract).all() else None
        summary = {
            "images": len(rows), "estimated": len(have), "diameter": diam,
            "AR_MSSD": M.average_recall(get["mssd"], "mssd", diameter=diam,
                                        visib_fract=visib),
            "AR_MSPD": M.average_recall(get["mspd"], "mspd", image_width=seq.camera.width,
                                        visib_fract=visib),
            "ADD-S AUC (10 % of diameter)": M.auc(get["adds"], 0.1, scale=diam,
                                                  visib_fract=visib)}
        if vsd:
            ev = np.array([r["vsd"] if not r.get("missing") else [inf] * len(M.VSD_TAUS)
                           for r in rows])
            summary["AR_VSD"] = M.average_recall(ev, "vsd", visib_fract=visib)
            summary["AR"] = (summary["AR_VSD"] + summary["AR_MSSD"]
                             + summary["AR_MSPD"]) / 3
        for name, v in summary.items():
            out.print(f"{name}: {v:.4g}" if isinstance(v, float) else f"{name}: {v}",
                      soft_wrap=True)
        if output is not None:
            with atomic_path(output) as tmp:
                tmp.write_text(json.dumps({"summary": summary, "images": rows}, indent=1)
                               + "\n", encoding="utf-8")
            out.print(f"{output}: errors and recalls", soft_wrap=True)

    _run(go)


def _cloud_viewpoint(viewpoint: str | None, cloud, scan: Path
                     ) -> tuple[tuple[float, float, float] | None, str]:
    """The sensor position of a scan and where it came from: ``--viewpoint x,y,z``,
    ``--viewpoint none`` (ignored), else the position the PLY header records."""
    if viewpoint is not None and viewpoint.strip().lower() == "none":
        return None, "none (--viewpoint none)"
    if viewpoint is not None:
        return _vec3(viewpoint, "--viewpoint"), "--viewpoint"
    if cloud.viewpoint is not None:
        return tuple(float(v) for v in cloud.viewpoint), f"{scan}'s header"
    return None, (f"none ({scan} records no viewpoint; give --viewpoint for a "
                  "single-view scan)")


#: ``csdf infer`` notes a model that leaves more than this share of the points
#: unexplained
INFER_FEW_INLIERS = 0.8


def _cloud_arrays(cloud, scan: Path):
    """``(points (N, 3), normals (N, 3) or None)`` of a cloud read from ``scan``,
    checked, with errors naming the file (``scan.ply: points: row 7 is not finite``)."""
    from .detect.neighbours import normals_arg, points_arg

    try:
        P = points_arg(cloud.points)
        N = None if cloud.normals is None else normals_arg(cloud.normals, P)
    except CsdfError as exc:
        raise CsdfError(f"{scan}: {exc}") from None
    return P, N


def _write_png(path: Path, img) -> None:
    """Write an RGB image ``(H, W, 3)`` uint8 as PNG (a temporary file, then renamed)."""
    from PIL import Image

    from .io import atomic_path

    with atomic_path(path) as tmp:
        Image.fromarray(img).save(tmp, format="PNG")


def _size(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    try:
        if not sep:
            raise ValueError
        return int(w), int(h)
    except ValueError:
        raise CsdfError(f"--size expects WIDTHxHEIGHT (e.g. 640x480), got {text!r}") from None


def _vec3(text: str | None, flag: str) -> tuple[float, float, float] | None:
    """``x,y,z`` of option ``flag`` as three floats, or None when not given."""
    v = _numbers(text, flag, "x,y,z")
    return None if v is None else (v[0], v[1], v[2])


def _numbers(text: str | None, flag: str, names: str) -> tuple[float, ...] | None:
    """Comma-separated numbers of option ``flag``, as many as ``names`` lists
    (``'x,y,z'``); None when not given."""
    if text is None:
        return None
    n = names.count(",") + 1
    parts = text.split(",")
    try:
        if len(parts) != n:
            raise ValueError
        return tuple(float(p) for p in parts)
    except ValueError:
        count = {3: "three", 4: "four"}.get(n, str(n))
        raise CsdfError(f"{flag} expects {names} ({count} numbers), got {text!r}") from None


def _view(m, size: str, eye: str | None, target: str | None, fov: float, params: dict):
    from .render import auto_camera

    w, h = _size(size)
    return auto_camera(m, w, h, fov=fov, eye=_vec3(eye, "--eye"),
                       target=_vec3(target, "--target"), params=params,
                       check_ranges=False)  # (the caller checked them)


_EYE_HELP = "Camera position x,y,z (default: looking at the model from the +x -y +z octant)."
_TARGET_HELP = "Point looked at, x,y,z (default: the centre of the model's bounding box)."


@app.command(name="render")
def render_(
    model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name."),
    output: Path = typer.Option(..., "-o", "--output", help="Image file (.png)."),
    size: str = typer.Option("640x480", "--size", help="WIDTHxHEIGHT in pixels."),
    eye: str | None = typer.Option(None, "--eye", help=_EYE_HELP),
    target: str | None = typer.Option(None, "--target", help=_TARGET_HELP),
    fov: float = typer.Option(40.0, "--fov", help="Vertical field of view in degrees."),
    shadows: bool = typer.Option(False, "--shadows", help="Soft shadows."),
    ao: bool = typer.Option(False, "--ao", help="Ambient occlusion."),
    param: list[str] = typer.Option([], "--param", "-p", help="name=value (repeatable)."),
    no_check_ranges: bool = typer.Option(False, "--no-check-ranges", help=_NO_CHECK_HELP),
):
    """Render a model to a PNG by sphere tracing (exact normals, Lambert shading)."""

    def go():
        from .render import render

        if output.suffix.lower() != ".png":
            raise CsdfError(f"{output}: the output must end in .png")
        from .render.trace import trace_field

        m = _load(model)
        params = _checked_params(m, param, no_check_ranges)
        cam = _view(m, size, eye, target, fov, params)
        _note_compiling((trace_field(m, params, check_ranges=False), ("value", "grad")))
        r = render(m, cam, params=params, shadows=shadows, ao=ao, check_ranges=False)
        r.save(output)
        out.print(f"{output}: {cam.width}x{cam.height}, {r.mask.mean():.0%} of the pixels "
                  f"on the surface, {r.stats['seconds']:.2f} s", soft_wrap=True)

    _run(go)


@app.command(name="scan")
def scan_(
    model: Path = typer.Argument(..., help="A .csdf model or program, or a zoo name."),
    output: Path = typer.Option(..., "-o", "--output", help="Point cloud file (.ply)."),
    size: str = typer.Option("640x480", "--size", help="Sensor WIDTHxHEIGHT in pixels."),
    eye: str | None = typer.Option(None, "--eye", help=_EYE_HELP),
    target: str | None = typer.Option(None, "--target", help=_TARGET_HELP),
    fov: float = typer.Option(40.0, "--fov", help="Vertical field of view in degrees."),
    noise: float = typer.Option(0.0, "--noise", help="Range noise standard deviation "
                                "(model units, along the ray)."),
    outliers: float = typer.Option(0.0, "--outliers", help="Fraction of points replaced "
                                   "by outliers in the view frustum."),
    seed: int | None = typer.Option(None, "--seed", min=0, help="Random seed."),
    world: bool = typer.Option(False, "--world", help="Write world coordinates (default: "
                               "the camera frame, OpenCV: x right, y down, z forward)."),
    ascii_: bool = typer.Option(False, "--ascii", help="Write ASCII PLY."),
    param: list[str] = typer.Option([], "--param", "-p", help="name=value (repeatable)."),
    no_check_ranges: bool = typer.Option(False, "--no-check-ranges", help=_NO_CHECK_HELP),
):
    """Simulate a depth sensor: the visible surface points of a model, with normals."""

    def go():
        from .io import write_points
        from .scan import scan

        if output.suffix.lower() != ".ply":
            raise CsdfError(f"{output}: the output must end in .ply")
        from .render.trace import trace_field

        m = _load(model)
        params = _checked_params(m, param, no_check_ranges)
        cam = _view(m, size, eye, target, fov, params)
        _note_compiling((trace_field(m, params, what="scan", check_ranges=False),
                         ("value", "grad")))
        t0 = time.perf_counter()
        pts, nrm = scan(m, cam, noise=noise, outliers=outliers, seed=seed, params=params,
                        check_ranges=False)  # checked above
        if world:
            pts, nrm = cam.camera_to_world(pts), nrm @ cam.R.T
        # the sensor position in the cloud's frame, recorded in the PLY header
        vp = tuple(float(v) for v in cam.t) if world else (0.0, 0.0, 0.0)
        write_points(output, pts, nrm, ascii=ascii_, viewpoint=vp)
        frame = "world" if world else "camera"
        out.print(f"{output}: {len(pts):,} points ({frame} frame), "
                  f"{time.perf_counter() - t0:.2f} s", soft_wrap=True)

    _run(go)


zoo_app = typer.Typer(help="The model zoo: parametric furniture, parts, vehicles, buildings.",
                      no_args_is_help=True)
app.add_typer(zoo_app, name="zoo")


@zoo_app.command("list")
def zoo_list():
    """List the zoo's models with their parameters."""

    def go():
        from . import zoo

        t = Table("model", "parameters", "description")
        for name in zoo.names():
            info = zoo.info(name)
            t.add_row(name, ", ".join(p.name for p, _ in info.params), info.title)
        out.print(t)

    _run(go)


@zoo_app.command("show")
def zoo_show(
    name: str = typer.Argument(..., help="Model name (see csdf zoo list)."),
    source: bool = typer.Option(False, "--source", help="Print the .csdf source only."),
):
    """Describe a zoo model: parameters with ranges, sizes; or print its source."""

    def go():
        import difflib

        from . import zoo

        names = zoo.names()
        if name not in names:
            close = difflib.get_close_matches(name, names, n=3)
            hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise CsdfError(f"unknown zoo model {name!r}{hint} (models: {', '.join(names)})")
        if source:
            sys.stdout.write(zoo.source(name))
            return
        info = zoo.info(name)
        prog = zoo.load(name).compile()
        out.print(f"[bold]{name}[/]: {info.description}", soft_wrap=True)
        t = Table("parameter", "default", "range", "meaning")
        for p, doc in info.params:
            t.add_row(p.name, f"{p.default:g}", f"[{p.lo:g}, {p.hi:g}]", doc)
        out.print(t)
        out.print(f"{prog.exactness}, Lipschitz {prog.lipschitz:g}; compact "
                  f"{prog.compact_nbytes()} bytes, expanded {prog.nbytes} bytes; "
                  f"{info.path}", soft_wrap=True)

    _run(go)


@app.command()
def edit(
    model: Path | None = typer.Argument(
        None, help="The .csdf model to edit (created on the first save if missing); "
                   "without one, the editor opens a zoo model and asks for a file name "
                   "in the current folder when saving."),
    port: int = typer.Option(0, "--port", min=0, max=65535,
                             help="TCP port on 127.0.0.1 (default: a free one)."),
    no_browser: bool = typer.Option(False, "--no-browser",
                                    help="Only print the URL; do not open a browser."),
):
    """Live editor: the model's text, a real-time GPU preview and a slider per parameter,
    served on 127.0.0.1 (Ctrl-C to stop)."""

    def go():
        from .editor.server import serve

        try:
            serve(model, port=port, open_browser=not no_browser)
        except KeyboardInterrupt:  # pragma: no cover - interactive
            pass

    _run(go)


def main() -> None:
    """Entry point of the ``csdf`` script."""
    global _AS_SCRIPT
    _AS_SCRIPT = True
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
