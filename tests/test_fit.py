"""Pose, scale and shape recovery from point clouds: exact on noiseless data, robust to
outliers, reproducible multistart, the ICP baseline, and clear errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

import csdf
from csdf.fit.lie import exp_so3, left_jacobian, log_so3, rotation_angle, sphere_rotations


def _part():
    r = csdf.param("r", 0.1, 0.05, 0.2)
    c = csdf.cylinder(0.04, 0.3)
    return (csdf.box((0.3, 0.2, 0.12)) | csdf.sphere(r).translate((0.1, 0.0, 0.05))) - c


def _surface(shape, n, seed=0, **params):
    """Points on the zero set: random points projected by Newton steps."""
    rng = np.random.default_rng(seed)
    b = shape.bounds
    p = rng.uniform(b[0] - 0.05, b[1] + 0.05, (4 * n, 3))
    for _ in range(30):
        f, g = shape.value_and_grad(p, params)
        p = p - (f / np.maximum(np.sum(g * g, axis=1), 1e-30))[:, None] * g
    f = shape(p, params)
    return p[np.abs(f) < 1e-12][:n]


R_TRUE = exp_so3(np.array([0.3, -0.5, 0.8]))
T_TRUE = np.array([0.5, -0.2, 1.0])


def _scene(shape, n=1500, s=1.0, **params):
    q = _surface(shape, n, **params)
    return s * q @ R_TRUE.T + T_TRUE


def _init(angle_deg=20.0, offset=0.02):
    M = np.eye(4)
    M[:3, :3] = exp_so3(np.deg2rad(angle_deg) * np.array([0.6, 0.0, 0.8])) @ R_TRUE
    M[:3, 3] = T_TRUE + offset
    return M


def test_lie_helpers():
    w = np.array([0.3, -0.2, 0.9])
    np.testing.assert_allclose(log_so3(exp_so3(w)), w, atol=1e-12)
    # left Jacobian: exp(w + dw) ~ exp(J dw) exp(w)
    dw = 1e-6 * np.array([1.0, 2.0, -1.0])
    lhs = exp_so3(w + dw)
    rhs = exp_so3(left_jacobian(w) @ dw) @ exp_so3(w)
    assert np.abs(lhs - rhs).max() < 1e-11
    Rs = sphere_rotations(50)
    assert np.allclose(np.einsum("nij,nkj->nik", Rs, Rs), np.eye(3), atol=1e-12)


def test_pose_is_recovered_exactly_from_noiseless_points():
    shape = _part()
    P = _scene(shape)
    res = csdf.fit(shape, P, init=_init(25))
    assert rotation_angle(res.rotation, R_TRUE) < 1e-6
    np.testing.assert_allclose(res.translation, T_TRUE, atol=1e-7)
    assert res.rmse < 1e-8 and res.inlier_fraction == 1.0 and res.converged
    T = res.transform
    np.testing.assert_allclose(T[:3, :3], R_TRUE, atol=1e-6)
    json.dumps(res.to_dict())


def test_pose_scale_and_params_are_recovered():
    shape = _part()
    P = _scene(shape, s=1.3, r=0.13)
    res = csdf.fit(shape, P, init=_init(10), estimate=("pose", "scale", "params"))
    assert rotation_angle(res.rotation, R_TRUE) < 1e-5
    assert res.scale == pytest.approx(1.3, rel=1e-5)
    assert res.params["r"] == pytest.approx(0.13, rel=1e-4)
    np.testing.assert_allclose(res.translation, T_TRUE, atol=1e-5)


def test_a_close_start_needs_no_coarse_stage():
    # coarse=False refines from the start at once: the same solution in fewer
    # evaluations, with parameters, with the pose alone, and with an ambiguous scale
    shape = _part()
    M = _init(1.0, 0.002)
    for est, r in (("pose", 0.1), ("pose,params", 0.13)):
        P = _scene(shape, r=r)
        init = {"rotation": M[:3, :3], "translation": M[:3, 3], "params": {"r": 0.12}}
        if est == "pose":
            init["params"] = {"r": 0.1}
        a = csdf.fit(shape, P, init=init, estimate=est)
        b = csdf.fit(shape, P, init=init, estimate=est, coarse=False)
        assert rotation_angle(b.rotation, R_TRUE) < 1e-6 and b.rmse < 1e-7
        assert rotation_angle(a.rotation, b.rotation) < 1e-6
        np.testing.assert_allclose(a.translation, b.translation, atol=1e-7)
        assert b.params["r"] == pytest.approx(r, abs=1e-7)
        assert b.iterations < a.iterations and b.converged
    sphere = csdf.sphere(csdf.param("r", 0.5, 0.1, 2.0))
    Ps = _scene(sphere, n=800, r=0.7)
    res = csdf.fit(sphere, Ps, init={"translation": T_TRUE + 0.01, "params": {"r": 0.69}},
                   estimate="pose,scale,params", coarse=False)
    assert any("ambiguous" in n for n in res.notes) and res.scale == 1.0
    assert res.params["r"] == pytest.approx(0.7, rel=1e-6)


def test_a_looser_tol_stops_sooner_at_the_same_solution():
    # tol: the last stage stops when a step lowers the cost by less than that fraction
    shape = _part()
    M = _init(1.0, 0.002)
    P = _scene(shape, r=0.13)
    P = P + np.random.default_rng(4).normal(0.0, 2e-4, P.shape)  # a little noise
    init = {"rotation": M[:3, :3], "translation": M[:3, 3], "params": {"r": 0.12}}
    kw = dict(init=init, estimate="pose,params", coarse=False, loss="huber", f_scale=6e-4)
    a = csdf.fit(shape, P, **kw)
    b = csdf.fit(shape, P, tol=1e-4, **kw)
    assert b.iterations < a.iterations
    assert b.params["r"] == pytest.approx(a.params["r"], abs=2e-5)
    assert rotation_angle(a.rotation, b.rotation) < 1e-3
    for bad in (0.0, 1.0, -1e-3, "x"):
        with pytest.raises(csdf.CsdfError, match="tol"):
            csdf.fit(shape, P, tol=bad, **kw)


def test_scale_size_ambiguity_is_noted_and_resolved():
    r = csdf.param("r", 0.5, 0.1, 2.0)
    shape = csdf.sphere(r) | csdf.box(0.6).translate((0.4, 0, 0))  # r does not resize all
    sphere = csdf.sphere(r)
    P = _scene(sphere, n=800, r=0.7)
    res = csdf.fit(sphere, P, init={"translation": T_TRUE + 0.05},
                   estimate="pose,scale,params")
    assert any("ambiguous" in n for n in res.notes)
    # scale is held at its start and the parameter explains the size
    assert res.scale == 1.0 and res.params["r"] == pytest.approx(0.7, rel=1e-6)
    assert shape.params  # the union keeps r meaningful: no note expected there
    P2 = _scene(shape, n=1500, s=1.2)
    res2 = csdf.fit(shape, P2, init=_init(5), estimate="pose,scale,params")
    assert res2.scale == pytest.approx(1.2, rel=1e-4) and not res2.notes


def test_robust_loss_with_outliers():
    shape = _part()
    P = _scene(shape, n=2000)
    rng = np.random.default_rng(3)
    noise = rng.normal(scale=0.001, size=P.shape)
    out = rng.uniform(P.min(0) - 0.2, P.max(0) + 0.2, (1000, 3))  # a third are outliers
    res = csdf.fit(shape, np.vstack([P + noise, out]), init=_init(20), loss="cauchy")
    assert rotation_angle(res.rotation, R_TRUE) < np.deg2rad(0.5)
    assert np.linalg.norm(res.translation - T_TRUE) < 0.002
    assert 0.6 < res.inlier_fraction < 0.75


def _cluttered(seed=0):
    """1000 surface points (noise 1 mm) and as many outliers in a box on one side of the
    part (clutter): they pull Huber's optimum."""
    P = _scene(_part(), n=1000)
    rng = np.random.default_rng(seed)
    lo, hi = P.min(0), P.max(0)
    out = rng.uniform(lo, hi + np.array([0.15, 0.15, 0.0]), (1000, 3))
    return np.vstack([P + rng.normal(scale=0.001, size=P.shape), out])


def test_auto_loss_switches_to_cauchy_under_heavy_outliers():
    shape = _part()
    X = _cluttered()
    huber = csdf.fit(shape, X, init=_init(20), loss="huber")
    auto = csdf.fit(shape, X, init=_init(20))  # the default is loss='auto'
    assert huber.loss == "huber" and auto.loss == "cauchy"
    # Huber's optimum is pulled by the clutter; auto's (Cauchy's) is not
    assert rotation_angle(huber.rotation, R_TRUE) > np.deg2rad(1.0)
    assert np.linalg.norm(huber.translation - T_TRUE) > 0.003
    assert rotation_angle(auto.rotation, R_TRUE) < np.deg2rad(0.3)
    assert np.linalg.norm(auto.translation - T_TRUE) < 0.001
    assert any("loss='auto'" in n and "Cauchy" in n for n in auto.notes)
    assert auto.to_dict()["loss"] == "cauchy"


def test_auto_loss_is_huber_on_a_clean_cloud():
    shape = _part()
    P = _scene(shape, n=1500) + np.random.default_rng(1).normal(scale=0.001, size=(1500, 3))
    huber = csdf.fit(shape, P, init=_init(20), loss="huber")
    auto = csdf.fit(shape, P, init=_init(20), loss="auto")
    assert auto.loss == huber.loss == "huber"
    np.testing.assert_array_equal(auto.transform, huber.transform)
    assert auto.notes == huber.notes == [] and auto.cost == huber.cost
    # also through multistart's final refinement and the SciPy engine
    a = csdf.fit(shape, P, multistart=True, seed=3)
    b = csdf.fit(shape, P, multistart=True, seed=3, loss="huber")
    np.testing.assert_array_equal(a.transform, b.transform)
    assert a.loss == "huber"
    c = csdf.fit(shape, P, init=_init(5), solver="scipy")
    assert c.loss == "huber" and rotation_angle(c.rotation, R_TRUE) < np.deg2rad(0.3)


def test_multistart_from_any_rotation_is_reproducible():
    shape = _part()
    P = _scene(shape, n=1200)
    a = csdf.fit(shape, P, multistart=True, seed=7)
    b = csdf.fit(shape, P, multistart=True, seed=7)
    np.testing.assert_array_equal(a.transform, b.transform)
    assert rotation_angle(a.rotation, R_TRUE) < np.deg2rad(0.1)


def test_icp_baseline():
    shape = _part()
    P = _scene(shape, n=1500)
    res = csdf.icp(shape, P, init=_init(10), seed=0)
    assert res.method == "icp" and res.scale == 1.0
    assert rotation_angle(res.rotation, R_TRUE) < np.deg2rad(1.0)
    assert np.linalg.norm(res.translation - T_TRUE) < 0.003


def test_bad_input():
    shape = _part()
    P = _scene(shape, n=50)
    with pytest.raises(csdf.CsdfError, match="empty"):
        csdf.fit(shape, np.zeros((0, 3)))
    bad = P.copy()
    bad[3] = np.nan
    with pytest.raises(csdf.CsdfError, match="NaN or inf .*rows \\[3\\]"):
        csdf.fit(shape, bad)
    with pytest.raises(csdf.ParamError, match="unknown parameter.*radius.*r"):
        csdf.fit(shape, P, estimate="pose,params", params=["radius"])
    with pytest.raises(csdf.CsdfError, match="cannot determine 8 unknowns"):
        csdf.fit(shape, P[:5], estimate="pose,scale,params")
    with pytest.raises(csdf.CsdfError, match="shape \\(N, 3\\)"):
        csdf.fit(shape, P[:, :2])
    with pytest.raises(csdf.CsdfError, match="estimate must be"):
        csdf.fit(shape, P, estimate="pose,colour")
    with pytest.raises(csdf.CsdfError, match="loss must be one of auto, huber, cauchy, "
                       "linear, soft_l1, arctan; got 'l3'"):
        csdf.fit(shape, P, loss="l3")


def _plate_scan():
    """A plate seen from straight above by the synthetic sensor (only its top face);
    points in the camera frame (sensor at the origin) and the plate's true pose there."""
    plate = csdf.box((0.3, 0.2, 0.04))
    cam = csdf.Camera.look_at((0.0, 0.0, 0.6), (0.0, 0.0, 0.0), up=(0, 1, 0), fov=30.0,
                              width=48, height=48)
    pts, _ = csdf.scan(plate, cam)
    R, t = cam.R.T, cam.R.T @ (np.zeros(3) - cam.t)
    return plate, pts, R, t


def test_visibility_rejects_back_face_minimum():
    from csdf.fit.lm import State, Visibility, lm_solve
    from csdf.fit.problem import prepare

    plate, P, R, t = _plate_scan()
    # the plate pulled towards the sensor by its thickness (along its normal n): the
    # scanned top face then lies on the model's bottom face, as good a fit for the plain
    # distance residuals as the truth (only the offset along n is observable here)
    n = R @ np.array([0.0, 0.0, 1.0])
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t + 0.045 * n
    prob = prepare(plate, P, init=M)
    start = State(prob.R, prob.t, 0.0, np.zeros(0))
    fs = prob.f_scale
    plain = lm_solve(prob, P, start, [], fs, 50)[0]
    assert abs((plain.t - t) @ n) > 0.03  # stays on the back face
    vis = Visibility(np.zeros(3), 0.5 * prob.size)
    st = start
    for _ in range(4):  # re-match, like ICP
        st = lm_solve(prob, P, st, [], fs, 50, vis=vis)[0]
    assert abs((st.t - t) @ n) < 1e-6 and np.linalg.norm(st.R[:, 2] - n) < 1e-6
    res = csdf.fit(plate, P, init=M, viewpoint=np.zeros(3))
    assert abs((res.translation - t) @ n) < 1e-6
    with pytest.raises(csdf.CsdfError, match="viewpoint must be"):
        csdf.fit(plate, P, viewpoint=[0.0, 1.0])
    with pytest.raises(csdf.CsdfError, match="viewpoint needs solver='lm'"):
        csdf.fit(plate, P, viewpoint=np.zeros(3), solver="scipy")


def test_solvers_agree_on_noiseless_data():
    shape = _part()
    P = _scene(shape, n=800)
    a = csdf.fit(shape, P, init=_init(15), solver="lm")
    b = csdf.fit(shape, P, init=_init(15), solver="scipy")
    for r in (a, b):
        assert rotation_angle(r.rotation, R_TRUE) < 1e-7
        np.testing.assert_allclose(r.translation, T_TRUE, atol=1e-8)
    with pytest.raises(csdf.CsdfError, match="solver must be"):
        csdf.fit(shape, P, solver="newton")


def test_escape_leaves_a_near_symmetric_minimum():
    # a disc with six bolt holes: turned by ~30 degrees about its axis the holes sit
    # between their true places, a local minimum of the distance residuals
    hole = csdf.cylinder(0.012, 0.1).translate((0.1, 0.0, 0.0)).repeat_polar(6)
    disc = csdf.cylinder(0.15, 0.03) - hole
    P = _scene(disc, n=1500)
    M = np.eye(4)
    M[:3, :3] = R_TRUE @ exp_so3(np.deg2rad(28.0) * np.array([0.0, 0.0, 1.0]))
    M[:3, 3] = T_TRUE
    stuck = csdf.fit(disc, P, init=M, escape=False)
    assert rotation_angle(stuck.rotation, R_TRUE) > np.deg2rad(5)
    res = csdf.fit(disc, P, init=M)
    z = np.array([0.0, 0.0, 1.0])  # exact modulo the six-fold symmetry
    assert min(rotation_angle(res.rotation, R_TRUE @ exp_so3(k * np.pi / 3 * z))
               for k in range(6)) < 1e-6


def test_noise_bias_of_parameters_is_corrected():
    r = csdf.param("r", 0.1, 0.05, 0.2)
    ball = csdf.sphere(r) | csdf.box((0.05, 0.05, 0.3))  # pose is observable
    P = _scene(ball, n=3000, r=0.08)
    P = P + np.random.default_rng(5).normal(scale=0.006, size=P.shape)
    kw = dict(init={"rotation": R_TRUE, "translation": T_TRUE}, estimate="pose,params")
    biased = csdf.fit(ball, P, debias=False, **kw)
    fixed = csdf.fit(ball, P, **kw)
    err0, err1 = abs(biased.params["r"] - 0.08), abs(fixed.params["r"] - 0.08)
    assert err0 > 1e-4 and err1 < err0 / 3


def test_parameters_that_start_too_large_are_recovered():
    # a rod whose length starts far too long: the points on its true end caps lie inside
    # the long rod, nearer its side than its caps, so only a start from short lengths
    # (the joint stage's second start) pulls the caps to them
    length = csdf.param("length", 0.3, 0.1, 0.4)
    rod = csdf.cylinder(0.02, length) | csdf.box((0.08, 0.01, 0.01))
    P = _scene(rod, n=2000, length=0.15)
    res = csdf.fit(rod, P, init={"rotation": R_TRUE, "translation": T_TRUE},
                   estimate="pose,params")
    assert res.params["length"] == pytest.approx(0.15, abs=1e-6)
    assert rotation_angle(res.rotation, R_TRUE) < 1e-6


@pytest.mark.parametrize("estimate", [("pose",), ("pose", "scale"), ("pose", "params"),
                                      ("pose", "scale", "params"), ("params",)])
def test_lm_system_is_the_normal_equations_of_the_jacobian_to_the_last_bit(estimate):
    """lm_solve forms J^T W J and J^T W r row by row without the Jacobian (`_system`);
    the sums must be those of normal_equations on `jacobian`'s columns, bit for bit, so
    that a fit's result does not depend on which path formed them."""
    from csdf.fit.lm import State, _linearised, _system, normal_equations
    from csdf.fit.problem import jacobian, loss_weights, prepare

    shape = csdf.zoo.load("table")
    rng = np.random.default_rng(3)
    P = rng.normal(size=(700, 3)) * 0.4
    prob = prepare(shape, P, None, estimate, None, "cauchy", 0.01, "auto")
    idx = [i for i, p in enumerate(prob.prog.params) if p.name in prob.names]
    st = State(prob.R @ exp_so3(np.array([0.1, -0.2, 0.05])),
               prob.t + 0.01, 0.02 if prob.scale else 0.0, prob.values[idx] * 1.01)
    r, lin = _linearised(prob, P, st, idx, prob.f_scale)
    _, w = loss_weights(r, prob.f_scale, "cauchy")
    A, b = _system(prob, lin, w, r)
    A0, b0 = normal_equations(jacobian(prob.pose, prob.scale, *lin), w, r)
    assert A.shape == (6 * prob.pose + prob.scale + len(idx),) * 2
    np.testing.assert_array_equal(A, A0)
    np.testing.assert_array_equal(b, b0)


def test_compiled_huber_weights_are_the_numpy_rule():
    """loss_weights' compiled Huber pass gives the cost and weights of the NumPy rule
    (``_rho_w``) to the bit, NaN residuals included."""
    from csdf.fit.problem import _rho_w, loss_weights

    r = np.random.default_rng(3).normal(0.0, 2.0, 5000)
    r[[3, 17]] = [np.nan, 0.0]
    fs = 0.7
    rho, w = _rho_w((r / fs) ** 2, "huber")
    cost, w2 = loss_weights(r, fs, "huber")
    np.testing.assert_array_equal(w2, w)
    assert cost == 0.5 * fs * fs * float(np.sum(rho)) or (np.isnan(cost)
                                                           and np.isnan(np.sum(rho)))
    cost, w2 = loss_weights(r[~np.isnan(r)], fs, "huber")
    rho, w = _rho_w((r[~np.isnan(r)] / fs) ** 2, "huber")
    np.testing.assert_array_equal(w2, w)
    assert cost == 0.5 * fs * fs * float(np.sum(rho))
