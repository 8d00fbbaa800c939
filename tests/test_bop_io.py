"""BOP-layout I/O (``csdf.io.bop``): the files and keys BOP tools expect, a round trip
that keeps poses exactly and depth to its 0.1 mm quantisation, clipping that says so,
choosing one object of several, atomic writes, and errors that name the file and key."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import csdf
from csdf.io.bop import DepthClipWarning, read_bop, write_bop
from csdf.synth import sequence

W, H = 80, 60
SHAPE = csdf.box((0.3, 0.2, 0.15)) | csdf.sphere(0.08).translate((0.15, 0.0, 0.075))


@pytest.fixture(scope="module")
def seq():
    return sequence(SHAPE, n_frames=4, width=W, height=H, seed=4, occlusion=0.3)


@pytest.fixture
def folder(seq, tmp_path) -> Path:
    return write_bop(seq, tmp_path / "scene" / "000001", obj_id=7)


def load(path: Path):
    return json.loads(path.read_text())


def dump(path: Path, data) -> None:
    path.write_text(json.dumps(data))


def test_files_and_keys(seq, folder):
    names = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())
    assert names == sorted(
        ["scene_camera.json", "scene_gt.json", "scene_gt_info.json"]
        + [f"depth/{k:06d}.png" for k in range(4)]
        + [f"mask_visib/{k:06d}_000000.png" for k in range(4)]
        + [f"mask/{k:06d}_000000.png" for k in range(4)]
        + [f"mask_occluder/{k:06d}.png" for k in range(4)])  # no temporary files left
    cams = load(folder / "scene_camera.json")
    gt = load(folder / "scene_gt.json")
    info = load(folder / "scene_gt_info.json")
    assert sorted(cams) == sorted(gt) == sorted(info) == ["0", "1", "2", "3"]
    assert cams["2"]["depth_scale"] == 0.1
    assert cams["2"]["cam_K"] == seq.camera.K.ravel().tolist()
    (entry,) = gt["2"]
    assert entry["obj_id"] == 7
    np.testing.assert_array_equal(np.reshape(entry["cam_R_m2c"], (3, 3)),
                                  seq.poses[2].rotation)
    np.testing.assert_allclose(entry["cam_t_m2c"], seq.poses[2].translation * 1000.0)
    (inf,) = info["2"]
    assert inf["px_count_visib"] == int(seq.masks[2].sum())
    assert inf["px_count_all"] == int(seq.silhouettes[2].sum())
    assert inf["visib_fract"] == pytest.approx(seq.visib_fract[2])
    rows, cols = np.nonzero(seq.masks[2])
    assert inf["bbox_visib"] == [cols.min(), rows.min(), np.ptp(cols) + 1, np.ptp(rows) + 1]
    with Image.open(folder / "depth" / "000002.png") as im:
        assert im.mode == "I;16" and im.size == (W, H)
        stored = np.array(im)
    np.testing.assert_array_equal(stored, np.rint(seq.depth[2] * 1e4))  # 0.1 mm units
    with Image.open(folder / "mask_visib" / "000002_000000.png") as im:
        assert im.mode == "L"
        np.testing.assert_array_equal(np.array(im), seq.masks[2] * 255)


def test_round_trip(seq, folder):
    back = read_bop(folder)
    assert back.shape == seq.shape
    for a, b in zip(back.poses, seq.poses):
        assert np.max(np.abs(a.translation - b.translation)) < 1e-9  # metres
        D = a.rotation.T @ b.rotation
        assert math.acos(min(1.0, (np.trace(D) - 1) / 2)) < 1e-7  # radians (acos floor)
        assert np.max(np.abs(a.rotation - b.rotation)) < 1e-12
    assert np.max(np.abs(back.depth - seq.depth)) <= 0.5e-4 + 1e-12  # half of 0.1 mm
    np.testing.assert_array_equal(back.depth > 0, seq.depth > 0)
    np.testing.assert_array_equal(back.masks, seq.masks)
    np.testing.assert_array_equal(back.silhouettes, seq.silhouettes)
    np.testing.assert_array_equal(back.occluder_masks, seq.occluder_masks)
    np.testing.assert_allclose(back.visib_fract, seq.visib_fract, rtol=1e-15)
    np.testing.assert_array_equal(back.camera.K, seq.camera.K)
    assert (back.camera.width, back.camera.height) == (W, H)
    # and once more through the files: exactly the same
    again = read_bop(write_bop(back, folder.parent / "again", obj_id=7))
    np.testing.assert_array_equal(again.depth, back.depth)
    assert all(a == b for a, b in zip(again.poses, back.poses))


def test_other_units_and_optional_files(seq, tmp_path):
    mm = dataclasses.replace(seq, depth=seq.depth * 1000.0, poses=[
        csdf.Pose(p.rotation, p.translation * 1000.0) for p in seq.poses])
    folder = write_bop(mm, tmp_path / "mm", mm_per_unit=1.0, depth_scale=1.0)
    assert load(folder / "scene_camera.json")["0"]["depth_scale"] == 1.0
    back = read_bop(folder)  # read in metres
    assert np.max(np.abs(back.depth - seq.depth)) <= 0.5e-3 + 1e-12
    # without mask/, mask_occluder/ and scene_gt_info.json: what can be known
    for sub in ("mask", "mask_occluder"):
        for p in (folder / sub).iterdir():
            p.unlink()
        (folder / sub).rmdir()
    (folder / "scene_gt_info.json").unlink()
    bare = read_bop(folder)
    assert bare.silhouettes is None and not bare.occluder_masks.any()
    assert np.all(np.isnan(bare.visib_fract))
    np.testing.assert_array_equal(bare.masks, seq.masks)


def test_depth_beyond_16_bits_is_clipped_with_a_warning(seq, tmp_path):
    far = dataclasses.replace(seq, depth=seq.depth * 6.0)  # up to ~ 9 m > 6.5535 m
    with pytest.warns(DepthClipWarning, match=r"clipped to 65535.*larger depth_scale"):
        folder = write_bop(far, tmp_path / "far")
    back = read_bop(folder)
    assert back.depth.max() == pytest.approx(6.5535)
    ok = far.depth < 6.5
    assert np.max(np.abs(back.depth[ok] - far.depth[ok])) <= 0.5e-4 + 1e-12
    with warnings.catch_warnings():  # whole millimetres reach 65.535 m: no clipping
        warnings.simplefilter("error")
        coarse = read_bop(write_bop(far, tmp_path / "far1", depth_scale=1.0))
    assert np.max(np.abs(coarse.depth - far.depth)) <= 0.5e-3 + 1e-12


def test_choosing_one_object_of_several(folder):
    gt = load(folder / "scene_gt.json")
    info = load(folder / "scene_gt_info.json")
    other = {"obj_id": 3, "cam_R_m2c": np.eye(3).ravel().tolist(),
             "cam_t_m2c": [0.0, 0.0, 900.0]}
    for key in gt:  # another object first: ours moves to index 1
        gt[key].insert(0, other)
        info[key].insert(0, {"visib_fract": 1.0})
        k = int(key)
        for sub in ("mask_visib", "mask"):
            (folder / sub / f"{k:06d}_000000.png").rename(folder / sub / f"{k:06d}_000001.png")
    dump(folder / "scene_gt.json", gt)
    dump(folder / "scene_gt_info.json", info)
    with pytest.raises(csdf.CsdfError, match=r"lists objects \[3, 7\]; pass obj_id"):
        read_bop(folder)
    back = read_bop(folder, obj_id=7)
    assert back.poses[0].translation[2] != 0.9 and back.masks.any()
    with pytest.raises(csdf.CsdfError, match="image '0' has no object 5"):
        read_bop(folder, obj_id=5)
    with pytest.raises(csdf.CsdfError, match="000000_000000.png: missing"):
        read_bop(folder, obj_id=3)  # its masks were never written


def test_write_errors(seq, tmp_path):
    with pytest.raises(csdf.CsdfError, match="obj_id"):
        write_bop(seq, tmp_path / "a", obj_id=0)
    with pytest.raises(csdf.CsdfError, match="3 poses"):
        write_bop(dataclasses.replace(seq, poses=seq.poses[:3]), tmp_path / "a")
    with pytest.raises(csdf.CsdfError, match="finite and >= 0"):
        write_bop(dataclasses.replace(seq, depth=-seq.depth), tmp_path / "a")
    with pytest.raises(csdf.CsdfError, match="depth_scale"):
        write_bop(seq, tmp_path / "a", depth_scale=0)
    with pytest.raises(csdf.CsdfError, match="Sequence"):
        write_bop({"depth": seq.depth}, tmp_path / "a")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(csdf.CsdfError, match="cannot make folder"):
        write_bop(seq, blocker)


def edit(folder: Path, name: str, change) -> None:
    data = load(folder / name)
    change(data)
    dump(folder / name, data)


@pytest.mark.parametrize("case, match", [
    ("no_folder", r"BOP scene folder .*nope does not exist"),
    ("no_camera", r"scene_camera.json: missing"),
    ("bad_json", r"scene_gt.json: not valid JSON \(line 1, column"),
    ("not_object", r"scene_gt.json: must hold a JSON object"),
    ("bad_key", r"scene_gt.json: key 'first' is not an image id"),
    ("no_t", r"scene_gt.json: image '1', object 0: missing key 'cam_t_m2c'"),
    ("bad_R", r"scene_gt.json: image '2', object 0: 'cam_R_m2c' must be a rotation"),
    ("short_K", r"scene_camera.json: image '0': 'cam_K' must be a list of 9 finite"),
    ("no_scale", r"scene_camera.json: image '3': missing key 'depth_scale'"),
    ("K_differs", r"image '1': 'cam_K' differs"),
    ("camera_gap", r"scene_camera.json: no entry for image '2'"),
    ("no_depth", r"depth/000001.png: missing"),
    ("8bit_depth", r"depth/000001.png: a depth image must be a 16-bit"),
    ("not_png", r"depth/000002.png: not a readable PNG"),
    ("mask_size", r"mask_visib/000003_000000.png: 40x30 pixels, but .* 80x60"),
    ("bad_visib", r"scene_gt_info.json: image '0', object 0: 'visib_fract' must be"),
])
def test_read_errors_name_the_file_and_key(folder, case, match):
    target = folder
    if case == "no_folder":
        target = folder / "nope"
    elif case == "no_camera":
        (folder / "scene_camera.json").unlink()
    elif case == "bad_json":
        (folder / "scene_gt.json").write_text('{"0": [}')
    elif case == "not_object":
        (folder / "scene_gt.json").write_text("[1, 2]")
    elif case == "bad_key":
        edit(folder, "scene_gt.json", lambda d: d.update(first=d["0"]))
    elif case == "no_t":
        edit(folder, "scene_gt.json", lambda d: d["1"][0].pop("cam_t_m2c"))
    elif case == "bad_R":
        edit(folder, "scene_gt.json", lambda d: d["2"][0].update(cam_R_m2c=[1] * 9))
    elif case == "short_K":
        edit(folder, "scene_camera.json", lambda d: d["0"].update(cam_K=[1, 2, 3]))
    elif case == "no_scale":
        edit(folder, "scene_camera.json", lambda d: d["3"].pop("depth_scale"))
    elif case == "K_differs":
        edit(folder, "scene_camera.json", lambda d: d["1"]["cam_K"].__setitem__(0, 99.0))
    elif case == "camera_gap":
        edit(folder, "scene_camera.json", lambda d: d.pop("2"))
    elif case == "no_depth":
        (folder / "depth" / "000001.png").unlink()
    elif case == "8bit_depth":
        Image.fromarray(np.zeros((H, W), np.uint8)).save(folder / "depth" / "000001.png")
    elif case == "not_png":
        (folder / "depth" / "000002.png").write_bytes(b"not an image")
    elif case == "mask_size":
        Image.fromarray(np.zeros((30, 40), np.uint8)).save(
            folder / "mask_visib" / "000003_000000.png")
    elif case == "bad_visib":
        edit(folder, "scene_gt_info.json", lambda d: d["0"][0].update(visib_fract="all"))
    with pytest.raises(csdf.CsdfError, match=match):
        read_bop(target)
