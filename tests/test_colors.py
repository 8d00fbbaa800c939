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
    i = colors_at(a & b, [[0.3, 0, np.sqrt(0.12)], [0.5, 0.0, 0.1]])  # ball; box face
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
    # the text form checks the palette too (a fuzzer found it did not)
    text = coloured.disassemble().replace("palette 1.0 0.0 0.0 1.0", "palette 2.0 0.0 0.0 1.0")
    assert "palette 2.0" in text
    with pytest.raises(csdf.BytecodeError, match="palette colour 0 is not RGBA"):
        csdf.Program.from_text(text)


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


def _two_balls():
    return (csdf.sphere(0.5).translate((-0.4, 0, 0)).color(RED),
            csdf.sphere(0.5).translate((0.4, 0, 0)).color(BLUE))


def test_smooth_blends_mix_the_operands_colours_by_the_blend_weight():
    a, b = _two_balls()
    k = 0.3
    u = csdf.union(a, b, k=k)
    # on the plane x = 0 the two distances are equal: half and half (Quilez's h = 1/2)
    mid = colors_at(u, [[0, 0.35, 0], [0, 0, 0.4]])
    np.testing.assert_allclose(mid[:, :3], [[0.5, 0, 0.5]] * 2, atol=1e-12)
    # elsewhere in the blend, the polynomial weights: h_b / 2 for the farther operand
    p = np.array([[-0.1, 0.38, 0.0]])
    da = np.linalg.norm(p - [-0.4, 0, 0]) - 0.5
    db = np.linalg.norm(p - [0.4, 0, 0]) - 0.5
    w_b = max(k - (db - da), 0) / k / 2
    np.testing.assert_allclose(colors_at(u, p)[0, :3], [1 - w_b, 0, w_b], atol=1e-12)
    # outside the blend the winner's colour, as in a hard union
    np.testing.assert_array_equal(colors_at(u, [[-0.9, 0, 0], [0.9, 0, 0]])[:, :3],
                                  [RED, BLUE])
    # the exponential blend mixes by its softmax weights
    e = colors_at(csdf.union(a, b, k=k, blend="exponential"), p)[0, :3]
    w = np.exp(-np.array([da, db]) / k)
    np.testing.assert_allclose(e, [w[0] / w.sum(), 0, w[1] / w.sum()], atol=1e-12)
    # a hard union keeps the compact form: a palette index
    assert color_program(a | b)[1] is not None and color_program(u)[1] is None
    # blends of one colour are that colour, in the compact form
    same = csdf.union(a, csdf.sphere(0.5).translate((0.4, 0, 0)).color(RED), k=k)
    assert color_program(same)[1] is not None
    np.testing.assert_array_equal(colors_at(same, [[0, 0.35, 0]])[0, :3], RED)


def test_blended_colours_survive_the_bytecode_text_meshes_and_an_uncoloured_default():
    a, b = _two_balls()
    plain = csdf.sphere(0.3).translate((0, 0, 0.7))
    shape = csdf.union(a, b, plain, k=0.2)
    prog = shape.compile()
    assert len(prog.colors[0]) == 5 and prog.colors[1] is None
    pts = np.array([[0, 0.35, 0], [0, 0, 1.0], [-0.9, 0, 0], [0.0, 0.25, 0.55]])
    want = colors_at(shape, pts)
    np.testing.assert_array_equal(want[1], DEFAULT_COLOR)  # the uncoloured ball's top
    grey = colors_at(shape, pts, default=(0, 1, 0, 1))
    np.testing.assert_array_equal(grey[1], (0, 1, 0, 1))
    for back in (csdf.Program.from_bytes(prog.to_bytes()),
                 csdf.Program.from_text(prog.disassemble())):
        assert back == prog
        np.testing.assert_array_equal(colors_at(back, pts), want)
    assert "colors channels 5" in prog.disassemble()
    m = csdf.mesh(shape, resolution=32, colors=True, progress=False)
    rgb = m.visual.vertex_colors[:, :3].astype(float) / 255
    mixed = (rgb[:, 0] > 0.2) & (rgb[:, 2] > 0.2) & (rgb[:, 1] < 0.05)
    assert mixed.sum() > 20  # the seam between red and blue is a gradient
    # a channel section with the wrong number of programs is refused
    bad = prog.disassemble().replace("colors channels 5", "colors channels 4")
    with pytest.raises(csdf.BytecodeError, match="5 colour programs"):
        csdf.Program.from_text(bad)


def test_color_fields_are_procedural_colours_of_the_coordinates():
    from csdf.expr import X, Z, sin

    t = csdf.param("t", 4.0, 1.0, 8.0)
    stripes = csdf.box(1).color_field((0.5 + 0.5 * sin(t * X), 0.2, Z + 0.5))
    pts = np.array([[0.5, 0.1, 0.0], [-0.5, 0.0, 0.3], [0.1, 0.5, 0.9]])
    want = np.c_[0.5 + 0.5 * np.sin(4 * pts[:, 0]), np.full(3, 0.2),
                 np.clip(pts[:, 2] + 0.5, 0, 1), np.ones(3)]
    np.testing.assert_allclose(colors_at(stripes, pts), want, atol=1e-12)
    want6 = want.copy()
    want6[:, 0] = 0.5 + 0.5 * np.sin(6 * pts[:, 0])
    np.testing.assert_allclose(colors_at(stripes, pts, {"t": 6.0}), want6, atol=1e-12)
    # the pattern moves with the shape; inner colours win on their own surfaces
    moved = stripes.translate((2, 0, 0))
    np.testing.assert_allclose(colors_at(moved, pts + [2, 0, 0]), want, atol=1e-12)
    inner = (csdf.box(1) | csdf.sphere(0.3).translate((0.6, 0, 0)).color(GREEN)) \
        .color_field(lambda x, y, z: (x * 0 + 1, y * 0, z * 0))
    got = colors_at(inner, [[-0.5, 0, 0], [0.9, 0, 0]])
    np.testing.assert_array_equal(got[:, :3], [RED, GREEN])
    # the language writes and reads it; the geometry is untouched
    back = csdf.loads(csdf.dumps(stripes))
    np.testing.assert_allclose(colors_at(back, pts), want, atol=1e-12)
    np.testing.assert_array_equal(stripes.compile().code, csdf.box(1).compile().code)
    with pytest.raises(csdf.ShapeError, match="3 or 4 expressions"):
        csdf.box(1).color_field((X, X))
    with pytest.raises(csdf.ShapeError, match="not a shape"):
        csdf.box(1).color_field((csdf.box(1), 0, 0))
    with pytest.raises(csdf.ShapeError, match="may not use z"):
        csdf.circle(1).color_field((Z, 0, 0))


def test_channel_colours_in_the_preview_shader():
    import os

    from csdf.colors import albedo_glsl
    from glsl_runner import ES_PRELUDE, glslang, validate

    a, b = _two_balls()
    shape = csdf.union(a, b, k=0.2).color_field((0.3, 0.3, 0.3)) \
        | csdf.sphere(0.2).translate((0, 0, 1))
    geometry = csdf.to_glsl(shape)
    src = albedo_glsl(shape, declared=geometry, default=(0.8, 0.76, 0.7))
    assert "sdf_albedo_u(p) * vec3(0.8, 0.76, 0.7)" in src
    if glslang() is None:
        if os.environ.get("CSDF_REQUIRE_TOOLS") == "1":
            pytest.fail("CSDF_REQUIRE_TOOLS=1 but glslangValidator is not installed")
        pytest.skip("needs glslangValidator (apt-get install glslang-tools)")
    main = "out vec4 c;\nvoid main() { c = vec4(sdf_albedo(vec3(0.5)), sdf(vec3(0.0))); }\n"
    ok, log = validate(ES_PRELUDE + geometry + src + main)
    assert ok, log


@pytest.mark.parametrize("kind", ["palette", "channels"])
def test_shadertoy_export_draws_the_colours(kind):
    import os

    from csdf.field import shadertoy
    from glsl_runner import ES_PRELUDE, glslang, validate

    r = csdf.param("r", 0.4, 0.1, 0.6)
    a = csdf.box(1).color(RED)
    b = csdf.sphere(r).translate((0.5, 0, 0)).color(BLUE)
    shape = a - b if kind == "palette" else csdf.union(a, b, k=0.2)
    src = shadertoy(shape)
    assert "vec3 sdf_albedo(vec3 p)" in src and "pow(sdf_albedo(p), vec3(2.2))" in src
    assert ("sdf_albedo_index" in src) == (kind == "palette")
    assert "uniform" not in src and src.count("const float u_r = 0.4;") == 1
    assert "0.55 + 0.35 * n" in shadertoy(csdf.sphere(1))  # uncoloured: as before
    if glslang() is None:
        if os.environ.get("CSDF_REQUIRE_TOOLS") == "1":
            pytest.fail("CSDF_REQUIRE_TOOLS=1 but glslangValidator is not installed")
        pytest.skip("needs glslangValidator (apt-get install glslang-tools)")
    prelude = ES_PRELUDE + "uniform vec3 iResolution;\nuniform float iTime;\n"
    main = "out vec4 c;\nvoid main() { mainImage(c, gl_FragCoord.xy); }\n"
    ok, log = validate(prelude + src + main)
    assert ok, log


def test_scenes_render_and_scan_in_their_instances_colours():
    from csdf.render import auto_camera

    scene = csdf.Scene()
    scene.add(csdf.box(0.5).color(RED), pose=csdf.Pose(translation=(0, 0, 0)), name="a")
    scene.add(csdf.sphere(0.3).color(BLUE), pose=csdf.Pose(translation=(1, 0, 0)),
              name="b")
    scene.add(csdf.sphere(0.2), pose=csdf.Pose(translation=(0, 1, 0)), name="c")
    cam = auto_camera(scene, 80, 60)
    pts, normals, ids, rgba = csdf.scan(scene, cam, colors=True, outliers=0.0)
    assert set(np.unique(ids)) == {0, 1, 2}
    np.testing.assert_array_equal(np.unique(rgba[ids == 0], axis=0), [RED + (1.0,)])
    np.testing.assert_array_equal(np.unique(rgba[ids == 1], axis=0), [BLUE + (1.0,)])
    np.testing.assert_array_equal(np.unique(rgba[ids == 2], axis=0), [DEFAULT_COLOR])
    img = csdf.render(scene, cam)
    rgb = np.asarray(img.color).astype(int)
    red = img.instance == 0
    blue = img.instance == 1
    assert (rgb[red][:, 0] > rgb[red][:, 2]).all() and (rgb[blue][:, 2] > rgb[blue][:, 0]).all()
    with pytest.raises(csdf.CsdfError, match="instance id of each point"):
        csdf.colors.colors_of(scene, pts)
