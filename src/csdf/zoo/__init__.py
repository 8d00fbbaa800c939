"""The model zoo: hand-written ``.csdf`` models of furniture, vehicles, buildings, signs
and industrial parts, at real-world scale in metres (z up).

Every model is a short text file in this package (see ``docs/language.md``) with named,
documented parameters and ranges::

    from csdf import zoo
    zoo.names()                          # ['bookshelf', 'car', 'chair', ...]
    chair = zoo.load("chair")            # a csdf.Shape with the file's defaults
    armchair = zoo.load("chair", arm_height=0.22, back_height=0.5)
    [(p.name, p.default, p.lo, p.hi, doc) for p, doc in zoo.info("chair").params]
    csdf.mesh(armchair, resolution=128)

``clutter(n, seed=0)`` is a union of ``n`` random spheres, boxes and tori, the test
scene of long programs (pruned evaluation, scenes).

``load(name, **params)`` gives a shape whose parameter *defaults* are the values given
(the declarations keep their ranges, so the shape still takes any value at evaluation
time: ``shape(points, seat_height=0.5)``).
"""

from __future__ import annotations

import difflib
import math
import numbers
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from ..errors import CsdfError, ParamError
from ..expr import Param
from ..shapes.base import Shape
from .clutter import clutter

__all__ = ["names", "path", "source", "load", "info", "ModelInfo", "ZOO_DIR", "clutter"]

ZOO_DIR = Path(__file__).resolve().parent
_SUFFIX = ".csdf"


def names() -> list[str]:
    """The zoo's model names, sorted (the file names without ``.csdf``)."""
    return sorted(p.name[: -len(_SUFFIX)] for p in ZOO_DIR.glob("*" + _SUFFIX) if p.is_file())


def path(name: str) -> Path:
    """The ``.csdf`` file of model ``name``.

    Raises:
        CsdfError: an unknown name (the message lists the known ones and the closest).
    """
    known = names()
    if not isinstance(name, str) or name not in known:
        close = difflib.get_close_matches(str(name), known, n=3, cutoff=0.6)
        hint = f" (did you mean {', '.join(repr(c) for c in close)}?)" if close else ""
        raise CsdfError(f"unknown zoo model {name!r}{hint}; the zoo has: {', '.join(known)}")
    return ZOO_DIR / (name + _SUFFIX)


def source(name: str) -> str:
    """The text of model ``name``."""
    return path(name).read_text(encoding="utf-8")


@dataclass(frozen=True)
class ModelInfo:
    """What a zoo model declares.

    Attributes:
        name: the model's name.
        path: its ``.csdf`` file.
        description: the comment block at the top of the file, as one text (it starts
            with ``Title: ...``; :attr:`title` is the part before the colon).
        params: ``(Param, doc)`` pairs in file order: the declaration (name, default,
            range) and the comment written after it.
    """

    name: str
    path: Path
    description: str
    params: tuple[tuple[Param, str], ...]

    @property
    def title(self) -> str:
        """What the model is, in a few words: the description up to its first colon."""
        return self.description.split(":")[0].strip()


_PARAM_LINE = re.compile(r"^\s*param\s+([A-Za-z_][A-Za-z0-9_]*)\b[^#]*(?:#\s*(.*))?$")


def info(name: str) -> ModelInfo:
    """The description and the documented parameters of model ``name``."""
    text = source(name)
    desc: list[str] = []
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        desc.append(line[1:].strip())
    docs: dict[str, str] = {}
    for line in text.splitlines():
        m = _PARAM_LINE.match(line)
        if m:
            docs[m.group(1)] = (m.group(2) or "").strip()
    shape = _load_default(name)
    by_name = {p.name: p for p in shape.params}
    order = [n for n in docs if n in by_name] + sorted(set(by_name) - set(docs))
    return ModelInfo(
        name=name, path=path(name), description=" ".join(d for d in desc if d),
        params=tuple((by_name[n], docs.get(n, "")) for n in order),
    )


@lru_cache(maxsize=64)
def _load_default(name: str) -> Shape:
    from ..lang import loads

    return loads(source(name), file=str(path(name)))


def load(name: str, **params: float) -> Shape:
    """Model ``name`` as a :class:`csdf.Shape`.

    Args:
        name: a name from :func:`names`.
        **params: new default values of the model's parameters (each inside its range).

    Returns:
        The shape; with ``params``, the same model whose parameter defaults are the
        given values (ranges unchanged), so meshing or evaluating it without explicit
        parameter values uses them.

    Raises:
        CsdfError: an unknown model; :class:`csdf.ParamError` (a ``CsdfError``) for an
            unknown parameter name, a value that is not a finite real number, or a value
            outside the parameter's range (the message lists the model's parameters with
            their ranges).
    """
    shape = _load_default(name)
    if not params:
        return shape
    declared = {p.name: p for p in shape.params}
    listing = ", ".join(f"{p.name} in [{p.lo:g}, {p.hi:g}] (default {p.default:g})"
                        for p in declared.values())
    values: dict[str, float] = {}
    for key, value in params.items():
        p = declared.get(key)
        if p is None:
            close = difflib.get_close_matches(key, list(declared), n=1, cutoff=0.6)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ParamError(f"zoo model {name!r} has no parameter {key!r}{hint}; "
                             f"its parameters: {listing}")
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ParamError(f"zoo model {name!r}: parameter {key!r} must be a real number, "
                             f"got {type(value).__name__}")
        v = float(value)
        if not math.isfinite(v):
            raise ParamError(f"zoo model {name!r}: parameter {key!r} must be finite, got {v}")
        if not p.lo <= v <= p.hi:
            raise ParamError(f"zoo model {name!r}: {key} = {v:g} is outside its range "
                             f"[{p.lo:g}, {p.hi:g}]; its parameters: {listing}")
        values[key] = v
    return _with_defaults(name, values)


def _with_defaults(name: str, values: dict[str, float]) -> Shape:
    """Re-load the model with the default expressions of some ``param`` statements
    replaced by the given numbers.

    The replacement is made on the parse tree's character spans (the loader's own
    grammar), not by pattern matching on the text, so comments, layout and any
    expression form of a default are handled; the edited text then goes through the
    ordinary loader, which checks it like any model.
    """
    from ..lang.loader import loads, parser

    text = source(name)
    tree = parser().parse(text)
    spans: list[tuple[int, int, str]] = []
    for st in tree.children:
        if getattr(st, "data", None) != "param_stmt":
            continue
        pname, default = str(st.children[0]), st.children[1]
        if pname in values:
            spans.append((default.meta.start_pos, default.meta.end_pos, repr(values[pname])))
    for start, end, new in sorted(spans, reverse=True):
        text = text[:start] + new + text[end:]
    return loads(text, file=str(path(name)))
