"""Reading a model file of any kind csdf reads: ``.csdf``, Fidget's ``.vm`` and
OpenSCAD's ``.csg`` and ``.scad`` as shapes, ``.csdfb`` bytecode and ``.csdft`` text as
programs."""

from __future__ import annotations

from pathlib import Path

from ..errors import CsdfError

__all__ = ["load_model", "MODEL_SUFFIXES"]

MODEL_SUFFIXES = (".csdf", ".vm", ".csdfb", ".csdft", ".csg", ".scad")


def load_model(path: str | Path):
    """A :class:`csdf.Shape` (from ``.csdf``, ``.vm``, ``.csg`` or ``.scad``) or a
    :class:`csdf.Program` (from ``.csdfb`` or ``.csdft``).

    Raises:
        CsdfError: an unreadable file, another suffix, or the reader's error, naming the
            file (bytecode errors keep their class, e.g. ``BytecodeError``).
    """
    from ..compiler.program import Program
    from ..lang import load

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".csdf", ".vm", ".csg", ".scad"):
        return load(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CsdfError(f"cannot read {path}: {exc.strerror}") from None
    try:
        if suffix == ".csdfb":
            return Program.from_bytes(data)
        if suffix == ".csdft":
            try:
                text = data.decode("utf-8")
            except UnicodeDecodeError:
                raise CsdfError(f"{path} is not UTF-8 text") from None
            return Program.from_text(text)
    except CsdfError as exc:
        if str(exc).startswith(str(path)):
            raise
        # the same error class ("byte 826: checksum mismatch"), naming the file
        try:
            named = type(exc)(f"{path}: {exc}")
        except TypeError:  # (an error class with another constructor)
            named = CsdfError(f"{path}: {exc}")
        raise named from None
    raise CsdfError(f"{path}: unknown model type {suffix!r}; use .csdf, .vm, .csg, .scad, "
                    ".csdfb or .csdft")
