"""``csdf track`` and ``csdf metrics`` (issue 18) on a small BOP-layout sequence written
by ``csdf.io.write_bop``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import csdf
from csdf.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("bop")
    seq = csdf.synth.sequence(csdf.zoo.load("cross_shaft"), n_frames=6, seed=3,
                              width=120, height=90)
    csdf.io.write_bop(seq, root / "scene")
    gt = json.loads((root / "scene" / "scene_gt.json").read_text())
    (root / "init.json").write_text(json.dumps(gt["0"][0]))
    return root, seq


def test_track_then_metrics(scene):
    root, seq = scene
    poses = root / "poses.json"
    r = runner.invoke(app, ["track", "cross_shaft", str(root / "scene"), "-o", str(poses),
                            "--init", str(root / "init.json")])
    assert r.exit_code == 0, r.output
    doc = json.loads(poses.read_text())
    assert [f["image_id"] for f in doc["frames"]] == list(range(6))
    for f, gt in zip(doc["frames"], seq.poses):
        t = np.array(f["cam_t_m2c"]) / 1000.0
        assert np.linalg.norm(t - gt.translation) < 0.005  # 4 % of the 12 cm part
        assert f["success"]
    out = root / "m.json"
    r = runner.invoke(app, ["metrics", "cross_shaft", str(root / "scene"), str(poses),
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    summary = json.loads(out.read_text())["summary"]
    assert summary["AR_MSSD"] > 0.9 and summary["AR_VSD"] > 0.8 and 0 <= summary["AR"] <= 1
    # the ground truth scored against itself is perfect
    r = runner.invoke(app, ["metrics", "cross_shaft", str(root / "scene"),
                            str(root / "scene" / "scene_gt.json"), "--no-vsd"])
    assert r.exit_code == 0 and "AR_MSSD: 1" in r.output and "AR_MSPD: 1" in r.output


def test_bad_inputs_are_named(scene, tmp_path):
    root, _ = scene
    r = runner.invoke(app, ["track", "teapot", str(root / "scene"), "-o",
                            str(tmp_path / "p.json")])
    assert r.exit_code != 0 and "not a zoo model" in r.output
    r = runner.invoke(app, ["track", "cross_shaft", str(tmp_path / "none"), "-o",
                            str(tmp_path / "p.json")])
    assert r.exit_code != 0 and "does not exist" in r.output
    bad = tmp_path / "init.json"
    bad.write_text('{"cam_R_m2c": [1, 0, 0]}')
    r = runner.invoke(app, ["track", "cross_shaft", str(root / "scene"), "-o",
                            str(tmp_path / "p.json"), "--init", str(bad)])
    assert r.exit_code != 0 and "cam_R_m2c (9 finite numbers, row-major) and cam_t_m2c" in r.output
    assert not (tmp_path / "p.json").exists()
    r = runner.invoke(app, ["metrics", "cross_shaft", str(root / "scene"), str(bad)])
    assert r.exit_code != 0 and "cam_t_m2c" in r.output


def test_poses_that_are_not_rotations_and_missing_estimates(scene, tmp_path):
    root, _ = scene
    bad = tmp_path / "init.json"
    bad.write_text(json.dumps({"cam_R_m2c": [2, 0, 0, 0, 1, 0, 0, 0, 1],
                               "cam_t_m2c": [0, 0, 500]}))
    r = runner.invoke(app, ["track", "cross_shaft", str(root / "scene"), "-o",
                            str(tmp_path / "p.json"), "--init", str(bad)])
    assert r.exit_code != 0 and "cam_R_m2c is not a rotation" in r.output
    empty = tmp_path / "none.json"
    empty.write_text("{}")
    r = runner.invoke(app, ["metrics", "cross_shaft", str(root / "scene"), str(empty)])
    assert r.exit_code != 0 and "no pose for any image" in r.output


def test_track_with_colour_images_from_a_bop_folder(tmp_path):
    from csdf.io.bop import read_bop

    shape = csdf.zoo.load("cross_shaft")
    seq = csdf.synth.sequence(shape, n_frames=4, seed=5, width=120, height=90,
                              colors=True)
    csdf.io.write_bop(seq, tmp_path / "scene")
    back = read_bop(tmp_path / "scene")
    assert back.colors.shape == (4, 90, 120, 3)
    assert np.abs(back.colors - seq.colors).max() <= 0.5 / 255 + 1e-6  # 8-bit PNGs
    gt = json.loads((tmp_path / "scene" / "scene_gt.json").read_text())
    (tmp_path / "init.json").write_text(json.dumps(gt["0"][0]))
    poses = tmp_path / "poses.json"
    r = runner.invoke(app, ["track", "cross_shaft", str(tmp_path / "scene"), "-o",
                            str(poses), "--init", str(tmp_path / "init.json"),
                            "--no-masks"])
    assert r.exit_code == 0, r.output
    for f, truth in zip(json.loads(poses.read_text())["frames"], seq.poses):
        assert f["success"]
        assert np.linalg.norm(np.array(f["cam_t_m2c"]) / 1000 - truth.translation) < 0.005
    (tmp_path / "scene" / "rgb" / "000002.png").write_bytes(b"not a png")
    r = runner.invoke(app, ["track", "cross_shaft", str(tmp_path / "scene"), "-o",
                            str(poses), "--init", str(tmp_path / "init.json")])
    assert r.exit_code != 0 and "000002.png: not a readable PNG" in r.output
    r = runner.invoke(app, ["track", "cross_shaft", str(tmp_path / "scene"), "-o",
                            str(poses), "--init", str(tmp_path / "init.json"),
                            "--no-colors"])
    assert r.exit_code == 0, r.output
