"""The scene file: readable JSON text, one record per instance.

::

    {
      "format": "csdf-scene", "version": 1,
      "models": {"m0": {"csdf": "export sphere(0.2)\\n"}},
      "instances": [
        {"id": 0, "name": "chair_0", "model": {"zoo": "chair"},
         "pose": {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                  "translation": [0.5, 0, 0], "scale": 1.0},
         "params": {"seat_height": 0.5}},
        {"id": 1, "name": "part", "model": {"file": "parts/flange.csdf"}, ...},
        {"id": 2, "name": "ball", "model": {"ref": "m0"}, ...}
      ]
    }

A model is a zoo name, a model file (relative to the scene file) or a reference into
``models``, where shapes built in Python are kept as ``.csdf`` text (:func:`csdf.dumps`)
and programs as bytecode text: one entry per model, so instances that share a model
share it again when the file is read. ``pose`` and ``params`` may be left out
(identity, defaults). Errors name the file, and the line and column (bad JSON) or the
place in the document (``instances[3].pose.rotation``).
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..pose import Pose

__all__ = ["dumps", "loads", "save", "load", "MAX_SCENE_BYTES", "FORMAT", "VERSION"]

FORMAT = "csdf-scene"
VERSION = 1
#: the largest scene file read
MAX_SCENE_BYTES = 64 << 20


def _file_record(src: dict, base: Path | None) -> dict:
    """``{"file": PATH}`` of an instance's model file: as it was given, or with ``base``
    (the folder of the scene file being written) relative to that folder, so that the
    file reads back from wherever the scene is saved (absolute where no relative path
    leads there)."""
    resolved = src.get("resolved")
    if base is None or resolved is None:
        return {"file": src["file"]}
    try:
        rel = os.path.relpath(resolved, Path(base).resolve())
    except ValueError:  # another drive
        return {"file": resolved}
    return {"file": Path(rel).as_posix()}


def dumps(scene, base: Path | None = None) -> str:
    """The scene as JSON text (see the module docs); ``base``: the folder the text will
    be saved in, which model file paths are then written relative to (default: as they
    were given)."""
    from ..lang import dumps as shape_text

    models: dict[str, dict] = {}
    keys: dict[int, str] = {}
    records = []
    for inst in scene:
        src = dict(inst.source)
        if "zoo" in src:
            model = src
        elif "file" in src:
            model = _file_record(src, base)
        else:
            key = keys.get(id(inst.model))
            if key is None:
                key = keys[id(inst.model)] = f"m{len(keys)}"
                if "csdf" in src:
                    try:
                        text = shape_text(inst.model)
                    except CsdfError as exc:
                        raise CsdfError(f"instance {inst.name!r}: its shape cannot be "
                                        f"written as .csdf text: {exc}") from None
                    models[key] = {"csdf": text}
                else:
                    models[key] = {"program": inst.model.disassemble()}
            model = {"ref": key}
        p = inst.pose
        records.append({
            "id": inst.id, "name": inst.name, "model": model,
            "pose": {"rotation": p.rotation.tolist(), "translation": p.translation.tolist(),
                     "scale": p.scale},
            "params": {k: float(v) for k, v in inst.params.items()},
        })
    # one line per instance, so that a scene reads (and diffs) record by record
    head = json.dumps({"format": FORMAT, "version": VERSION})[1:-1]
    lines = ["{", f" {head},", f' "models": {json.dumps(models, indent=2)},',
             ' "instances": [']
    lines += [f"  {json.dumps(r, allow_nan=False)}," for r in records]
    if records:
        lines[-1] = lines[-1][:-1]
    lines += [" ]", "}"]
    return "\n".join(lines) + "\n"


def save(scene, path: str | os.PathLike) -> None:
    """Write :func:`dumps` to ``path`` (through a temporary file, then renamed)."""
    from ..io.atomic import atomic_path

    text = dumps(scene, base=Path(path).parent)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def load(path: str | os.PathLike, scene):
    """Read a scene file into ``scene`` (an empty :class:`csdf.Scene`, returned); model
    files are found relative to the scene file.

    Raises:
        CsdfError: an unreadable or too large file, bad JSON (with line and column),
            or a bad record (naming where).
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if size > MAX_SCENE_BYTES:
            raise CsdfError(f"{p}: the file is {size} bytes, more than the "
                            f"{MAX_SCENE_BYTES} a scene file may have")
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise CsdfError(f"cannot read {p}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise CsdfError(f"{p}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    return loads(text, scene, str(p), base=p.parent)


class _Bad(Exception):
    pass


def _need(ok: bool, where: str, what: str) -> None:
    if not ok:
        raise _Bad(f"{where}: {what}")


def _number(v: Any, where: str) -> float:
    _need(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v),
          where, f"must be a finite number, got {v!r}")
    return float(v)


def _matrix(v: Any, rows: int, cols: int, where: str) -> np.ndarray:
    ok = isinstance(v, list) and len(v) == rows and all(
        isinstance(r, list) and len(r) == cols for r in v)
    _need(ok, where, f"must be {rows} lists of {cols} numbers")
    return np.array([[_number(x, f"{where}[{i}][{j}]") for j, x in enumerate(r)]
                     for i, r in enumerate(v)])


def loads(text: str, scene, source: str = "<string>", base: Path | None = None):
    """Fill ``scene`` (an empty :class:`csdf.Scene`, returned) from JSON text (see the
    module docs); ``base``: the folder model files are relative to (default the working
    folder)."""
    from ..compiler.program import Program
    from ..lang import loads as shape_loads

    if len(text) > MAX_SCENE_BYTES:
        raise CsdfError(f"{source}: more than {MAX_SCENE_BYTES} characters")
    try:
        doc = json.loads(text, parse_constant=lambda c: _reject(c))
    except json.JSONDecodeError as exc:
        raise CsdfError(f"{source}:{exc.lineno}:{exc.colno}: bad JSON: {exc.msg}") from None
    except _Bad as exc:
        raise CsdfError(f"{source}: {exc}") from None
    except RecursionError:
        raise CsdfError(f"{source}: the JSON is nested too deeply") from None
    if len(scene):
        raise CsdfError("a scene file is read into an empty scene")
    try:
        _need(isinstance(doc, dict), "the document", "must be a JSON object")
        _need(doc.get("format") == FORMAT, "format", f"must be {FORMAT!r}")
        _need(doc.get("version") == VERSION, "version",
              f"must be {VERSION} (this csdf reads version {VERSION})")
        models_doc = doc.get("models", {})
        _need(isinstance(models_doc, dict), "models", "must be an object")
        models: dict[str, Any] = {}
        for key, m in models_doc.items():
            where = f"models.{key}"
            _need(isinstance(m, dict) and len(m) == 1 and (
                isinstance(m.get("csdf"), str) or isinstance(m.get("program"), str)),
                where, 'must be {"csdf": TEXT} or {"program": TEXT}')
            if "csdf" in m:  # the language's errors name the place: source (where):L:C
                models[key] = shape_loads(m["csdf"], f"{source} ({where})")
                continue
            try:
                models[key] = Program.from_text(m["program"])
            except CsdfError as exc:
                raise _Bad(f"{where}: {exc}") from None
        records = doc.get("instances")
        _need(isinstance(records, list), "instances", "must be a list")
        for i, rec in enumerate(records):
            _instance(scene, rec, f"instances[{i}]", models, base)
    except _Bad as exc:
        raise CsdfError(f"{source}: {exc}") from None
    return scene


def _reject(c: str):
    raise _Bad(f"{c} is not a number a scene file may hold")


def _instance(scene, rec: Any, where: str, models: dict, base: Path | None) -> None:
    _need(isinstance(rec, dict), where, "must be an object")
    extra = set(rec) - {"id", "name", "model", "pose", "params"}
    _need(not extra, where, f"unknown field(s) {', '.join(sorted(extra))}")
    iid = rec.get("id", scene._next)
    _need(isinstance(iid, int) and not isinstance(iid, bool) and 0 <= iid < 2**62,
          f"{where}.id", "must be an integer >= 0")
    _need(iid not in scene._inst, f"{where}.id", f"{iid} is used twice")
    name = rec.get("name")
    _need(name is None or (isinstance(name, str) and name), f"{where}.name",
          "must be a non-empty string")
    m = rec.get("model")
    _need(isinstance(m, dict) and len(m) == 1, f"{where}.model",
          'must be {"zoo": NAME}, {"file": PATH} or {"ref": KEY}')
    ((kind, value),) = m.items()
    _need(kind in ("zoo", "file", "ref") and isinstance(value, str), f"{where}.model",
          'must be {"zoo": NAME}, {"file": PATH} or {"ref": KEY}')
    pose_doc = rec.get("pose", {})
    _need(isinstance(pose_doc, dict) and set(pose_doc) <= {"rotation", "translation",
                                                          "scale"},
          f"{where}.pose", "must be an object of rotation, translation and scale")
    R = _matrix(pose_doc["rotation"], 3, 3, f"{where}.pose.rotation") \
        if "rotation" in pose_doc else None
    t = _matrix([pose_doc["translation"]], 1, 3, f"{where}.pose.translation")[0] \
        if "translation" in pose_doc else None
    s = _number(pose_doc.get("scale", 1.0), f"{where}.pose.scale")
    params = rec.get("params", {})
    _need(isinstance(params, dict), f"{where}.params", "must be an object")
    params = {k: _number(v, f"{where}.params.{k}") for k, v in params.items()}
    try:
        pose = Pose(R, t, s)
        if kind == "ref":
            _need(value in models, f"{where}.model.ref", f"no model {value!r} in models")
            model, src = models[value], {}
        else:
            model, src = scene._model(value if kind == "zoo" else Path(value), base)
            src["file" if kind == "file" else "zoo"] = value  # as the file wrote it
        scene._put(iid, model, src, pose, 1.0, params, name)
    except CsdfError as exc:
        raise _Bad(f"{where}: {exc}") from None
