"""Depth sequences in the BOP layout (the data format of the BOP benchmark for 6D
object pose estimation): :func:`write_bop` writes a :class:`csdf.synth.Sequence` as
one BOP scene folder and :func:`read_bop` reads one back.

A scene folder holds:

* ``scene_camera.json``: per image (keys ``"0"``, ``"1"``, ...) ``cam_K``, the 3x3
  intrinsic matrix row-major, and ``depth_scale``, the millimetres per unit of the
  stored depth;
* ``scene_gt.json``: per image a list of ``{"obj_id", "cam_R_m2c", "cam_t_m2c"}``:
  the model-to-camera rotation (row-major 3x3) and translation (millimetres);
* ``scene_gt_info.json``: per image and object ``bbox_obj``, ``bbox_visib``
  (``[x, y, width, height]`` pixels, ``-1`` when empty), ``px_count_all``,
  ``px_count_valid``, ``px_count_visib`` and ``visib_fract``;
* ``depth/IIIIII.png``: 16-bit depth along the optical axis, in units of
  ``depth_scale`` millimetres (0: missing);
* ``mask_visib/IIIIII_GGGGGG.png`` and ``mask/IIIIII_GGGGGG.png``: 8-bit masks (255
  inside) of the visible part and of the whole silhouette of object ``GGGGGG`` (its
  index in the image's ``scene_gt`` list);
* ``mask_occluder/IIIIII.png`` (csdf's own addition, ignored by BOP tools): the pixels
  of a :func:`csdf.synth.sequence` occluder, written when there is one;
* ``rgb/IIIIII.png``: 8-bit RGB colour images of the same camera, written when the
  sequence has colours (``sequence(colors=True)``); read as RGB floats in [0, 1].

Model units are converted with ``mm_per_unit`` (1000: the model is in metres). Every
file is written atomically (:func:`csdf.io.atomic_path`); the JSON files are written
after the images, so a folder whose writing was interrupted does not list images that
are not there. ``import csdf.io.bop`` does not load the renderer (nor Numba).
"""

from __future__ import annotations

import json
import math
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..pose import Pose
from ..synth import MAX_SEQUENCE_PIXELS, Sequence
from .atomic import atomic_path

__all__ = ["write_bop", "read_bop", "read_frames", "read_rgb", "DepthClipWarning",
           "DEPTH_SCALE", "MAX_DEPTH_VALUE"]

#: default ``depth_scale``: stored depth in tenths of a millimetre
DEPTH_SCALE = 0.1
#: largest value of a 16-bit depth PNG
MAX_DEPTH_VALUE = 65535
#: a rotation read from a file whose rows are orthonormal only to this is made exactly
#: orthonormal (files written with few digits); worse is an error
_ROT_REPAIR_TOL = 1e-3


class DepthClipWarning(UserWarning):
    """:func:`write_bop` clipped depths beyond the 16-bit range of the PNG files (the
    message says how many pixels and the largest depth that fits)."""


def _pil():
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - Pillow is a dependency
        raise CsdfError("BOP images need Pillow: pip install pillow") from None
    return Image


# ------------------------------------------------------------------------- writing
def _check_sequence(seq: Sequence) -> tuple[int, int, int]:
    """``(N, H, W)`` of a sequence whose arrays agree; CsdfError naming what does not."""
    from ..render.camera import Camera  # (the renderer loads Numba: only when needed)

    if not isinstance(seq, Sequence):
        raise CsdfError(f"write_bop expects a csdf.synth.Sequence, got {type(seq).__name__}")
    depth = np.asarray(seq.depth)
    if depth.ndim != 3 or depth.shape[0] < 1:
        raise CsdfError(f"sequence depth must have shape (N, H, W), got {depth.shape}")
    n, h, w = depth.shape
    if not isinstance(seq.camera, Camera):
        raise CsdfError("the sequence's camera must be a csdf.Camera")
    if (seq.camera.width, seq.camera.height) != (w, h):
        raise CsdfError(f"the camera is {seq.camera.width}x{seq.camera.height} pixels but "
                        f"the depth images are {w}x{h}")
    if not np.issubdtype(depth.dtype, np.number) or np.any(~np.isfinite(depth)) \
            or np.any(depth < 0):
        raise CsdfError("sequence depth must be finite and >= 0 (0 = missing)")
    for name in ("masks", "occluder_masks", "silhouettes"):
        a = getattr(seq, name)
        if a is None and name == "silhouettes":
            continue
        if np.shape(a) != (n, h, w):
            raise CsdfError(f"sequence {name} must have shape {(n, h, w)}, got "
                            f"{np.shape(a)}")
    if len(seq.poses) != n:
        raise CsdfError(f"the sequence has {n} depth images but {len(seq.poses)} poses")
    for k, p in enumerate(seq.poses):
        if not isinstance(p, Pose) or p.scale != 1.0:
            raise CsdfError(f"pose {k} must be a rigid csdf.Pose (scale 1)")
    if np.shape(seq.visib_fract) != (n,):
        raise CsdfError(f"sequence visib_fract must have shape ({n},), got "
                        f"{np.shape(seq.visib_fract)}")
    return n, h, w


def _bbox(mask: np.ndarray) -> list[int]:
    """``[x, y, width, height]`` of a mask's pixels, ``[-1, -1, -1, -1]`` when empty."""
    rows = np.flatnonzero(mask.any(1))
    cols = np.flatnonzero(mask.any(0))
    if rows.size == 0:
        return [-1, -1, -1, -1]
    return [int(cols[0]), int(rows[0]), int(cols[-1] - cols[0] + 1),
            int(rows[-1] - rows[0] + 1)]


def _write_png(path: Path, array: np.ndarray) -> None:
    Image = _pil()
    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(array)).save(tmp, format="PNG")


def _write_json(path: Path, data: Any) -> None:
    text = json.dumps(data, indent=2, allow_nan=False)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n")


def _positive(v, name: str) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise CsdfError(f"{name} must be a positive number, got {v!r}") from None
    if not (math.isfinite(x) and x > 0):
        raise CsdfError(f"{name} must be a positive finite number, got {x}")
    return x


def write_bop(sequence: Sequence, folder: str | os.PathLike, obj_id: int = 1, *,
              depth_scale: float = DEPTH_SCALE, mm_per_unit: float = 1000.0) -> Path:
    """Write a sequence as a BOP scene folder (see the module docs for the files).

    Args:
        sequence: a :class:`csdf.synth.Sequence` (depth in model units, 0 = missing;
            model-to-camera poses).
        folder: the scene folder; made (with its parents) if needed. Files of the same
            names are replaced; others are left alone.
        obj_id: the object's BOP id (a positive integer).
        depth_scale: millimetres per unit of the stored depth (default 0.1: depth PNGs
            in tenths of a millimetre, up to 6.5535 m).
        mm_per_unit: millimetres per model unit (1000 for a model in metres).

    Returns:
        The folder's path.

    Warns:
        DepthClipWarning: depths beyond ``65535 * depth_scale`` millimetres were stored
            as 65535 (the message gives the count and the largest depth that fits).

    Raises:
        CsdfError: a sequence whose arrays disagree, negative or non-finite depths,
            poses that are not rigid, a bad ``obj_id`` or scale, or a file that cannot
            be written (naming it).
    """
    n, h, w = _check_sequence(sequence)
    if isinstance(obj_id, bool) or not isinstance(obj_id, (int, np.integer)) or obj_id < 1:
        raise CsdfError(f"obj_id must be a positive integer, got {obj_id!r}")
    obj_id = int(obj_id)
    depth_scale = _positive(depth_scale, "depth_scale")
    mm_per_unit = _positive(mm_per_unit, "mm_per_unit")
    root = Path(folder)
    sil = sequence.silhouettes
    occ = np.asarray(sequence.occluder_masks, dtype=bool)
    rgb = getattr(sequence, "colors", None)
    subfolders = ["depth", "mask_visib"] + (["mask"] if sil is not None else []) \
        + (["mask_occluder"] if occ.any() else []) + (["rgb"] if rgb is not None else [])
    for sub in subfolders:
        try:
            (root / sub).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CsdfError(f"cannot make folder {root / sub}: "
                            f"{exc.strerror or exc}") from None

    depth = np.asarray(sequence.depth, dtype=np.float64)
    stored = np.rint(depth * (mm_per_unit / depth_scale))
    stored[(depth > 0) & (stored < 1)] = 1  # a tiny depth stays a return
    over = stored > MAX_DEPTH_VALUE
    if over.any():
        warnings.warn(
            f"write_bop: {int(over.sum())} depth pixels beyond "
            f"{MAX_DEPTH_VALUE * depth_scale / mm_per_unit:g} model units "
            f"({MAX_DEPTH_VALUE} x depth_scale {depth_scale:g} mm) were clipped to "
            f"{MAX_DEPTH_VALUE}; pass a larger depth_scale to keep them",
            DepthClipWarning, stacklevel=2)
        stored[over] = MAX_DEPTH_VALUE
    stored = stored.astype(np.uint16)
    masks = np.asarray(sequence.masks, dtype=bool)
    K = sequence.camera.K.ravel().tolist()
    cameras: dict[str, Any] = {}
    gts: dict[str, Any] = {}
    infos: dict[str, Any] = {}
    for k in range(n):
        _write_png(root / "depth" / f"{k:06d}.png", stored[k])
        _write_png(root / "mask_visib" / f"{k:06d}_000000.png",
                   masks[k].astype(np.uint8) * 255)
        if sil is not None:
            _write_png(root / "mask" / f"{k:06d}_000000.png",
                       np.asarray(sil[k], dtype=np.uint8) * 255)
        if occ.any():
            _write_png(root / "mask_occluder" / f"{k:06d}.png", occ[k].astype(np.uint8) * 255)
        if rgb is not None:
            _write_png(root / "rgb" / f"{k:06d}.png",
                       np.rint(np.clip(rgb[k], 0.0, 1.0) * 255).astype(np.uint8))
        pose = sequence.poses[k]
        cameras[str(k)] = {"cam_K": K, "depth_scale": depth_scale}
        gts[str(k)] = [{"cam_R_m2c": pose.rotation.ravel().tolist(),
                        "cam_t_m2c": (pose.translation * mm_per_unit).tolist(),
                        "obj_id": obj_id}]
        info: dict[str, Any] = {}
        if sil is not None:
            s = np.asarray(sil[k], dtype=bool)
            info["bbox_obj"] = _bbox(s)
            info["px_count_all"] = int(s.sum())
            info["px_count_valid"] = int((s & (stored[k] > 0)).sum())
        info["bbox_visib"] = _bbox(masks[k])
        info["px_count_visib"] = int(masks[k].sum())
        vf = float(sequence.visib_fract[k])
        if math.isfinite(vf):
            info["visib_fract"] = vf
        infos[str(k)] = [info]
    _write_json(root / "scene_gt_info.json", infos)
    _write_json(root / "scene_gt.json", gts)
    _write_json(root / "scene_camera.json", cameras)
    return root


# ------------------------------------------------------------------------- reading
def _load_json(path: Path) -> dict:
    """A JSON file whose top level is an object; CsdfError naming the file otherwise."""
    if not path.is_file():
        raise CsdfError(f"{path}: missing (a BOP scene folder needs it)")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise CsdfError(f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: "
                        f"{exc.msg})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CsdfError(f"{path}: cannot read it ({exc})") from None
    if not isinstance(data, dict):
        raise CsdfError(f"{path}: must hold a JSON object keyed by image id, got "
                        f"{type(data).__name__}")
    return data


def _numbers(value: Any, n: int, where: str) -> np.ndarray:
    """``value`` as ``(n,)`` finite float64; CsdfError naming ``where`` otherwise."""
    ok = (isinstance(value, list) and len(value) == n
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    a = np.asarray(value, dtype=np.float64) if ok else None
    if a is None or not np.all(np.isfinite(a)):
        raise CsdfError(f"{where} must be a list of {n} finite numbers, got "
                        f"{json.dumps(value)[:80]}")
    return a


def _entry(data: dict, path: Path, image: str, key: str) -> Any:
    """``data[image][key]``; CsdfError naming the file, image and key when missing."""
    item = data.get(image)
    if not isinstance(item, dict):
        raise CsdfError(f"{path}: image {image!r} must be a JSON object, got "
                        f"{type(item).__name__}")
    if key not in item:
        raise CsdfError(f"{path}: image {image!r}: missing key {key!r}")
    return item[key]


def _rotation(value: Any, where: str) -> np.ndarray:
    R = _numbers(value, 9, where).reshape(3, 3)
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > 1e-6 or np.linalg.det(R) < 0:
        if err > _ROT_REPAIR_TOL or np.linalg.det(R) < 0:
            raise CsdfError(f"{where} must be a rotation (orthonormal, determinant +1); "
                            f"|R^T R - I| = {err:.3g}")
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
    return R


def _read_png(path: Path, kind: str, size: tuple[int, int] | None) -> np.ndarray:
    """A PNG as a 2D array: ``kind`` ``'depth'`` (16-bit, uint16 values) or ``'mask'``
    (8-bit or 1-bit, bool); ``size`` ``(W, H)`` to check."""
    if not path.is_file():
        raise CsdfError(f"{path}: missing")
    Image = _pil()
    try:
        with Image.open(path) as im:
            im.load()
            mode, wh = im.mode, im.size
            if kind == "depth" and mode not in ("I;16", "I;16B", "I;16L", "I"):
                raise CsdfError(f"{path}: a depth image must be a 16-bit grayscale PNG, "
                                f"got mode {mode!r}")
            if kind == "mask" and mode not in ("1", "L", "P", "I;16", "I"):
                raise CsdfError(f"{path}: a mask must be a grayscale PNG, got mode {mode!r}")
            if kind == "rgb":
                if mode not in ("RGB", "RGBA", "L", "P"):
                    raise CsdfError(f"{path}: a colour image must be an 8-bit RGB PNG, "
                                    f"got mode {mode!r}")
                a = np.array(im.convert("RGB"))
            else:
                a = np.array(im)
    except CsdfError:
        raise
    except Exception as exc:  # noqa: BLE001 - Pillow raises many kinds for bad files
        raise CsdfError(f"{path}: not a readable PNG image ({exc})") from None
    if size is not None and wh != size:
        raise CsdfError(f"{path}: {wh[0]}x{wh[1]} pixels, but the scene's depth images "
                        f"are {size[0]}x{size[1]}")
    if kind == "rgb":
        return a.astype(np.float32) / 255.0
    if kind == "depth":
        if a.min(initial=0) < 0 or a.max(initial=0) > MAX_DEPTH_VALUE:
            raise CsdfError(f"{path}: depth values outside 0..{MAX_DEPTH_VALUE}")
        return a.astype(np.uint16)
    return a > 0


def _image_ids(gt: dict, path: Path) -> list[str]:
    ids = []
    for key in gt:
        try:
            ok = str(int(key)) == key and int(key) >= 0
        except ValueError:
            ok = False
        if not ok:
            raise CsdfError(f"{path}: key {key!r} is not an image id (a non-negative "
                            "integer)")
        ids.append(key)
    if not ids:
        raise CsdfError(f"{path}: lists no images")
    return sorted(ids, key=int)


def _pick(gt: dict, path: Path, ids: list[str], obj_id: int | None) -> tuple[int, list[int]]:
    """The object id to read and, per image, the index of its entry in ``scene_gt``."""
    lists = []
    for key in ids:
        entries = gt[key]
        if not isinstance(entries, list):
            raise CsdfError(f"{path}: image {key!r} must be a list of objects, got "
                            f"{type(entries).__name__}")
        ids_here = []
        for g, e in enumerate(entries):
            v = e.get("obj_id") if isinstance(e, dict) else None
            if isinstance(v, bool) or not isinstance(v, int):
                raise CsdfError(f"{path}: image {key!r}, object {g}: missing or bad "
                                f"key 'obj_id' (an integer), got {json.dumps(v)}")
            ids_here.append(v)
        lists.append(ids_here)
    if obj_id is None:
        found = sorted({v for ids_here in lists for v in ids_here})
        if len(found) != 1:
            raise CsdfError(f"{path} lists objects {found}; pass obj_id= to choose one")
        obj_id = found[0]
    index = []
    for key, ids_here in zip(ids, lists):
        hits = [g for g, v in enumerate(ids_here) if v == obj_id]
        if len(hits) != 1:
            what = "no" if not hits else f"{len(hits)} instances of"
            raise CsdfError(f"{path}: image {key!r} has {what} object {obj_id}; a "
                            "sequence follows exactly one instance per image")
        index.append(hits[0])
    return obj_id, index


def _intrinsics(cams: dict, cam_path: Path, ids: list[str]) -> tuple[np.ndarray, list[float]]:
    """The one ``cam_K`` (3, 3) of images ``ids`` in ``scene_camera.json`` and each
    image's ``depth_scale``."""
    K0 = None
    scales = []
    for key in ids:
        K = _numbers(_entry(cams, cam_path, key, "cam_K"), 9,
                     f"{cam_path}: image {key!r}: 'cam_K'").reshape(3, 3)
        if K0 is None:
            if (K[0, 1] != 0 or K[1, 0] != 0 or np.any(K[2] != [0.0, 0.0, 1.0])
                    or K[0, 0] <= 0 or K[1, 1] <= 0):
                raise CsdfError(f"{cam_path}: image {key!r}: 'cam_K' must be "
                                "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
            K0 = K
        elif not np.allclose(K, K0, rtol=1e-9, atol=0.0):
            raise CsdfError(f"{cam_path}: image {key!r}: 'cam_K' differs from image "
                            f"{ids[0]!r}'s; a sequence has one camera")
        v = _entry(cams, cam_path, key, "depth_scale")
        if isinstance(v, bool) or not isinstance(v, (int, float)) \
                or not (math.isfinite(v) and v > 0):
            raise CsdfError(f"{cam_path}: image {key!r}: 'depth_scale' must be a "
                            f"positive number, got {json.dumps(v)}")
        scales.append(float(v))
    return K0, scales


def _first_depth(root: Path, ids: list[str]) -> np.ndarray:
    """The first image's raw depth, its size checked, and the whole sequence's."""
    from ..render.camera import check_resolution

    first = _read_png(root / "depth" / f"{int(ids[0]):06d}.png", "depth", None)
    h, w = first.shape
    check_resolution(w, h)
    if len(ids) * w * h > MAX_SEQUENCE_PIXELS:
        raise CsdfError(f"{root}: {len(ids)} images of {w}x{h} pixels are over the limit "
                        f"of {MAX_SEQUENCE_PIXELS:,} pixels in all")
    return first


def read_bop(folder: str | os.PathLike, obj_id: int | None = None, *,
             mm_per_unit: float = 1000.0) -> Sequence:
    """Read a BOP scene folder (as :func:`write_bop` writes, or one of the BOP
    datasets') into a :class:`csdf.synth.Sequence`, one object's view of every image.

    Args:
        folder: the scene folder.
        obj_id: the object to follow (default: the only one the scene lists); each
            image must show exactly one instance of it.
        mm_per_unit: millimetres per model unit of the result (1000: metres).

    Returns:
        :class:`csdf.synth.Sequence`: depth in model units (0 = missing), images in
        increasing id order; ``silhouettes`` from ``mask/`` (None without that folder);
        ``occluder_masks`` from ``mask_occluder/`` (all False without it);
        ``visib_fract`` from ``scene_gt_info.json``, else from the masks and
        silhouettes, else NaN. The camera's pose is the identity.

    Raises:
        CsdfError: naming the file (and image and key): a missing folder or file,
            invalid JSON, a missing or malformed key, images of different sizes or
            intrinsics, a rotation that is not one, an object id that is absent or
            ambiguous, depth images that are not 16-bit PNGs, a scene over
            :data:`csdf.synth.MAX_SEQUENCE_PIXELS` pixels.
    """
    from ..render.camera import Camera

    root = Path(folder)
    if not root.is_dir():
        raise CsdfError(f"BOP scene folder {root} does not exist or is not a folder")
    mm_per_unit = _positive(mm_per_unit, "mm_per_unit")
    cam_path, gt_path = root / "scene_camera.json", root / "scene_gt.json"
    cams = _load_json(cam_path)
    gt = _load_json(gt_path)
    ids = _image_ids(gt, gt_path)
    _, index = _pick(gt, gt_path, ids, obj_id)
    for key in ids:
        if key not in cams:
            raise CsdfError(f"{cam_path}: no entry for image {key!r} (listed in "
                            f"{gt_path.name})")

    K0, scales = _intrinsics(cams, cam_path, ids)

    poses = []
    for key, g in zip(ids, index):
        e = gt[key][g]
        where = f"{gt_path}: image {key!r}, object {g}"
        for name in ("cam_R_m2c", "cam_t_m2c"):
            if name not in e:
                raise CsdfError(f"{where}: missing key {name!r}")
        R = _rotation(e["cam_R_m2c"], f"{where}: 'cam_R_m2c'")
        t = _numbers(e["cam_t_m2c"], 3, f"{where}: 'cam_t_m2c'") / mm_per_unit
        poses.append(Pose(R, t))

    first = _first_depth(root, ids)
    h, w = first.shape
    n = len(ids)
    depth = np.empty((n, h, w))
    masks = np.empty((n, h, w), dtype=bool)
    sil = np.empty((n, h, w), dtype=bool) if (root / "mask").is_dir() else None
    occ = np.zeros((n, h, w), dtype=bool)
    has_occ = (root / "mask_occluder").is_dir()
    for k, (key, g) in enumerate(zip(ids, index)):
        im = int(key)
        raw = first if k == 0 else _read_png(root / "depth" / f"{im:06d}.png", "depth",
                                             (w, h))
        depth[k] = raw * (scales[k] / mm_per_unit)
        masks[k] = _read_png(root / "mask_visib" / f"{im:06d}_{g:06d}.png", "mask", (w, h))
        if sil is not None:
            sil[k] = _read_png(root / "mask" / f"{im:06d}_{g:06d}.png", "mask", (w, h))
        if has_occ:
            occ[k] = _read_png(root / "mask_occluder" / f"{im:06d}.png", "mask", (w, h))

    visib = np.full(n, np.nan)
    info_path = root / "scene_gt_info.json"
    if info_path.exists():
        info = _load_json(info_path)
        for k, (key, g) in enumerate(zip(ids, index)):
            entries = info.get(key)
            if entries is None:
                continue
            if not isinstance(entries, list) or g >= len(entries) \
                    or not isinstance(entries[g], dict):
                raise CsdfError(f"{info_path}: image {key!r} must be a list with an "
                                f"object at index {g}")
            v = entries[g].get("visib_fract")
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) \
                    or not 0.0 <= v <= 1.0:
                raise CsdfError(f"{info_path}: image {key!r}, object {g}: "
                                f"'visib_fract' must be a number in [0, 1], got "
                                f"{json.dumps(v)}")
            visib[k] = float(v)
    if sil is not None:
        todo = np.isnan(visib)
        total = sil.sum((1, 2))
        visib[todo] = np.where(total[todo] > 0,
                               masks[todo].sum((1, 2)) / np.maximum(total[todo], 1), 0.0)
    camera = Camera(K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2], w, h)
    return Sequence(depth=depth, masks=masks, poses=poses, camera=camera,
                    occluder_masks=occ, visib_fract=visib, silhouettes=sil,
                    colors=read_rgb(root, [int(i) for i in ids], (w, h)))


def read_rgb(folder: str | os.PathLike, ids: list[int], size: tuple[int, int]
             ) -> np.ndarray | None:
    """The colour images ``rgb/IIIIII.png`` of images ``ids`` of a BOP scene folder,
    ``(N, H, W, 3)`` float32 RGB in [0, 1] (``size`` ``(W, H)``, checked), or None when
    the folder has no ``rgb/``.

    Raises:
        CsdfError: a missing or unreadable image, or one of another size (naming it).
    """
    root = Path(folder) / "rgb"
    if not root.is_dir():
        return None
    w, h = size
    out = np.empty((len(ids), h, w, 3), dtype=np.float32)
    for k, im in enumerate(ids):
        out[k] = _read_png(root / f"{int(im):06d}.png", "rgb", size)
    return out


def read_frames(folder: str | os.PathLike, *, mm_per_unit: float = 1000.0
                ) -> tuple[np.ndarray, np.ndarray | None, Any, list[int]]:
    """The depth frames of a BOP-layout folder without ground truth (what a tracker
    reads): ``scene_camera.json`` and ``depth/``, with ``mask_visib/`` masks of the
    first object where that folder exists.

    Returns:
        ``(depth (N, H, W) model units, 0 = missing; masks (N, H, W) bool or None;
        camera (csdf.Camera); image ids)``, in increasing id order.

    Raises:
        CsdfError: as :func:`read_bop`, naming the file.
    """
    from ..render.camera import Camera

    root = Path(folder)
    if not root.is_dir():
        raise CsdfError(f"BOP scene folder {root} does not exist or is not a folder")
    mm_per_unit = _positive(mm_per_unit, "mm_per_unit")
    cam_path = root / "scene_camera.json"
    cams = _load_json(cam_path)
    ids = _image_ids(cams, cam_path)
    K0, scales = _intrinsics(cams, cam_path, ids)
    first = _first_depth(root, ids)
    h, w = first.shape
    depth = np.empty((len(ids), h, w))
    has_masks = (root / "mask_visib").is_dir()
    masks = np.empty((len(ids), h, w), dtype=bool) if has_masks else None
    for k, key in enumerate(ids):
        im = int(key)
        raw = first if k == 0 else _read_png(root / "depth" / f"{im:06d}.png", "depth",
                                             (w, h))
        depth[k] = raw * (scales[k] / mm_per_unit)
        if masks is not None:
            masks[k] = _read_png(root / "mask_visib" / f"{im:06d}_000000.png", "mask",
                                 (w, h))
    camera = Camera(K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2], w, h)
    return depth, masks, camera, [int(i) for i in ids]
