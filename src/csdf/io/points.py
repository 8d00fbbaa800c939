"""Point clouds as PLY files: positions, optional normals and colours.

:func:`write_points` writes one ``vertex`` element (``x y z``, optional ``nx ny nz``,
optional ``red green blue [alpha]``), binary little-endian by default or ASCII, through
:func:`csdf.io.atomic_path`. :func:`read_points` reads ASCII and binary (either byte
order) PLY files with a ``vertex`` element holding ``x, y, z`` and optionally
``nx, ny, nz`` of any scalar type; other properties (colours, ...) and other elements
(faces of a mesh, ...) are skipped. Every flaw in a file (a bad header, a truncated
body, counts larger than the data can hold, missing coordinates) raises
:class:`csdf.CsdfError` naming the file and what is wrong; nothing is allocated from a
count before it is checked against the file's size.

**Viewpoint.** A cloud seen from one sensor position records it in the header as one
comment line (written by ``write_points(..., viewpoint=...)`` and ``csdf scan``)::

    comment csdf viewpoint X Y Z

``X Y Z``: three finite decimal numbers (``repr`` of floats), the sensor position in the
cloud's frame and units (``0 0 0`` for a camera-frame cloud). :func:`read_point_cloud`
returns it (None when the line is absent, as in files written by other tools);
:func:`read_points` ignores it (its return value is unchanged).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from .atomic import atomic_path

__all__ = ["write_points", "read_points", "read_point_cloud", "read_point_properties",
           "PointCloud", "PLY_TYPES", "MAX_HEADER_BYTES", "VIEWPOINT_COMMENT"]

#: the header comment that records the sensor position: ``comment csdf viewpoint X Y Z``
VIEWPOINT_COMMENT = "csdf viewpoint"

#: PLY scalar type names -> numpy type codes (without byte order)
PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
MAX_HEADER_BYTES = 1 << 16
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}


# ---------------------------------------------------------------------- writing
def _as_array(a: Any, n: int | None, what: str, cols: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.asarray(a)
    except (TypeError, ValueError) as exc:
        raise CsdfError(f"{what} must be an array: {exc}") from None
    if arr.ndim != 2 or arr.shape[1] not in cols or (n is not None and arr.shape[0] != n):
        rows = "N" if n is None else str(n)
        want = " or ".join(f"({rows}, {c})" for c in cols)
        raise CsdfError(f"{what} must have shape {want}, got {arr.shape}")
    if arr.dtype.kind not in "biuf":
        raise CsdfError(f"{what} must be numeric, got dtype {arr.dtype}")
    return arr


def write_points(
    path: str | os.PathLike,
    points: Any,
    normals: Any = None,
    colors: Any = None,
    *,
    scalars: dict[str, Any] | None = None,
    ascii: bool = False,
    viewpoint: Any = None,
) -> Path:
    """Write a point cloud as a PLY file, atomically.

    Args:
        path: output file (conventionally ``.ply``).
        points: ``(N, 3)`` positions (model units); float32 is written as ``float``,
            anything else as ``double``.
        normals: optional ``(N, 3)`` normals, written in the points' type.
        colors: optional ``(N, 3)`` RGB or ``(N, 4)`` RGBA: ``uint8``, or floats in
            ``[0, 1]`` (scaled to 0..255); written as ``uchar red green blue [alpha]``.
        scalars: optional ``{name: (N,) values}``, more per-point properties written in
            the points' type (e.g. ``{'distance': d}`` for volume samples); names are
            letters, digits and ``_``. Read back with :func:`read_point_properties`.
        ascii: write ``format ascii`` instead of ``binary_little_endian``.
        viewpoint: optional ``(3,)`` sensor position in the points' frame and units,
            recorded as the header line ``comment csdf viewpoint X Y Z`` (see the module
            docs); read back by :func:`read_point_cloud`.

    Returns:
        The path written.

    Raises:
        CsdfError: wrongly shaped arrays, colours out of range, bad or repeated property
            names, a viewpoint that is not 3 finite numbers, an unwritable folder.
    """
    vp_line = None
    if viewpoint is not None:
        try:
            vp = np.asarray(viewpoint, dtype=np.float64)
        except (TypeError, ValueError):
            vp = np.zeros(0)
        if vp.shape != (3,) or not np.all(np.isfinite(vp)):
            raise CsdfError(f"viewpoint must be 3 finite numbers, got {viewpoint!r}")
        vp_line = f"comment {VIEWPOINT_COMMENT} " + " ".join(repr(float(v)) for v in vp)
    pts = _as_array(points, None, "points", (3,))
    n = pts.shape[0]
    ftype = "f4" if pts.dtype == np.float32 else "f8"
    fields: list[tuple[str, str]] = [("x", ftype), ("y", ftype), ("z", ftype)]
    columns: list[np.ndarray] = [pts[:, 0], pts[:, 1], pts[:, 2]]
    if normals is not None:
        nrm = _as_array(normals, n, "normals", (3,))
        fields += [("nx", ftype), ("ny", ftype), ("nz", ftype)]
        columns += [nrm[:, 0], nrm[:, 1], nrm[:, 2]]
    if colors is not None:
        col = _as_array(colors, n, "colors", (3, 4))
        if col.dtype.kind == "f":
            if not np.all((col >= 0) & (col <= 1)):
                raise CsdfError("float colors must be in [0, 1]")
            col = np.round(col * 255.0)
        elif col.size and (col.min() < 0 or col.max() > 255):
            raise CsdfError("integer colors must be in [0, 255]")
        col = col.astype(np.uint8)
        names = ("red", "green", "blue", "alpha")[: col.shape[1]]
        fields += [(c, "u1") for c in names]
        columns += [col[:, i] for i in range(col.shape[1])]
    for name, values in (scalars or {}).items():
        if not isinstance(name, str) or not name.isascii() or \
                not name.replace("_", "a").isalnum():
            raise CsdfError(f"scalar property names must be letters, digits and _, "
                            f"got {name!r}")
        if name in {f[0] for f in fields}:
            raise CsdfError(f"property {name!r} is written twice")
        col = _as_array(np.asarray(values).reshape(-1, 1), n, f"scalars[{name!r}]", (1,))
        fields.append((name, ftype))
        columns.append(col[:, 0])
    ply_name = {"f4": "float", "f8": "double", "u1": "uchar"}  # PLY type of each field
    header = ["ply", f"format {'ascii' if ascii else 'binary_little_endian'} 1.0",
              "comment written by csdf"]
    if vp_line is not None:
        header.append(vp_line)
    header.append(f"element vertex {n}")
    header += [f"property {ply_name[t]} {name}" for name, t in fields]
    header.append("end_header")
    head = ("\n".join(header) + "\n").encode("ascii")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(head)
            if ascii:
                fmts = ["%.9g" if t == "f4" else "%.17g" if t == "f8" else "%d"
                        for _, t in fields]
                table = np.empty((n, len(fields)), dtype=object)
                for i, c in enumerate(columns):
                    table[:, i] = c.tolist()
                if n:
                    np.savetxt(fh, table, fmt=fmts, delimiter=" ")
            else:
                rec = np.empty(n, dtype=[(name, "<" + t) for name, t in fields])
                for (name, _), c in zip(fields, columns):
                    rec[name] = c
                fh.write(rec.tobytes())
    return Path(path)


# ---------------------------------------------------------------------- reading
class _Element:
    def __init__(self, name: str, count: int, line: int):
        self.name = name
        self.count = count
        self.line = line
        self.props: list[tuple[str, str | None, str | None]] = []  # name, type, list count


def _parse_header(data: bytes, where: str, comments: list[tuple[int, str]] | None = None):
    """``(format, elements, offset of the body)`` of a PLY file's bytes; the ``comment``
    lines' ``(line number, text after 'comment')`` are appended to ``comments`` if given."""
    if not data.startswith(b"ply"):
        raise CsdfError(f"{where}: not a PLY file (it must start with 'ply')")
    lines: list[str] = []
    pos = 0
    while True:
        nl = data.find(b"\n", pos, MAX_HEADER_BYTES)
        if nl < 0:
            raise CsdfError(f"{where}: no 'end_header' line in the first "
                            f"{MAX_HEADER_BYTES} bytes (truncated or not a PLY header)")
        try:
            line = data[pos:nl].decode("ascii").rstrip("\r")
        except UnicodeDecodeError:
            raise CsdfError(f"{where}: header line {len(lines) + 1} is not ASCII text") \
                from None
        pos = nl + 1
        if line.strip() == "end_header":
            break
        lines.append(line)
    if lines[0].strip() != "ply":
        raise CsdfError(f"{where}: not a PLY file (first line is {lines[0][:40]!r})")
    fmt: str | None = None
    elements: list[_Element] = []
    for no, raw in enumerate(lines[1:], start=2):
        words = raw.split()
        if not words or words[0] in ("comment", "obj_info"):
            if comments is not None and words and words[0] == "comment":
                comments.append((no, raw.strip()[len("comment"):].strip()))
            continue
        key = words[0]
        if key == "format":
            if fmt is not None:
                raise CsdfError(f"{where}: header line {no}: a second 'format' line")
            if len(words) != 3 or words[1] not in _FORMATS or words[2] != "1.0":
                raise CsdfError(f"{where}: header line {no}: unsupported format {raw!r} "
                                "(expected 'format ascii|binary_little_endian|"
                                "binary_big_endian 1.0')")
            fmt = words[1]
        elif key == "element":
            if len(words) != 3:
                raise CsdfError(f"{where}: header line {no}: expected 'element NAME COUNT'")
            try:
                count = int(words[2])
            except ValueError:
                raise CsdfError(f"{where}: header line {no}: element count {words[2]!r} is "
                                "not an integer") from None
            if count < 0:
                raise CsdfError(f"{where}: header line {no}: negative element count {count}")
            elements.append(_Element(words[1], count, no))
        elif key == "property":
            if not elements:
                raise CsdfError(f"{where}: header line {no}: property before any element")
            pname = words[-1]
            if len(words) in (3, 5) and pname in (q[0] for q in elements[-1].props):
                raise CsdfError(f"{where}: header line {no}: element {elements[-1].name!r} "
                                f"has property {pname!r} twice")
            if len(words) == 3 and words[1] in PLY_TYPES:
                elements[-1].props.append((words[2], PLY_TYPES[words[1]], None))
            elif len(words) == 5 and words[1] == "list" and words[2] in PLY_TYPES \
                    and words[3] in PLY_TYPES:
                if PLY_TYPES[words[2]][0] not in "iu":
                    raise CsdfError(f"{where}: header line {no}: list count type must be "
                                    "an integer type")
                elements[-1].props.append((words[4], PLY_TYPES[words[3]],
                                           PLY_TYPES[words[2]]))
            else:
                raise CsdfError(f"{where}: header line {no}: bad property line {raw.strip()!r}"
                                f" (types: {', '.join(sorted(PLY_TYPES))})")
        else:
            raise CsdfError(f"{where}: header line {no}: unknown keyword {key!r}")
    if fmt is None:
        raise CsdfError(f"{where}: the header has no 'format' line")
    return fmt, elements, pos


def _vertex_columns(el: _Element, where: str) -> tuple[list[str], list[str]]:
    """Names of the coordinate and normal columns, checked."""
    names = [p[0] for p in el.props]
    if len(set(names)) != len(names):
        raise CsdfError(f"{where}: element 'vertex' has a property named twice")
    missing = [c for c in ("x", "y", "z") if c not in names]
    if missing:
        raise CsdfError(f"{where}: element 'vertex' has no {', '.join(missing)} property")
    has_n = [c in names for c in ("nx", "ny", "nz")]
    if any(has_n) and not all(has_n):
        raise CsdfError(f"{where}: element 'vertex' has some but not all of nx, ny, nz")
    for name, _, list_t in el.props:
        if list_t is not None and name in ("x", "y", "z", "nx", "ny", "nz"):
            raise CsdfError(f"{where}: vertex property {name!r} is a list")
    return ["x", "y", "z"], (["nx", "ny", "nz"] if all(has_n) else [])


def _read_binary(data: bytes, offset: int, elements: list[_Element], order: str,
                 where: str) -> np.ndarray:
    """The vertex element as a structured array (skipping elements before it)."""
    for el in elements:
        if any(p[2] is not None for p in el.props):
            if el.name == "vertex":
                raise CsdfError(f"{where}: list properties in 'vertex' are not supported")
            raise CsdfError(f"{where}: element {el.name!r} (before 'vertex') has list "
                            "properties; cannot skip it in a binary file")
        dtype = np.dtype([(p[0], order + p[1]) for p in el.props])
        remaining = len(data) - offset
        if dtype.itemsize == 0 and el.count:
            raise CsdfError(f"{where}: element {el.name!r} has no properties")
        need = el.count * dtype.itemsize
        if need > remaining:
            raise CsdfError(f"{where}: truncated: element {el.name!r} declares {el.count} "
                            f"items of {dtype.itemsize} bytes ({need} bytes) but only "
                            f"{remaining} bytes follow")
        if el.name == "vertex":
            return np.frombuffer(data, dtype=dtype, count=el.count, offset=offset)
        offset += need
    raise AssertionError("unreachable")  # pragma: no cover


def _read_ascii(data: bytes, offset: int, elements: list[_Element],
                where: str) -> dict[str, np.ndarray]:
    """The vertex element's scalar columns from an ASCII body."""
    try:
        body = data[offset:].decode("ascii")
    except UnicodeDecodeError:
        raise CsdfError(f"{where}: the ASCII body holds non-ASCII bytes") from None
    skip = 0
    for el in elements:
        if el.name == "vertex":
            break
        skip += el.count
    vertex = next(el for el in elements if el.name == "vertex")
    if any(p[2] is not None for p in vertex.props):
        raise CsdfError(f"{where}: list properties in 'vertex' are not supported")
    width = len(vertex.props)
    # every value needs at least one character and one separator
    if vertex.count and (skip + vertex.count * max(width, 1)) * 2 - 1 > len(body):
        raise CsdfError(f"{where}: truncated: {vertex.count} vertices declared but the body "
                        f"has only {len(body)} bytes")
    first = data[:offset].count(b"\n") + 1  # the file's line number of the body's first
    numbered = [(first + i, ln) for i, ln in enumerate(body.splitlines()) if ln.strip()]
    if len(numbered) < skip + vertex.count:
        raise CsdfError(f"{where}: truncated: expected {skip + vertex.count} data lines "
                        f"before the end of the vertices, found {len(numbered)}")
    numbered = numbered[skip: skip + vertex.count]
    rows = [ln.split() for _, ln in numbered]
    for i, r in enumerate(rows):
        if len(r) != width:
            raise CsdfError(f"{where}: line {numbered[i][0]}: vertex {i} has {len(r)} "
                            f"values, expected {width}")
    try:
        table = np.array(rows, dtype=np.float64).reshape(vertex.count, width)
    except ValueError:
        raise CsdfError(f"{where}: a vertex value is not a number") from None
    _check_ascii_ranges(table, vertex, [no for no, _ in numbered], rows, where)
    # values are rounded to the declared type (a 'float' written with 9 digits reads back
    # as the same float32)
    with np.errstate(invalid="ignore", over="ignore"):
        return {p[0]: table[:, i].astype(p[1]).astype(np.float64) if p[1][0] == "f"
                else table[:, i] for i, p in enumerate(vertex.props)}


_PLY_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int",
              "u4": "uint", "f4": "float", "f8": "double"}


def _check_ascii_ranges(table: np.ndarray, el: _Element, line_nos: list[int],
                        rows: list[list[str]], where: str) -> None:
    """Every ASCII value must fit its declared type: integers whole and in range,
    ``float`` values finite unless written as inf/nan (no overflow to inf).

    Raises:
        CsdfError: naming the file, the line, the property, its type and the value.
    """
    for j, (name, code, _) in enumerate(el.props):
        col = table[:, j]
        if code[0] in "iu":
            info = np.iinfo(code)
            with np.errstate(invalid="ignore"):
                ok = (col >= info.min) & (col <= info.max) & (col == np.floor(col))
            limits = f"whole numbers in [{info.min}, {info.max}]"
        elif code == "f4":
            with np.errstate(over="ignore"):
                ok = np.isfinite(col.astype(np.float32)) | ~np.isfinite(col)
            limits = f"magnitudes up to {float(np.finfo(np.float32).max):.7g}"
        else:
            continue
        bad = np.flatnonzero(~ok)
        if len(bad):
            i = int(bad[0])
            raise CsdfError(f"{where}: line {line_nos[i]}: vertex {i}: property {name!r} "
                            f"({_PLY_NAMES[code]}) is {rows[i][j]}, outside its type "
                            f"({limits})")


def _read_vertex(path: str | os.PathLike, comments: list[tuple[int, str]] | None = None):
    """``(scalar columns of the vertex element, property names, coordinate names, normal
    names)``; the header's comments are appended to ``comments`` if given."""
    p = Path(path)
    where = str(p)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise CsdfError(f"cannot read {where}: {exc.strerror or exc}") from None
    fmt, elements, offset = _parse_header(data, where, comments)
    if not any(el.name == "vertex" for el in elements):
        raise CsdfError(f"{where}: no 'vertex' element in the header")
    if sum(el.name == "vertex" for el in elements) > 1:
        raise CsdfError(f"{where}: more than one 'vertex' element")
    vertex = next(el for el in elements if el.name == "vertex")
    pos, nrm = _vertex_columns(vertex, where)
    order = _FORMATS[fmt]
    if order is None:
        cols: Any = _read_ascii(data, offset, elements, where)
    else:
        cols = _read_binary(data, offset, elements, order, where)
    return cols, [p[0] for p in vertex.props], pos, nrm


def read_points(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray | None]:
    """Read the vertices (and normals) of a PLY file.

    Args:
        path: a PLY file, ASCII or binary (little- or big-endian), with a ``vertex``
            element holding scalar ``x, y, z`` and optionally ``nx, ny, nz`` (any scalar
            type); other properties and elements are ignored (a mesh's faces, ...).

    Returns:
        ``(points (N, 3) float64, normals (N, 3) float64 or None)`` in the file's units.

    Raises:
        CsdfError: the file cannot be read, or is not a well-formed PLY point cloud
            (the message says what and where).
    """
    cols, _, pos, nrm = _read_vertex(path)
    points, normals = _xyz_normals(cols, pos, nrm)
    return points, normals


@dataclass(frozen=True)
class PointCloud:
    """A point cloud read by :func:`read_point_cloud`.

    Attributes:
        points: ``(N, 3)`` float64 positions (the file's units).
        normals: ``(N, 3)`` float64 normals, or None.
        viewpoint: ``(3,)`` float64 sensor position recorded in the header (``comment
            csdf viewpoint X Y Z``), or None when the file records none.
    """

    points: np.ndarray
    normals: np.ndarray | None
    viewpoint: np.ndarray | None


def _viewpoint(comments: list[tuple[int, str]], where: str) -> np.ndarray | None:
    """The viewpoint of the header's ``comment csdf viewpoint X Y Z`` line (or None)."""
    found = None
    key = VIEWPOINT_COMMENT.split()
    for no, text in comments:
        words = text.split()
        if words[:2] != key:
            continue
        if found is not None:
            raise CsdfError(f"{where}: header line {no}: a second '{VIEWPOINT_COMMENT}' "
                            "comment")
        try:
            if len(words) != 5:
                raise ValueError
            vp = np.array([float(w) for w in words[2:]])
        except ValueError:
            raise CsdfError(f"{where}: header line {no}: expected 'comment "
                            f"{VIEWPOINT_COMMENT} X Y Z' (three numbers), got "
                            f"{text[:80]!r}") from None
        if not np.all(np.isfinite(vp)):
            raise CsdfError(f"{where}: header line {no}: the viewpoint must be finite, "
                            f"got {text[:80]!r}")
        found = vp
    return found


def read_point_cloud(path: str | os.PathLike) -> PointCloud:
    """Read a PLY point cloud with the sensor position its header records.

    Args:
        path: a PLY file as for :func:`read_points`.

    Returns:
        :class:`PointCloud` with ``points``, ``normals`` (as :func:`read_points`) and
        ``viewpoint`` (``(3,)`` or None; see the module docs).

    Raises:
        CsdfError: as :func:`read_points`, and a malformed or repeated ``comment csdf
            viewpoint`` line.
    """
    comments: list[tuple[int, str]] = []
    cols, _, pos, nrm = _read_vertex(path, comments)
    vp = _viewpoint(comments, str(Path(path)))
    points, normals = _xyz_normals(cols, pos, nrm)
    return PointCloud(points, normals, vp)


def _xyz_normals(cols: dict, pos: list, nrm: list) -> tuple[np.ndarray, np.ndarray | None]:
    """``(points (N, 3), normals (N, 3) or None)`` float64 from the vertex columns (a
    signalling NaN in a float32 column becomes a quiet NaN without a warning)."""
    with np.errstate(invalid="ignore"):
        points = np.stack([np.asarray(cols[c], dtype=np.float64) for c in pos], axis=1)
        normals = np.stack([np.asarray(cols[c], dtype=np.float64) for c in nrm], axis=1) \
            if nrm else None
    return points, normals


def read_point_properties(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Every scalar property of a PLY file's vertices (the same checks as
    :func:`read_points`).

    Returns:
        ``{name: (N,) array}`` in the file's order (``x, y, z, ..., red, ...,
        distance``); binary files keep their types, ASCII values are float64.
    """
    cols, names, _, _ = _read_vertex(path)
    return {name: np.array(cols[name]) for name in names}
