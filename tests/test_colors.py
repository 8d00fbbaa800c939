"""Colours on shapes (issue 24, first part): Shape.color, the nearest-coloured-surface
rule through CSG (csdf.colors), coloured meshes and their files."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

import csdf
from csdf.cli import app
from csdf.colors import DEFAULT_COLOR, color_program, colors_at
from test_bytecode_versions import _with_crc

RED, GREEN, BLUE = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def _box_and_ball():
    return (csdf.box(1).color(RED),
            csdf.sphere(0.4).translate((0.5, 0, 0)).color(BLUE))


def test_colours_follow_the_winning_operand_through_csg():
    a, b = _box_and_ball()
    # points on each operand's surface (or just off it)
    on_a, on_b, cut = [-0.5, 0, 0], [0.9, 0, 0], [0.1, 0, 0]
    u = colors_at(a | b, [on_a, on_b, [0, 0.5, 0]])
    np.testing.assert_array_equal(u[:, :3], [RED, BLUE, RED])
    i = colors_at(a & b, [[0.3, 0, np.sqrt(0.12)], [0.5, 0.0, 0.45]])  # ball; box's top
    np.testing.assert_array_equal(i[:, :3], [BLUE, RED])
    d = colors_at(a - b, [on_a, cut, [0, 0, 0.5]])  # the cut face is the cutter's
    np.testing.assert_array_equal(d[:, :3], [RED, BLUE, RED])
    s = colors_at(csdf.union(a, b, k=0.1), [on_a, on_b])  # a smooth blend: the nearer
    np.testing.assert_array_equal(s[:, :3], [RED, BLUE])


def test_uncoloured_parts_inner_colours_and_poses():
    a, b = _box_and_ball()
    plain = csdf.sphere(0.3).translate((-1.2, 0, 0))
    c = colors_at(a | b | plain, [[-1.5, 0, 0], [-0.5, 0, 0]])
    np.testing.assert_array_equal(c, [DEFAULT_COLOR, RED + (1.0,)])
    # an inner colour wins over the outer one on its own surface
    ball = csdf.sphere(0.4).translate((0.5, 0, 0))
    nested = ((a | ball).color(GREEN) | plain).color((0.5, 0.5, 0.5, 0.25))
    got = colors_at(nested, [[0.9, 0, 0], [-0.5, 0, 0], [-1.5, 0, 0]])
    np.testing.assert_array_equal(got, [GREEN + (1.0,), RED + (1.0,), (0.5, 0.5, 0.5, 0.25)])
    # colours move with the shape; no colour anywhere is the default; NaN in, NaN out
    moved = (a | b).translate((10, 0, 0))
    np.testing.assert_array_equal(colors_at(moved, [[10.9, 0, 0]])[0, :3], BLUE)
    np.testing.assert_array_equal(colors_at(csdf.sphere(1), [[1, 0, 0]]), [DEFAULT_COLOR])
    assert np.isnan(colors_at(a | b, [[np.nan, 0, 0]])).all()


def test_geometry_is_untouched_by_colour_and_colours_survive_the_bytecode():
    a, b = _box_and_ball()
    plain = csdf.box(1) - csdf.sphere(0.4).translate((0.5, 0, 0))
    coloured = (a - b).compile()
    geometry = plain.compile()
    # the same tape, constants and parameters: the colour program is a section apart
    np.testing.assert_array_equal(coloured.code, geometry.code)
    np.testing.assert_array_equal(coloured.consts, geometry.consts)
    assert geometry.colors is None and coloured.colors is not None
    prog, palette = color_program(a - b)
    assert palette.shape == (2, 4) and prog.dim == 3
    pts = [[-0.5, 0, 0], [0.1, 0, 0]]
    for back in (csdf.Program.from_bytes(coloured.to_bytes()),
                 csdf.Program.from_text(coloured.disassemble())):
        assert back == coloured
        np.testing.assert_array_equal(colors_at(back, pts), colors_at(a - b, pts))
        m = csdf.mesh(back, resolution=24, colors=True, progress=False)
        assert len(np.unique(m.visual.vertex_colors, axis=0)) == 2
    assert geometry.to_bytes()[4] == 2  # an uncoloured program keeps its version
    bad = bytearray(coloured.to_bytes()[:-4])
    inner = coloured.colors[0].to_bytes()
    i = len(bad) - len(inner) - 4 - 32 * len(coloured.colors[1])  # the palette's start
    assert bad[i:i + 8] == np.float64(1.0).tobytes()  # red's red
    bad[i:i + 8] = np.float64(2.0).tobytes()
    with pytest.raises(csdf.BytecodeError, match="palette colour 0"):
        csdf.Program.from_bytes(_with_crc(bytes(bad)))


def test_coloured_meshes_round_trip_through_ply_glb_and_obj(tmp_path):
    a, b = _box_and_ball()
    m = csdf.mesh(a - b, resolution=48, colors=True, progress=False)
    vc = np.asarray(m.visual.vertex_colors)
    assert set(map(tuple, vc.tolist())) == {(255, 0, 0, 255), (0, 0, 255, 255)}
    # the cut (inside the ball's reach) is blue, the rest red
    blue = (vc[:, :3] == (0, 0, 255)).all(axis=1)
    r = np.linalg.norm(m.vertices - [0.5, 0, 0], axis=1)
    assert np.all(np.abs(r[blue] - 0.4) < 0.03)
    for ext in ("ply", "glb", "obj"):
        path = tmp_path / f"m.{ext}"
        csdf.io.write_mesh(m, path)
        back = trimesh.load(path, force="mesh", process=False)
        got = np.asarray(back.visual.vertex_colors)
        assert len(got) == len(vc) and set(map(tuple, got.tolist())) == set(
            map(tuple, vc.tolist())), ext
    plain = csdf.mesh(csdf.sphere(0.5), resolution=16, colors=True, progress=False)
    assert (np.asarray(plain.visual.vertex_colors) == (204, 204, 204, 255)).all()


def test_cli_mesh_colors(tmp_path):
    model = tmp_path / "m.csdf"
    model.write_text("export box(1).color((1, 0, 0)) - sphere(0.4).translate((0.5, 0, 0))"
                     ".color((0, 0, 1))\n")
    out = tmp_path / "m.ply"
    r = CliRunner().invoke(app, ["mesh", str(model), "-o", str(out), "--resolution", "32",
                                 "--colors", "-q"])
    assert r.exit_code == 0, r.output
    vc = np.asarray(trimesh.load(out, process=False).visual.vertex_colors)
    assert {(255, 0, 0, 255), (0, 0, 255, 255)} == set(map(tuple, vc.tolist()))


def test_renders_are_drawn_in_the_shapes_colours():
    from csdf.render.image import auto_camera

    a, b = _box_and_ball()
    plain = csdf.box(1) - csdf.sphere(0.4).translate((0.5, 0, 0))
    cam = auto_camera(plain, 96, 72)
    grey = csdf.render(plain, cam)
    red = csdf.render(csdf.box(1).color(RED) - csdf.sphere(0.4).translate((0.5, 0, 0)),
                      cam)
    np.testing.assert_array_equal(red.depth, grey.depth)  # the same geometry
    px = red.color[red.mask].astype(float)
    # the box's faces are red, the (uncoloured) cut keeps the default blue
    assert (px[:, 0] > 2 * px[:, 2] + 20).mean() > 0.5
    both = csdf.render(a - b, cam).color[red.mask].astype(float)
    assert (both[:, 2] > both[:, 0] + 20).sum() > 0 and (both[:, 0] > both[:, 2]).sum() > 0


def test_scans_and_surface_samples_carry_colours():
    a, b = _box_and_ball()
    part = a - b
    cam = csdf.Camera.look_at((2.5, -1.5, 1.5), (0, 0, 0), width=64, height=48)
    p0, n0 = csdf.scan(part, cam, noise=0.002, outliers=0.05, seed=3)
    p1, n1, c1 = csdf.scan(part, cam, noise=0.002, outliers=0.05, seed=3, colors=True)
    np.testing.assert_array_equal(p0, p1)  # the same cloud, colours besides
    np.testing.assert_array_equal(n0, n1)
    assert c1.shape == (len(p1), 4) and np.all((c1 >= 0) & (c1 <= 1))
    clean, _, cc = csdf.scan(part, cam, colors=True)
    world = clean @ cam.R.T + cam.t  # the camera frame back to the object's
    blue = (cc[:, :3] == BLUE).all(axis=1)
    assert blue.any() and (cc[:, :3] == RED).all(axis=1).any()
    r = np.linalg.norm(world[blue] - [0.5, 0, 0], axis=1)
    assert np.all(np.abs(r - 0.4) < 1e-3)  # the blue returns lie on the cut
    pts, nrm, col = csdf.sample_surface(part, 500, seed=1, colors=True)
    on_ball = np.abs(np.linalg.norm(pts - [0.5, 0, 0], axis=1) - 0.4) < 1e-6
    np.testing.assert_array_equal((col[:, :3] == BLUE).all(axis=1), on_ball)


def test_preview_shader_colours_compile_and_fall_back_to_a_default():
    import os

    from csdf.colors import albedo_glsl
    from glsl_runner import ES_PRELUDE, glslang, validate

    r = csdf.param("r", 0.4, 0.1, 0.6)
    shape = csdf.box(1).color(RED) - csdf.sphere(r).translate((0.5, 0, 0)).color(BLUE) \
        | csdf.sphere(0.2).translate((-1, 0, 0))
    geometry = csdf.to_glsl(shape)
    src = albedo_glsl(shape, declared=geometry, default=(0.8, 0.76, 0.7))
    assert "uniform float u_r" not in src  # declared once, by the geometry
    assert "vec3 sdf_albedo(vec3 p)" in src and "vec3(1.0, 0.0, 0.0)" in src
    assert "vec3(0.8, 0.76, 0.7)" in src  # the uncoloured ball
    plain = albedo_glsl(csdf.sphere(1), default=(0.8, 0.76, 0.7))
    assert "float" not in plain and "vec3(0.8, 0.76, 0.7)" in plain
    if glslang() is None:
        if os.environ.get("CSDF_REQUIRE_TOOLS") == "1":
            pytest.fail("CSDF_REQUIRE_TOOLS=1 but glslangValidator is not installed")
        pytest.skip("needs glslangValidator (apt-get install glslang-tools)")
    main = "out vec4 c;\nvoid main() { c = vec4(sdf_albedo(vec3(0.5)), sdf(vec3(0.0))); }\n"
    ok, log = validate(ES_PRELUDE + geometry + src + main)
    assert ok, log


def test_materials_are_named_colours_with_a_roughness():
    from csdf.shapes.appearance import MATERIALS, colors, node_roughness

    a = csdf.box(1).material("wood")
    b = csdf.sphere(0.4).translate((0.5, 0, 0)).material("glaze", color=BLUE, roughness=0.2)
    part = a - b
    got = colors_at(part, [[-0.5, 0, 0], [0.1, 0, 0]])
    np.testing.assert_array_equal(got[:, :3], [MATERIALS["wood"][0], BLUE])
    assert [node_roughness(n) for n, _ in colors(part)] == [MATERIALS["wood"][1], 0.2]
    np.testing.assert_array_equal(
        part.compile().code,
        (csdf.box(1) - csdf.sphere(0.4).translate((0.5, 0, 0))).compile().code)
    assert csdf.loads(csdf.dumps(part)).compile() == part.compile()
    with pytest.raises(csdf.ShapeError, match="not one of"):
        csdf.box(1).material("unobtainium")
    with pytest.raises(csdf.ShapeError, match="roughness"):
        csdf.box(1).material("wood", roughness=2)
