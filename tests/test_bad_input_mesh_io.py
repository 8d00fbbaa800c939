"""Bad input to meshing, file I/O and the CLI's loaders (issue 15): every one is a clear
:class:`csdf.CsdfError` naming the argument (or file) and its limits, never a stray
``ValueError``/``OverflowError``/``OSError``, and the CLI exits with status 2."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import csdf
from csdf.cli import app
from csdf.io import atomic_path, read_point_properties, read_points

runner = CliRunner()


def _mesh(shape, **kw):
    return csdf.mesh(shape, progress=False, **kw)


# ---------------------------------------------------------------------- csdf.mesh
@pytest.mark.parametrize("kw, words", [
    (dict(voxel_size=5e-324), ("voxel_size", "4096", "at least")),
    (dict(voxel_size=1e300), ("voxel_size", "empty", "at most")),
    (dict(voxel_size="a"), ("voxel_size", "positive number", "'a'")),
    (dict(voxel_size=10**400), ("voxel_size", "positive number")),
    (dict(voxel_size=True), ("voxel_size", "positive number")),
    (dict(voxel_size=float("nan")), ("voxel_size", "positive number")),
    (dict(resolution=2**1100), ("resolution", "4091", "1101 bits")),
    (dict(resolution=1), ("resolution", "[2, 4091]")),
    (dict(resolution=2.5), ("resolution", "integer")),
    (dict(resolution=np.float64(64.0)), ("resolution", "integer", "got 64")),
    (dict(voxel_size=np.float64(-1.0)), ("voxel_size", "positive", "got -1")),
    (dict(voxel_size=[0.1]), ("voxel_size", "positive", "a list")),
    (dict(bounds=((-1e308,) * 3, (1e308,) * 3)), ("bounds", "too large")),
])
def test_mesh_argument_errors_name_the_argument_and_its_limits(kw, words):
    with pytest.raises(csdf.CsdfError) as info:
        _mesh(csdf.sphere(1.0), **kw)
    msg = str(info.value)
    for w in words:
        assert w in msg, msg
    assert "np.float64" not in msg and "np.int64" not in msg, msg


def test_mesh_of_a_point_sized_shape_is_an_error():
    with pytest.raises(csdf.CsdfError, match="zero size"):
        _mesh(csdf.sphere(0))


def test_mesh_bounds_too_small_for_float64():
    with pytest.raises(csdf.CsdfError, match="bounds"):
        _mesh(csdf.sphere(1.0), bounds=((1e10, 1e10, 1e10), (1e10 + 1e-5,) * 3))


def test_voxel_size_limits_are_inclusive_and_meshable():
    s = csdf.sphere(1.0)
    m = _mesh(s, voxel_size=1.0)  # half the longest side: allowed (coarse, maybe empty)
    assert m.metadata["csdf"]["voxel_size"] == 1.0
    assert len(_mesh(s, voxel_size=0.25).faces) > 0
    assert len(_mesh(s, resolution=2).vertices) >= 0


def test_empty_intersection_message_has_plain_numbers():
    empty = csdf.sphere(1.0) & csdf.sphere(1.0).translate((5, 0, 0))
    with pytest.raises(csdf.CsdfError) as info:
        _mesh(empty)
    assert "np." not in str(info.value)
    with pytest.raises(csdf.CsdfError) as info:
        _mesh(csdf.sphere(1.0), bounds=(np.array([1.0, 1, 1]), np.array([0.0, 0, 0])))
    assert "np." not in str(info.value)
    # the interval check that an empty box (lo > hi, an intersection's box) reaches
    with pytest.raises(csdf.CsdfError) as info:
        csdf.as_field(csdf.sphere(1.0)).intervals(np.array([[4.0, 0, 0]]),
                                                  np.array([[1.0, 1, 1]]))
    msg = str(info.value)
    assert "np." not in msg and "lo[0] = 4.0 > hi[0] = 1.0" in msg, msg


# ---------------------------------------------------------------------- PLY reading
_HEAD_BIN = ("ply\nformat binary_little_endian 1.0\nelement other 1\nproperty float a\n"
             "property float a\nelement vertex 1\nproperty float x\nproperty float y\n"
             "property float z\nend_header\n")


def test_ply_duplicate_property_names_file_and_property(tmp_path):
    p = tmp_path / "dup.ply"
    p.write_bytes(_HEAD_BIN.encode() + struct.pack("<5f", 1, 2, 3, 4, 5))
    with pytest.raises(csdf.CsdfError) as info:
        read_points(p)
    msg = str(info.value)
    assert str(p) in msg and "'a'" in msg and "twice" in msg, msg
    q = tmp_path / "dupv.ply"
    q.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                 "property float y\nproperty float z\nproperty float y\nend_header\n"
                 "0 0 0 0\n")
    with pytest.raises(csdf.CsdfError, match=r"dupv\.ply.*'y'"):
        read_points(q)


_HEAD_ASCII = ("ply\nformat ascii 1.0\ncomment c\nelement vertex 3\nproperty float x\n"
               "property float y\nproperty float z\nproperty {t} v\nend_header\n"
               "0 0 0 {a}\n\n1 1 1 {b}\n2 2 2 {c}\n")


@pytest.mark.parametrize("t, vals, bad_line, bad", [
    ("uchar", (1, 255, 300), 13, "300"),
    ("uchar", (-1, 0, 0), 10, "-1"),
    ("char", (0, -129, 0), 12, "-129"),
    ("short", (0, 0, 40000), 13, "40000"),
    ("uint", (0, 4294967296, 0), 12, "4294967296"),
    ("int", (0, 1.5, 0), 12, "1.5"),
    ("int", (0, 0, "nan"), 13, "nan"),
    ("float", (0, 1e39, 0), 12, "1e+39"),
])
def test_ply_ascii_values_outside_their_type(tmp_path, t, vals, bad_line, bad):
    p = tmp_path / "range.ply"
    p.write_text(_HEAD_ASCII.format(t=t, a=vals[0], b=vals[1], c=vals[2]))
    with pytest.raises(csdf.CsdfError) as info:
        read_points(p)
    msg = str(info.value)
    for w in (str(p), f"line {bad_line}", "'v'", t, bad):
        assert w in msg, msg


def test_ply_ascii_values_at_their_type_limits_are_read(tmp_path):
    p = tmp_path / "ok.ply"
    p.write_text(_HEAD_ASCII.format(t="uchar", a=0, b=255, c="7.0"))
    assert read_point_properties(p)["v"].tolist() == [0, 255, 7]
    p.write_text(_HEAD_ASCII.format(t="float", a="inf", b="3.4e38", c="-1e-50"))
    assert read_points(p)[0].shape == (3, 3)


# ---------------------------------------------------------------------- atomic writes
def test_atomic_write_os_errors_are_csdf_errors(tmp_path):
    with pytest.raises(csdf.CsdfError) as info:
        with atomic_path("/proc/x.csdfb") as tmp:
            tmp.write_bytes(b"x")
    assert "/proc/x.csdfb" in str(info.value)
    target = tmp_path / "adir"
    target.mkdir()
    (target / "keep").write_text("x")
    with pytest.raises(csdf.CsdfError, match="adir"):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"x")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir"]


def test_atomic_write_error_inside_the_body_names_the_target(tmp_path):
    def boom(_path: Path) -> None:
        raise OSError(28, "No space left on device")

    with pytest.raises(csdf.CsdfError, match=r"out\.stl.*No space left"):
        with atomic_path(tmp_path / "out.stl") as tmp:
            boom(tmp)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs /proc")
def test_cli_compile_to_an_unwritable_folder_exits_2(tmp_path):
    model = tmp_path / "s.csdf"
    model.write_text("export sphere(1)\n")
    r = runner.invoke(app, ["compile", str(model), "-o", "/proc/x.csdfb"])
    assert r.exit_code == 2, r.output
    assert "/proc/x.csdfb" in r.output and "error" in r.output
    assert r.exception is None or isinstance(r.exception, SystemExit)


# ---------------------------------------------------------------------- program files
def _compiled(tmp_path, suffix):
    model = tmp_path / "s.csdf"
    model.write_text("export sphere(1)\n")
    out = tmp_path / f"s{suffix}"
    r = runner.invoke(app, ["compile", str(model), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return out


def test_bad_bytecode_file_errors_name_the_file(tmp_path):
    blob = _compiled(tmp_path, ".csdfb")
    data = bytearray(blob.read_bytes())
    data[-1] ^= 1
    blob.write_bytes(bytes(data))
    r = runner.invoke(app, ["info", str(blob)])
    assert r.exit_code == 2
    assert f"{blob}: byte" in r.output.replace("\n", "") and "checksum" in r.output


def test_bad_listing_file_errors_name_the_file(tmp_path):
    text = _compiled(tmp_path, ".csdft")
    text.write_text("csdf-program 1\nnonsense\n")
    r = runner.invoke(app, ["info", str(text)])
    assert r.exit_code == 2
    assert f"{text}: line" in r.output.replace("\n", ""), r.output


def test_signalling_nan_in_a_float32_ply_reads_quietly(tmp_path):
    """A signalling NaN in a binary float32 column reads as NaN, with no RuntimeWarning
    (warnings are errors here)."""
    import struct
    import warnings

    from csdf.io import read_point_cloud, read_points

    path = tmp_path / "snan.ply"
    hdr = (b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n"
           b"property float y\nproperty float z\nend_header\n")
    path.write_bytes(hdr + struct.pack("<I", 0x7FA00000) + struct.pack("<5f", 0, 0, 1, 2, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pts, _ = read_points(path)
        cloud = read_point_cloud(path)
    assert np.isnan(pts[0, 0]) and pts[1].tolist() == [1.0, 2.0, 3.0]
    assert np.isnan(cloud.points[0, 0])
