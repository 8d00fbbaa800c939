"""Rendering: the camera's conventions, sphere-traced depth and silhouettes against ray
casting of the shape's own mesh, exact normals, shading options, PNG output, errors."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.render import Camera, Field, auto_camera, render, sphere_trace

W, H = 96, 72


def csg_example() -> csdf.Shape:
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


def twisted_box() -> csdf.Shape:
    return csdf.box((1.0, 0.4, 2.0)).twist(1.2)


def tapered_wedge() -> csdf.Shape:
    """A field with no Lipschitz bound (taper of an unbounded plane): L = inf."""
    return csdf.plane((0.6, 0.0, 0.8), 0.1).taper(0.5) & csdf.box(1.5)


def mesh_depth(mesh, cam: Camera) -> np.ndarray:
    """Depth along the optical axis ``(H*W,)`` of the first hit of every pixel ray with a
    triangle mesh (inf for a miss), by brute force: each triangle is tested (Moller-
    Trumbore) against the pixels whose centres lie in its projected bounding box.

    (trimesh's embree-free ``RayMeshIntersector`` needs tens of GB on a 10^6-triangle
    mesh with oblique rays: its candidates are the triangles in each ray's bounding box.)
    """
    tri = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]  # (F, 3, 3)
    uv, z = cam.project(tri.reshape(-1, 3))
    assert np.all(z > 0), "the mesh must lie in front of the camera"
    uv = uv.reshape(-1, 3, 2)
    lo = np.maximum(np.ceil(uv.min(1) - 1e-9).astype(np.int64), 0)
    hi = np.floor(uv.max(1) + 1e-9).astype(np.int64)
    hi = np.minimum(hi, [cam.width - 1, cam.height - 1])
    nu = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    nv = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    count = nu * nv
    fi = np.repeat(np.arange(len(tri)), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    pix = (lo[fi, 1] + k // nu[fi]) * cam.width + lo[fi, 0] + k % nu[fi]
    _, dirs = cam.rays()
    D = dirs[pix]
    a, e1, e2 = tri[fi, 0], tri[fi, 1] - tri[fi, 0], tri[fi, 2] - tri[fi, 0]
    pvec = np.cross(D, e2)
    det = np.einsum("ij,ij->i", e1, pvec)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = cam.t - a
        u = np.einsum("ij,ij->i", s, pvec) * inv
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", D, q) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
    tol = 1e-9
    ok = (det != 0) & (u >= -tol) & (v >= -tol) & (u + v <= 1 + tol) & (t > 0)
    first = np.full(cam.width * cam.height, np.inf)
    np.minimum.at(first, pix[ok], t[ok])
    return first * (dirs @ cam.R)[:, 2]


# ------------------------------------------------------------------------- camera
def test_look_at_follows_opencv_conventions():
    cam = Camera.look_at((3.0, 0.0, 0.0), (0.0, 0.0, 0.0), up=(0, 0, 1), fov=60.0,
                         width=W, height=H)
    assert cam.R.T @ cam.R == pytest.approx(np.eye(3))
    assert np.linalg.det(cam.R) == pytest.approx(1.0)
    np.testing.assert_allclose(cam.R[:, 2], [-1, 0, 0], atol=1e-15)  # z forward
    np.testing.assert_allclose(cam.R[:, 1], [0, 0, -1], atol=1e-15)  # y down (world up)
    np.testing.assert_allclose(cam.R[:, 0], [0, 1, 0], atol=1e-15)  # x right
    uv, depth = cam.project([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5], [0.0, 0.5, 0.0]])
    np.testing.assert_allclose(uv[0], [(W - 1) / 2, (H - 1) / 2])
    np.testing.assert_allclose(depth, [3.0, 3.0, 3.0])
    assert uv[1, 1] < uv[0, 1]  # world up is up the image (smaller v)
    assert uv[2, 0] > uv[0, 0]  # +y is on the right when looking along -x with z up
    # vertical field of view: the top edge of the image is at fov / 2
    top = cam.camera_to_world([[0.0, -np.tan(np.radians(30.0)), 1.0]])
    assert cam.project(top)[0][0, 1] == pytest.approx(-0.5)


def test_rays_project_back_to_pixel_centres_and_frames_invert():
    cam = Camera.look_at((1.0, -2.0, 1.5), (0.1, 0.2, -0.1), fov=50.0, width=W, height=H)
    o, d = cam.rays()
    assert o.shape == d.shape == (W * H, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(o, np.broadcast_to(cam.t, o.shape))
    uv, depth = cam.project(o + 2.5 * d)
    vv, uu = np.mgrid[0:H, 0:W]
    np.testing.assert_allclose(uv, np.stack([uu.ravel(), vv.ravel()], 1), atol=1e-9)
    assert np.all(depth > 0)
    p = np.random.default_rng(0).normal(size=(50, 3))
    np.testing.assert_allclose(cam.camera_to_world(cam.world_to_camera(p)), p, atol=1e-12)
    assert np.all(np.isnan(cam.project(cam.t - cam.R[:, 2])[0]))  # behind the camera


def test_scaled_camera_keeps_the_field_of_view():
    cam = Camera.look_at((2, -2, 1), (0, 0, 0), fov=45.0, width=640, height=480)
    small = cam.scaled(W, H)
    assert (small.width, small.height) == (W, H)
    # the image's outer corners (half a pixel beyond the corner centres) stay put
    tv = np.tan(np.radians(22.5))
    tu = tv * 4 / 3
    for c in (cam, small):
        corners = [((u - c.cx) / c.fx, (v - c.cy) / c.fy)
                   for u in (-0.5, c.width - 0.5) for v in (-0.5, c.height - 0.5)]
        np.testing.assert_allclose(corners, [(-tu, -tv), (-tu, tv), (tu, -tv), (tu, tv)],
                                   atol=1e-12)
    _, d_small = small.rays()
    assert cam.rays(W, H)[1] == pytest.approx(d_small)
    r = render(csdf.sphere(0.5), cam, W, H)
    assert r.color.shape == (H, W, 3) and r.camera.width == W


def test_auto_camera_frames_the_shape():
    shape = twisted_box()
    cam = auto_camera(shape, W, H, fov=30.0)
    r = render(shape, cam)
    assert r.mask.any()
    assert not (r.mask[0].any() or r.mask[-1].any() or r.mask[:, 0].any() or r.mask[:, -1].any())
    centre = shape.bounds.mean(0)
    np.testing.assert_allclose(cam.project(centre[None])[0][0], [cam.cx, cam.cy], atol=1e-9)
    assert cam.R[2, 1] < 0  # camera y (down the image) points down in the world
    top = auto_camera(shape, W, H, direction=(0, 0, 1))  # looking straight down
    np.testing.assert_allclose(top.R[:, 2], [0, 0, -1], atol=1e-12)
    near = auto_camera(shape, W, H, eye=(3, 0, 0), target=(0, 0, 0.5))
    np.testing.assert_allclose(near.t, [3, 0, 0])


# ------------------------------------------------------------------------- depth vs mesh
CAMERAS = {
    "oblique": dict(eye=(2.2, -2.6, 1.8), fov=40.0),
    "axis": dict(eye=(0.35, -3.2, 0.25), fov=35.0),  # looks through a tunnel
}


def test_reference_ray_caster_agrees_with_trimesh():
    from trimesh.ray.ray_triangle import RayMeshIntersector

    m = csdf.mesh(csg_example(), resolution=24, progress=False)
    cam = Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), fov=40.0, width=48, height=36)
    o, d = cam.rays()
    loc, ray, _ = RayMeshIntersector(m).intersects_location(o, d, multiple_hits=False)
    ref = np.full(len(o), np.inf)
    ref[ray] = (loc - cam.t) @ cam.R[:, 2]
    got = mesh_depth(m, cam)
    assert np.array_equal(np.isfinite(ref), np.isfinite(got))
    fin = np.isfinite(ref)
    assert fin.sum() > 300
    np.testing.assert_allclose(got[fin], ref[fin], atol=1e-12)


@pytest.mark.parametrize(
    "make, view",
    [(csg_example, "oblique"), (csg_example, "axis"), (twisted_box, "oblique"),
     (tapered_wedge, "oblique")],
    ids=["csg-oblique", "csg-axis", "twisted-box", "lipschitz-inf"],
)
def test_depth_and_silhouette_agree_with_mesh_ray_casting(make, view):
    shape = make()
    cam = Camera.look_at(CAMERAS[view]["eye"], (0, 0, 0), fov=CAMERAS[view]["fov"],
                         width=W, height=H)
    r = render(shape, cam, W, H)
    m = csdf.mesh(shape, resolution=256, progress=False)
    scale = float(np.linalg.norm(np.ptp(m.vertices, axis=0)))
    ref = mesh_depth(m, cam)
    got = r.depth.ravel()
    in_ref, in_got = np.isfinite(ref), r.mask.ravel()
    assert np.array_equal(in_got, np.isfinite(got))
    assert in_got.sum() > 0.1 * W * H
    iou = (in_ref & in_got).sum() / (in_ref | in_got).sum()
    assert iou >= 0.99
    # depth agrees to 1e-3 of the scene size at >= 99 % of the pixels (background
    # agreeing counts as agreement)
    with np.errstate(invalid="ignore"):
        agree = (~in_ref & ~in_got) | (np.abs(ref - got) <= 1e-3 * scale)
    assert agree.mean() >= 0.99
    both = in_ref & in_got
    assert np.median(np.abs(ref[both] - got[both])) <= 1e-4 * scale
    # where they disagree about the silhouette, the pixel is next to the silhouette
    diff = (in_ref ^ in_got).reshape(H, W)
    mask = r.mask
    pad = np.pad(mask, 1, mode="edge")
    edge = np.zeros_like(mask)
    for dv, du in ((0, 1), (2, 1), (1, 0), (1, 2)):
        edge |= pad[dv:dv + H, du:du + W] != mask
    assert not np.any(diff & ~edge)


def test_normals_are_exact_gradients_and_face_the_camera():
    shape = twisted_box()
    cam = Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), fov=40.0, width=W, height=H)
    r = render(shape, cam)
    n = r.normals[r.mask]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert np.all(r.normals[~r.mask] == 0)
    assert np.all(np.isinf(r.depth[~r.mask]))
    _, d = cam.rays()
    assert np.all((n * d[r.mask.ravel()]).sum(1) < 0)
    # central differences of the field at the hit points
    p = cam.t + (r.depth.ravel() / (d @ cam.R)[:, 2])[r.mask.ravel(), None] * d[r.mask.ravel()]
    np.testing.assert_allclose(shape(p), 0.0, atol=1e-8)
    h = 1e-6
    g = np.stack([(shape(p + h * e) - shape(p - h * e)) / (2 * h) for e in np.eye(3)], 1)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    cos = (g * n).sum(1)
    assert np.quantile(cos, 0.95) > 1 - 1e-8  # smooth points: the same direction
    assert np.quantile(cos, 0.01) > 0.5  # at creases: one of the one-sided normals


def test_program_input_params_and_shading_options():
    r_par = csdf.param("r", 1.0, 0.8, 1.2)
    c = csdf.cylinder(0.5, 3.0)
    shape = (csdf.sphere(r_par) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")
    cam = Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), fov=40.0, width=W, height=H)
    base = render(shape, cam)
    small = render(shape, cam, params={"r": 0.85})
    assert small.mask.sum() < base.mask.sum()
    # a Program (bounds by interval arithmetic) renders the same geometry
    prog = render(shape.compile(), cam)
    assert np.array_equal(prog.mask, base.mask)
    np.testing.assert_allclose(prog.depth[base.mask], base.depth[base.mask], atol=1e-9)
    fancy = render(shape, cam, shadows=True, ao=True)
    assert np.array_equal(fancy.mask, base.mask)
    assert np.array_equal(fancy.depth, base.depth)
    assert fancy.color[base.mask].astype(int).sum() < base.color[base.mask].astype(int).sum()
    assert np.array_equal(fancy.color[~base.mask], base.color[~base.mask])
    assert base.color.dtype == np.uint8 and base.color.shape == (H, W, 3)
    with pytest.raises(csdf.ParamError, match="unknown parameter"):
        render(shape, cam, params={"radius": 1.0})


def test_camera_inside_the_bounding_box_and_inside_the_solid():
    shape = csg_example()
    # at the centre, where the three tunnels meet: walls around, the x tunnel's exit ahead
    cam = Camera.look_at((0.0, 0.0, 0.0), (1.0, 0.3, 0.2), fov=70.0, width=48, height=36)
    r = render(shape, cam)
    assert 0.2 < r.mask.mean() < 0.95
    _, d = cam.rays()
    hit = r.mask.ravel()
    reach = np.where(hit, r.depth.ravel() / (d @ cam.R)[:, 2], 2.0)  # 2: beyond the box
    p = reach[:, None] * d
    np.testing.assert_allclose(shape(p[hit]), 0.0, atol=1e-8)
    s = np.linspace(0.0, 0.999, 300)
    assert np.all(shape((s[None, :, None] * p[:, None, :]).reshape(-1, 3)) > 0)
    # a camera inside the solid sees it at distance zero
    inside = Camera.look_at((0.0, 0.7, 0.7), (0.0, 0.0, 0.0), fov=30.0, width=8, height=6)
    r = render(shape, inside)
    assert r.mask.all() and np.all(r.depth == 0)


def test_over_relaxation_and_plain_tracing_agree():
    shape = csg_example()
    fld = Field(shape)
    cam = Camera.look_at((2.2, -2.6, 1.8), (0, 0, 0), fov=40.0, width=W, height=H)
    o, d = cam.rays()
    relaxed = sphere_trace(fld, cam.t, d)
    plain = sphere_trace(fld, o, d, omega=1.0)  # per-ray origins, no relaxation
    # the two sample rays differently, so they may differ only on rays that graze the
    # surface (penetrating it by less than the hit tolerance)
    assert (relaxed.hit != plain.hit).mean() <= 0.005
    both = relaxed.hit & plain.hit
    assert (np.abs(relaxed.t[both] - plain.t[both]) <= 1e-8).mean() >= 0.995
    assert relaxed.evaluations <= 1.2 * plain.evaluations


def test_save_writes_a_png_atomically(tmp_path):
    from PIL import Image

    r = render(csdf.sphere(1.0), Camera.look_at((0, -4, 0), (0, 0, 0), width=W, height=H))
    out = r.save(tmp_path / "s.png")
    with Image.open(out) as im:
        assert im.size == (W, H) and im.mode == "RGB"
        assert np.array_equal(np.asarray(im), r.color)
    assert [p.name for p in tmp_path.iterdir()] == ["s.png"]
    with pytest.raises(csdf.CsdfError, match="PNG"):
        r.save(tmp_path / "s.jpg")
    with pytest.raises(csdf.CsdfError, match="does not exist"):
        r.save(tmp_path / "missing" / "s.png")


# ------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "size, match",
    [((0, 10), "width must be at least 1"), ((10, -2), "height must be at least 1"),
     ((8192, 8192), "over the limit"), ((9000, 10), "over the limit"),
     ((10.5, 10), "integer"), ((True, 10), "integer")],
)
def test_bad_resolution_raises(size, match):
    cam = Camera.look_at((0, -4, 0), (0, 0, 0))
    with pytest.raises(csdf.CsdfError, match=match):
        render(csdf.sphere(1.0), cam, *size)
    with pytest.raises(csdf.CsdfError, match=match):
        Camera.look_at((0, -4, 0), (0, 0, 0), width=size[0], height=size[1])


def test_bad_cameras_raise():
    with pytest.raises(csdf.CsdfError, match="finite"):
        Camera(np.nan, 100.0, 50.0, 40.0, W, H)
    with pytest.raises(csdf.CsdfError, match="positive"):
        Camera(-1.0, 100.0, 50.0, 40.0, W, H)
    with pytest.raises(csdf.CsdfError, match="finite"):
        Camera(100.0, 100.0, 50.0, 40.0, W, H, t=(0, np.inf, 0))
    with pytest.raises(csdf.CsdfError, match="rotation"):
        Camera(100.0, 100.0, 50.0, 40.0, W, H, R=2 * np.eye(3))
    with pytest.raises(csdf.CsdfError, match="finite"):
        Camera.look_at((np.nan, 0, 0), (0, 0, 0))
    with pytest.raises(csdf.CsdfError, match="same point"):
        Camera.look_at((1, 1, 1), (1, 1, 1))
    with pytest.raises(csdf.CsdfError, match="parallel"):
        Camera.look_at((0, 0, 3), (0, 0, 0), up=(0, 0, 1))
    with pytest.raises(csdf.CsdfError, match="fov"):
        Camera.look_at((0, -3, 0), (0, 0, 0), fov=180.0)
    with pytest.raises(csdf.CsdfError, match="csdf.Camera"):
        render(csdf.sphere(1.0), "camera")
    with pytest.raises(csdf.CsdfError, match="unbounded"):
        render(csdf.plane(), Camera.look_at((0, -4, 1), (0, 0, 0), width=8, height=8))
