import numpy as np
import pytest
import scipy.sparse as sp

from labutils.bundle.adjust import bundle_adjust, bundle_adjust_params
from labutils.bundle.reprojection import (
    Rt_from_camera_params,
    camera_params_from_Rt,
    jacobian_sparsity,
    reprojection_jacobian,
    reprojection_residuals,
)
from labutils.core.geometry import camera_center, left_jacobian_so3, rotation_from_angle_axis, skew
from labutils.core.metrics import ml_residual_bound, pose_errors
from labutils.core.robust import robust_cost
from labutils.core.scene import observations
from labutils.core.synthetic import make_scene

D_BAL = np.diag([1.0, -1.0, -1.0])          # our camera (z forward, y down) -> BAL's (looks down -z, y up)


def numeric_jacobian(cp, X, ci, pi, x, K, h=1e-6):
    """Central differences of the residuals with respect to [camera_params, points_3d]."""
    V, k = cp.shape
    p0 = np.concatenate([cp.ravel(), X.ravel()])

    def f(p):
        return reprojection_residuals(p[:V * k].reshape(V, k), p[V * k:].reshape(-1, 3), ci, pi, x, K)

    J = np.zeros((2 * len(ci), p0.size))
    for j in range(p0.size):
        e = np.zeros(p0.size)
        e[j] = h * max(1.0, abs(p0[j]))
        J[:, j] = (f(p0 + e) - f(p0 - e)) / (2 * e[j])
    return J


def perturbed_problem(rng, n_points=60, n_views=5, noise_px=0.0, rot_deg=1.0, shift=0.02, layout="general"):
    s = make_scene(n_points, n_views, layout=layout, noise_px=noise_px, rng=rng)
    ci, pi, x = observations(s.x_meas)
    R0 = np.stack([rotation_from_angle_axis(rng.normal(size=3) * np.radians(rot_deg) / np.sqrt(3)) @ R for R in s.R])
    t0 = s.t + rng.normal(scale=shift, size=s.t.shape)
    X0 = s.X + rng.normal(scale=shift, size=s.X.shape)
    return s, (R0, t0, X0, ci, pi, x)


def bal_problem(rng, n_points=50, n_views=4, noise_px=0.0):
    """A small synthetic problem in the BAL camera model (f, k1, k2 per camera)."""
    s = make_scene(n_points, n_views, noise_px=0.0, rng=rng)
    cp = camera_params_from_Rt(D_BAL @ s.R, s.t @ D_BAL)
    intr = np.column_stack([s.K[0, 0] * (1 + 0.02 * rng.normal(size=n_views)),
                            0.05 * rng.normal(size=n_views), 0.01 * rng.normal(size=n_views)])
    cp = np.hstack([cp, intr])
    ci, pi, _ = observations(s.x_true)
    r = reprojection_residuals(cp, s.X, ci, pi, np.zeros((len(ci), 2)), None).reshape(-1, 2)
    return cp, s.X, ci, pi, r + rng.normal(scale=noise_px, size=r.shape) if noise_px else r


# ------------------------------------------------------------------------------------------ shapes, packing
def test_camera_params_round_trip(rng):
    R = np.stack([rotation_from_angle_axis(w) for w in rng.normal(size=(6, 3))])
    t = rng.normal(size=(6, 3))
    cp = camera_params_from_Rt(R, t)
    assert cp.shape == (6, 6)
    R2, t2 = Rt_from_camera_params(cp)
    assert np.abs(R2 - R).max() < 1e-12 and np.abs(t2 - t).max() == 0


def test_residual_shape_and_value(rng):
    s, (R0, t0, X0, ci, pi, x) = perturbed_problem(rng)
    cp = camera_params_from_Rt(s.R, s.t)
    r_true = reprojection_residuals(cp, s.X, ci, pi, x, s.K)
    assert r_true.shape == (2 * len(ci),) and np.abs(r_true).max() < 1e-9
    r = reprojection_residuals(cp, s.X, ci, pi, x + [1.0, -2.0], s.K).reshape(-1, 2)
    assert np.allclose(r, [-1.0, 2.0])


# ------------------------------------------------------------------------------------------ Jacobian
def test_left_jacobian_matches_finite_differences(rng):
    for w in [rng.normal(size=3), 1e-7 * rng.normal(size=3), 3.0 * rng.normal(size=3) / np.sqrt(3)]:
        X = rng.normal(size=3)
        Jl = left_jacobian_so3(w[None])[0]
        analytic = -skew(rotation_from_angle_axis(w) @ X) @ Jl            # ∂(R(ω) X)/∂ω = -[R X]× J_l(ω)
        num = np.stack([(rotation_from_angle_axis(w + e) @ X - rotation_from_angle_axis(w - e) @ X) / 2e-6
                        for e in 1e-6 * np.eye(3)], axis=1)
        assert np.abs(analytic - num).max() < 1e-8


@pytest.mark.parametrize("model", ["shared K", "per-camera K with skew", "BAL"])
def test_jacobian_matches_finite_differences(rng, model):
    for _ in range(3):
        if model == "BAL":
            cp, X, ci, pi, x = bal_problem(rng, n_points=15, n_views=3)
            cp[:, :3] += 0.3 * rng.normal(size=(3, 3))          # a random problem, away from the optimum
            K = None
        else:
            s = make_scene(15, 3, noise_px=1.0, rng=rng)
            ci, pi, x = observations(s.x_meas)
            cp = camera_params_from_Rt(s.R, s.t)
            cp[:, :3] += 0.5 * rng.normal(size=(3, 3))
            X = s.X + 0.05 * rng.normal(size=s.X.shape)
            K = s.K
            if model != "shared K":
                K = np.stack([s.K + [[100 * rng.normal(), -78.6, 5], [0, 50 * rng.normal(), 3], [0, 0, 0]]
                              for _ in range(3)])
        J = reprojection_jacobian(cp, X, ci, pi, K)
        assert sp.issparse(J) and J.shape == (2 * len(ci), cp.size + X.size)
        Jn = numeric_jacobian(cp, X, ci, pi, x, K)
        rel = np.abs(J.toarray() - Jn).max() / np.abs(Jn).max()
        assert rel < 1e-6, f"{model}: relative error {rel:.2e}"


def test_sparsity_mask_covers_jacobian_and_column_order(rng):
    s = make_scene(30, 4, rng=rng)
    ci, pi, x = observations(s.x_meas)
    cp = camera_params_from_Rt(s.R, s.t)
    J = reprojection_jacobian(cp, s.X, ci, pi, s.K).toarray()
    A = jacobian_sparsity(4, 30, ci, pi).toarray()
    assert A.shape == J.shape
    assert np.all(A[np.abs(J) > 0] == 1)                     # the mask covers every non-zero
    assert A.sum() == 2 * len(ci) * (6 + 3)
    # observation 0: its camera's 6 columns, then its point's 3 columns at 6 V + 3 p
    i = 0
    nz = np.flatnonzero(A[2 * i])
    assert nz.tolist() == list(range(6 * ci[i], 6 * ci[i] + 6)) + list(range(24 + 3 * pi[i], 24 + 3 * pi[i] + 3))
    A9 = jacobian_sparsity(4, 30, ci, pi, camera_block=9)
    assert A9.shape == (2 * len(ci), 36 + 90)


# ------------------------------------------------------------------------------------------ recovery
@pytest.mark.parametrize("solver", ["lm-schur", "scipy"])
def test_noise_free_recovery_with_gauge(rng, solver):
    s, (R0, t0, X0, ci, pi, x) = perturbed_problem(rng, n_points=80, n_views=6, rot_deg=1.0, shift=0.02)
    res = bundle_adjust(R0, t0, X0, ci, pi, x, s.K, solver=solver, tol=1e-12, max_iter=200)
    assert res.success and res.cost_final < 1e-12 < res.cost_initial
    rot, centre = pose_errors(res.R, res.t, s.R, s.t)
    assert rot.max() < 1e-6 and centre.max() < 1e-8
    # the gauge: camera 0's pose is the starting one, and so is the distance between the first two centres
    assert np.abs(res.R[0] - R0[0]).max() < 1e-12 and np.abs(res.t[0] - t0[0]).max() < 1e-12
    C0, C = -R0.transpose(0, 2, 1) @ t0[..., None], -res.R.transpose(0, 2, 1) @ res.t[..., None]
    assert abs(np.linalg.norm(C[1] - C[0]) - np.linalg.norm(C0[1] - C0[0])) < 1e-12
    assert res.n_free == 6 * 6 - 7 + 3 * 80 and res.free.shape == (6 * 6 + 3 * 80,)
    assert res.residuals.shape == (len(ci), 2)


def test_gauge_none_and_fixed_cameras(rng):
    s, (R0, t0, X0, ci, pi, x) = perturbed_problem(rng, n_points=60, n_views=5)
    free = bundle_adjust(R0, t0, X0, ci, pi, x, s.K, gauge=None, tol=1e-12)
    assert free.cost_final < 1e-12 and free.n_free == 5 * 6 + 3 * 60 and free.gauge == {}
    # two true cameras held: the similarity is fixed by them, the rest is recovered in the true frame
    R0[:2], t0[:2] = s.R[:2], s.t[:2]
    fixed = bundle_adjust(R0, t0, X0, ci, pi, x, s.K, fixed_cameras=[0, 1], tol=1e-12)
    assert np.abs(fixed.R[:2] - s.R[:2]).max() < 1e-15 and np.abs(fixed.t[:2] - s.t[:2]).max() == 0
    assert np.abs(fixed.X - s.X).max() < 1e-8 and fixed.n_free == 3 * 6 + 3 * 60


def test_one_fixed_camera_is_the_anchor(rng):
    s, (R0, t0, X0, ci, pi, x) = perturbed_problem(rng, n_points=60, n_views=5)
    res = bundle_adjust(R0, t0, X0, ci, pi, x, s.K, fixed_cameras=[2], tol=1e-12)
    assert res.gauge["anchor"] == 2 and res.gauge["scale_camera"] == 0
    assert np.abs(res.R[2] - R0[2]).max() < 1e-15 and np.abs(res.t[2] - t0[2]).max() < 1e-15
    C = camera_center(res.R, res.t)
    C0 = camera_center(R0, t0)
    assert abs(np.linalg.norm(C[0] - C[2]) - np.linalg.norm(C0[0] - C0[2])) < 1e-12
    assert pose_errors(res.R, res.t, s.R, s.t)[0].max() < 1e-6 and res.n_free == 4 * 6 - 1 + 3 * 60


def test_single_threaded_blas_restores_the_thread_count():
    from labutils.core.blas import _openblas_controls, single_threaded_blas

    before = [get() for get, _ in _openblas_controls()]
    with single_threaded_blas():
        assert all(get() == 1 for get, _ in _openblas_controls())
    assert [get() for get, _ in _openblas_controls()] == before


def test_pose_refinement_with_fixed_points(rng):
    """A PnP-style refinement: one camera, all points held."""
    s = make_scene(40, 2, noise_px=0.0, rng=rng)
    ci, pi, x = observations(s.x_true[:1])
    R0 = rotation_from_angle_axis([0.01, -0.02, 0.01]) @ s.R[0]
    res = bundle_adjust(R0[None], s.t[:1] + 0.01, s.X, ci, pi, x, s.K, fixed_points=np.arange(40), tol=1e-12)
    assert np.abs(res.X - s.X).max() == 0 and res.n_free == 6
    assert np.abs(res.R[0] - s.R[0]).max() < 1e-9 and np.abs(res.t[0] - s.t[0]).max() < 1e-9


def test_noisy_residual_matches_theory(rng):
    """RMS residual at the optimum ≈ σ sqrt(1 - d/N) (H&Z Result 5.2), pooled over trials."""
    sigma, ss, n_res, d = 1.0, 0.0, 0, 0
    for _ in range(4):
        s, (R0, t0, X0, ci, pi, x) = perturbed_problem(rng, n_points=60, n_views=4, noise_px=sigma, rot_deg=0.5,
                                                       shift=0.01)
        res = bundle_adjust(R0, t0, X0, ci, pi, x, s.K)
        ss += 2 * res.cost_final
        n_res += 2 * len(ci)
        d = res.n_free
    rms = np.sqrt(ss / n_res)
    expected = ml_residual_bound(sigma, n_res // 4, d)
    assert abs(rms / expected - 1) < 0.05                       # 960 residuals: ~2 % standard error


def test_robust_loss_resists_outliers_and_solvers_agree(rng):
    s = make_scene(150, 6, noise_px=0.5, outlier_ratio=0.05, rng=rng)
    ci, pi, x = observations(s.x_meas)
    R0 = np.stack([rotation_from_angle_axis(rng.normal(size=3) * np.radians(0.3)) @ R for R in s.R])
    X0 = s.X + rng.normal(scale=0.005, size=s.X.shape)
    plain = bundle_adjust(R0, s.t, X0, ci, pi, x, s.K)
    robust = {solver: bundle_adjust(R0, s.t, X0, ci, pi, x, s.K, solver=solver, loss="cauchy", f_scale=1.0,
                                    max_iter=500)
              for solver in ("lm-schur", "scipy")}
    err_plain = pose_errors(plain.R, plain.t, s.R, s.t)[0].mean()
    err_robust = pose_errors(robust["lm-schur"].R, robust["lm-schur"].t, s.R, s.t)[0].mean()
    assert err_robust < 0.3 * err_plain
    a, b = robust["lm-schur"].loss_cost_final, robust["scipy"].loss_cost_final
    assert abs(a - b) / b < 1e-3 and a <= b * (1 + 1e-6)
    # the robust cost is what was minimised
    assert robust["lm-schur"].loss_cost_final == pytest.approx(
        robust_cost(robust["lm-schur"].residuals, "cauchy", 1.0))


def test_cost_text_names_the_robust_cost_that_was_lowered(rng):
    """The log line of a robust BA gives the cost it minimised (which must fall) and the plain one in brackets."""
    s = make_scene(60, 4, noise_px=0.5, outlier_ratio=0.1, rng=rng)
    ci, pi, x = observations(s.x_meas)
    plain = bundle_adjust(s.R, s.t, s.X, ci, pi, x, s.K)
    assert plain.cost_text().startswith(f"{plain.cost_initial:.4g} -> {plain.cost_final:.4g} px² in ")
    robust = bundle_adjust(s.R, s.t, s.X, ci, pi, x, s.K, loss="cauchy", f_scale=1.0)
    text = robust.cost_text()
    assert robust.loss_cost_final < robust.loss_cost_initial
    assert text.startswith(f"robust cost {robust.loss_cost_initial:.4g} -> {robust.loss_cost_final:.4g} (½Σr² ")
    assert f"{robust.cost_initial:.4g} -> {robust.cost_final:.4g} px²) in {robust.n_iter} iterations" in text


def test_bal_model_solvers_agree_and_intrinsics_option(rng):
    cp, X, ci, pi, x = bal_problem(rng, n_points=80, n_views=5, noise_px=0.5)
    cp0 = cp.copy()
    cp0[:, :3] += 0.005 * rng.normal(size=(5, 3))
    cp0[:, 6] *= 1.01
    X0 = X + 0.005 * rng.normal(size=X.shape)
    cost = {}
    for fix in (False, True):
        out = {solver: bundle_adjust_params(cp0, X0, ci, pi, x, None, solver=solver, fix_intrinsics=fix, max_iter=300)
               for solver in ("lm-schur", "scipy")}
        a, b = out["lm-schur"].cost_final, out["scipy"].cost_final
        assert abs(a - b) / b < 1e-3
        assert a < 0.5 * 0.5 ** 2 * 2 * len(ci)               # below the noise level: 0.5 σ² N
        cost[fix] = a
        if fix:
            assert np.all(out["lm-schur"].camera_params[:, 6:] == cp0[:, 6:])
            assert out["lm-schur"].n_free == 5 * 6 - 7 + 3 * 80
        else:
            assert np.all(out["lm-schur"].camera_params[:, 6:] != cp0[:, 6:])
            assert out["lm-schur"].n_free == 5 * 9 - 7 + 3 * 80
    assert cost[False] < cost[True]                             # more freedom, lower cost


def test_dino_subset_solvers_agree(dino):
    """LM-Schur and scipy reach the same cost on the real tracks (8 views, for speed; all 36 in notebook 04)."""
    V = 8
    tr = dino.tracks[:V]
    keep = np.isfinite(tr[..., 0]).sum(0) >= 2
    ci, pi, x = observations(tr[:, keep])
    from labutils.twoview.triangulation import triangulate_multiview

    X0 = triangulate_multiview(dino.P[:V], tr[:, keep])
    out = [bundle_adjust(dino.R[:V], dino.t[:V], X0, ci, pi, x, dino.K, solver=solver, loss="cauchy", max_iter=500)
           for solver in ("lm-schur", "scipy")]
    assert abs(out[0].loss_cost_final / out[1].loss_cost_final - 1) < 1e-3
    assert out[0].loss_cost_final < out[0].loss_cost_initial


# ------------------------------------------------------------------------------------------ bad input
def test_bad_input(rng):
    s, (R0, t0, X0, ci, pi, x) = perturbed_problem(rng, n_points=20, n_views=3)
    cp = camera_params_from_Rt(R0, t0)
    with pytest.raises(ValueError, match="indexes a missing camera"):
        bundle_adjust(R0, t0, X0, np.where(ci == 2, 3, ci), pi, x, s.K)
    with pytest.raises(ValueError, match="indexes a missing point"):
        bundle_adjust(R0, t0, X0, ci, np.where(pi == 0, 20, pi), x, s.K)
    with pytest.raises(ValueError, match="indexes a missing camera"):
        bundle_adjust(R0, t0, X0, ci - 1, pi, x, s.K)
    bad = x.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="points_2d has non-finite"):
        bundle_adjust(R0, t0, X0, ci, pi, bad, s.K)
    badX = X0.copy()
    badX[0, 0] = np.inf
    with pytest.raises(ValueError, match="X has non-finite"):
        bundle_adjust(R0, t0, badX, ci, pi, x, s.K)
    with pytest.raises(ValueError, match="non-finite"):
        bundle_adjust(R0, t0 * np.nan, X0, ci, pi, x, s.K)
    keep = ci != 1
    with pytest.raises(ValueError, match=r"camera\(s\) \[1\] have no observations"):
        bundle_adjust(R0, t0, X0, ci[keep], pi[keep], x[keep], s.K)
    keep = pi != 5
    with pytest.raises(ValueError, match=r"point\(s\) \[5\] have no observations"):
        bundle_adjust(R0, t0, X0, ci[keep], pi[keep], x[keep], s.K)
    few = (pi < 2) | (np.arange(len(pi)) < 3)
    sub = np.unique(pi[few])
    remap = np.searchsorted(sub, pi[few])
    with pytest.raises(ValueError, match="fewer residuals"):
        bundle_adjust(R0, t0, X0[sub], ci[few], remap, x[few], s.K)
    with pytest.raises(ValueError, match="one entry of each per observation"):
        bundle_adjust(R0, t0, X0, ci, pi[:-1], x, s.K)
    with pytest.raises(ValueError, match="integers"):
        bundle_adjust(R0, t0, X0, ci + 0.5, pi, x, s.K)
    with pytest.raises(ValueError, match="K must have shape"):
        bundle_adjust(R0, t0, X0, ci, pi, x, np.eye(4))
    with pytest.raises(ValueError, match="rotation"):
        bundle_adjust(R0 * 2, t0, X0, ci, pi, x, s.K)
    with pytest.raises(ValueError, match="solver"):
        bundle_adjust(R0, t0, X0, ci, pi, x, s.K, solver="ceres")
    with pytest.raises(ValueError, match="loss"):
        bundle_adjust(R0, t0, X0, ci, pi, x, s.K, loss="tukey")
    with pytest.raises(ValueError, match="gauge"):
        bundle_adjust(R0, t0, X0, ci, pi, x, s.K, gauge="first-camera")
    with pytest.raises(ValueError, match="K=None"):
        reprojection_residuals(np.hstack([cp, np.ones((3, 3))]), X0, ci, pi, x, s.K)
    with pytest.raises(ValueError, match="needs the calibration K"):
        reprojection_residuals(cp, X0, ci, pi, x, None)
    with pytest.raises(ValueError, match="fix_intrinsics"):
        bundle_adjust_params(cp, X0, ci, pi, x, s.K, fix_intrinsics=True)
