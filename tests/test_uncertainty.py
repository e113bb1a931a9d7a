"""The predicted pose covariance (Cramér–Rao bound in the alignment gauge) and the noise-study helpers."""
import numpy as np
import pytest

from labutils.bundle import reprojection as bundle
from labutils.bundle import uncertainty as U
from labutils.core.geometry import angle_axis_from_rotation, camera_center
from labutils.core.metrics import align_cameras, pose_errors, rotation_error_deg
from labutils.core.scene import observations
from labutils.core.synthetic import make_scene
from labutils.sfm import noise_study as NS


@pytest.fixture(scope="module")
def small():
    """A small turntable (12 views, ~140 points, ~600 observations), noise-free."""
    s = make_scene(150, 12, layout="turntable", noise_px=0.0, rng=np.random.default_rng(1))
    ci, pi, _ = observations(s.x_true)
    return s, ci, pi


def _aligned_error_vector(cp, s):
    """Nonlinear reference: BA camera parameters -> Umeyama alignment -> (φ_i, c_i) per camera."""
    R, t = bundle.Rt_from_camera_params(cp)
    R_al, t_al, _ = align_cameras(R, t, s.R, s.t)
    phi = [angle_axis_from_rotation(Ra @ Rt.T) for Ra, Rt in zip(R_al, s.R)]
    dC = camera_center(R_al, t_al) - camera_center(s.R, s.t)
    return np.hstack([np.array(phi), dC]).ravel()


def test_gauge_basis_spans_the_null_space_of_the_jacobian(small):
    s, ci, pi = small
    J = bundle.reprojection_jacobian(bundle.camera_params_from_Rt(s.R, s.t), s.X, ci, pi, s.K)
    N = U.gauge_basis(s.R, s.t, s.X)
    assert np.linalg.matrix_rank(N) == 7
    assert np.abs(J @ N).max() < 1e-12 * abs(J).max() * np.abs(N).max()
    # and nothing else is in the null space: exactly 7 tiny singular values of the (column-scaled) J
    Jd = J.toarray()
    sv = np.linalg.svd(Jd / np.linalg.norm(Jd, axis=0), compute_uv=False)
    assert sv[-7] < 1e-10 * sv[0] < sv[-8]


def test_pose_error_map_matches_finite_differences(small):
    """The hand-written linearisation of 'parameters -> alignment -> errors' against the nonlinear chain."""
    s, _, _ = small
    cp = bundle.camera_params_from_Rt(s.R, s.t)
    E = U.pose_error_map(s.R, s.t)
    h, V = 1e-6, len(s.R)
    E_num = np.empty_like(E)
    for k in range(6 * V):
        d = np.zeros(6 * V)
        d[k] = h
        E_num[:, k] = (_aligned_error_vector(cp + d.reshape(V, 6), s)
                       - _aligned_error_vector(cp - d.reshape(V, 6), s)) / (2 * h)
    assert np.abs(E - E_num).max() < 1e-7 * np.abs(E).max()


def test_pose_error_map_ignores_the_gauge(small):
    s, _, _ = small
    V = len(s.R)
    E = U.pose_error_map(s.R, s.t)
    N = U.gauge_basis(s.R, s.t, s.X)[:6 * V]
    assert np.abs(E @ N).max() < 1e-12 * np.abs(E).max() * np.abs(N).max()


def test_schur_dense_and_a_fixed_gauge_give_the_same_covariance(small):
    """The aligned covariance does not depend on how the gauge of JᵀJ is fixed (S-transformation)."""
    s, ci, pi = small
    V = len(s.R)
    schur = U.aligned_pose_covariance(s.R, s.t, s.X, ci, pi, s.K, 1.0)
    dense = U.aligned_pose_covariance(s.R, s.t, s.X, ci, pi, s.K, 1.0, method="dense")
    assert np.allclose(schur, dense, rtol=0, atol=1e-9 * np.abs(dense).max())
    # gauge fixed by deleting 7 columns (camera 0 and one translation coordinate of camera 1), as BA does
    J = bundle.reprojection_jacobian(bundle.camera_params_from_Rt(s.R, s.t), s.X, ci, pi, s.K).toarray()
    keep = np.ones(J.shape[1], bool)
    keep[:6] = False
    keep[6 + 3 + np.argmax(np.abs(s.t[1]))] = False
    H_inv = np.zeros((J.shape[1],) * 2)
    H_inv[np.ix_(keep, keep)] = np.linalg.inv(J[:, keep].T @ J[:, keep])
    E = U.pose_error_map(s.R, s.t)
    fixed = E @ H_inv[:6 * V, :6 * V] @ E.T
    assert np.allclose(schur, fixed, rtol=0, atol=1e-7 * np.abs(dense).max())
    # while the covariance in that fixed gauge itself, without the alignment, is a different thing
    D = U.camera_perturbation_map(s.R, s.t)
    raw = np.einsum("vij,vjk,vlk->vil", D, H_inv[:6 * V, :6 * V].reshape(V, 6, V, 6)[np.arange(V), :, np.arange(V)], D)
    schur_rot = schur.reshape(V, 6, V, 6)[np.arange(V), :3, np.arange(V), :3]
    assert abs(np.trace(raw[:, :3, :3], axis1=1, axis2=2).sum() / np.trace(schur_rot, axis1=1, axis2=2).sum() - 1) > 0.2


def test_s_transformation_projects_onto_the_gauge(small):
    s, _, _ = small
    N = U.gauge_basis(s.R, s.t, s.X)
    G = U.first_camera_gauge(s.R, s.t, s.X)
    P = U.s_transformation(N, G)
    scale = np.abs(P).max()
    assert np.abs(P @ N).max() < 1e-9 * scale * np.abs(N).max()
    assert np.abs(G.T @ P).max() < 1e-9 * scale * np.abs(G).max()
    assert np.abs(P @ P - P).max() < 1e-9 * scale ** 2
    with pytest.raises(ValueError, match="do not fix the gauge"):
        U.s_transformation(N, np.zeros_like(G))


def test_prediction_scales_with_sigma(small):
    s, ci, pi = small
    p1 = U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, 1.0)
    p3 = U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, 3.0)
    assert np.allclose(p3.cov, 9 * p1.cov) and np.allclose(p3.rot_rms_deg, 3 * p1.rot_rms_deg)
    assert np.all(p1.rot_rms_deg > 0) and np.all(p1.centre_rms_rel > 0)
    assert 1 <= p1.n_effective("rot") <= 3 * len(s.R) and 1 <= p1.n_effective("centre") <= 3 * len(s.R)


def test_monte_carlo_ba_from_truth_matches_the_prediction(small):
    """BA started from the truth on σ = 1 px observations, aligned: RMS errors within 10 % of the bound.

    Trial count: one trial's sum of squared errors is a Gaussian quadratic form worth n_eff ≈ 17
    independent χ²₁ terms (``PosePrediction.n_effective``), so the RMS over T trials has a relative
    standard deviation of 1 / sqrt(2 T n_eff); ``trials_needed(0.10, z=3)`` ≈ 27. We run 60 (sd ≈ 2 %:
    the 10 % band is ~4.5 standard deviations; a bias of the linearisation would show above that).
    """
    s, ci, pi = small
    sigma, n_trials = 1.0, 60
    pred = U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, sigma)
    assert max(pred.trials_needed(0.10, z=3, which=w) for w in ("rot", "centre")) <= n_trials
    rng = np.random.default_rng(2024)
    rot, cen, rot_raw, cen_raw = [], [], [], []
    C_true = camera_center(s.R, s.t)
    for _ in range(n_trials):
        x_meas, _ = NS.noisy_observations(s.x_true, sigma, rng=rng)
        R, t, _, info = NS.ba_from_truth(s, x_meas)
        r, c = pose_errors(R, t, s.R, s.t)
        rot.append(r)
        cen.append(c)
        # BA ran in its default gauge (camera 0 and the 0-1 baseline held): the raw errors
        rot_raw.append(rotation_error_deg(R, s.R))
        cen_raw.append(np.linalg.norm(camera_center(R, t) - C_true, axis=1) / pred.scene_size)
    rot_rms, cen_rms = NS.rms_errors(np.array(rot), np.array(cen))
    assert abs(rot_rms / pred.rot_rms_deg_all - 1) < 0.10
    assert abs(cen_rms / pred.centre_rms_rel_all - 1) < 0.10
    # the same trials in the fixed gauge match the fixed-gauge prediction (and not the aligned one)
    V = len(s.R)
    cov = U.gauge_pose_covariance(s.R, s.t, s.X, ci, pi, s.K, sigma).reshape(V, 6, V, 6)
    var = np.diagonal(cov.reshape(6 * V, 6 * V)).reshape(V, 6)
    rot_fixed = np.degrees(np.sqrt(var[:, :3].sum(1).mean()))
    cen_fixed = np.sqrt(var[:, 3:].sum(1).mean()) / pred.scene_size
    rot_raw_rms, cen_raw_rms = NS.rms_errors(np.array(rot_raw), np.array(cen_raw))
    # in this gauge the errors are dominated by a few drift modes (n_eff ≈ 5 for rotations, 1.5 for centres):
    # 3 sd of the Monte Carlo
    band = [3 / np.sqrt(2 * n_trials * U.effective_terms(cov[:, k, :, k].reshape(3 * V, 3 * V)))
            for k in (slice(0, 3), slice(3, 6))]
    assert abs(rot_raw_rms / rot_fixed - 1) < band[0] and abs(cen_raw_rms / cen_fixed - 1) < band[1]
    assert rot_fixed > 1.3 * pred.rot_rms_deg_all and var[0].max() < 1e-20
    # per camera too (each camera's RMS is noisier: 3 terms per trial, so a wider band)
    per_cam = np.sqrt(np.mean(np.array(rot) ** 2, axis=0)) / pred.rot_rms_deg
    assert np.all(np.abs(per_cam - 1) < 0.35)


def test_zero_noise_gives_zero_error(small):
    s, _, _ = small
    R, t, _, _ = NS.ba_from_truth(s, s.x_true)
    rot, cen = pose_errors(R, t, s.R, s.t)
    assert rot.max() < 1e-6 and cen.max() < 1e-9


def test_errors_grow_linearly_with_sigma(small):
    """One noise draw scaled by σ: the ML errors are linear in σ (log–log slope 1) while σ is small."""
    s, _, _ = small
    eps, _ = NS.noisy_observations(s.x_true, 1.0, rng=np.random.default_rng(3))
    eps -= s.x_true
    sigmas = np.array([0.25, 1.0, 4.0])
    rot, cen = [], []
    for sigma in sigmas:
        R, t, _, _ = NS.ba_from_truth(s, s.x_true + sigma * eps)
        r, c = NS.rms_errors(*pose_errors(R, t, s.R, s.t))
        rot.append(r)
        cen.append(c)
    assert abs(NS.loglog_slope(sigmas, rot) - 1) < 0.1 and abs(NS.loglog_slope(sigmas, cen) - 1) < 0.1


def test_robust_steps_resist_outliers(small):
    """20 % outliers: plain least squares is dragged far off; a Cauchy loss then rejection at 5 px
    removes every outlier (and almost no inlier) and lands within 2x the all-inlier bound (one trial
    of ~17 effective terms has a relative sd of ~17 %, and 20 % fewer observations cost ~25 %)."""
    s, ci, pi = small
    pred = U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, 1.0)
    x_meas, out = NS.noisy_observations(s.x_true, 1.0, rng=np.random.default_rng(4), outlier_ratio=0.2,
                                       image_size=s.image_size)
    assert 0.1 < out.sum() / s.visible.sum() < 0.3
    plain = NS.rms_errors(*pose_errors(*NS.ba_from_truth(s, x_meas)[:2], s.R, s.t))[0]
    R, t, _, info = NS.ba_from_truth(s, x_meas, loss="cauchy", f_scale=2.0, threshold_px=5.0)
    robust = NS.rms_errors(*pose_errors(R, t, s.R, s.t))[0]
    is_out = out[ci, pi]
    assert plain > 10 * pred.rot_rms_deg_all
    assert not np.any(info["kept"] & is_out) and np.sum(~info["kept"] & ~is_out) < 0.05 * np.sum(~is_out)
    assert robust < 2 * pred.rot_rms_deg_all


def test_run_noise_study(small):
    s, ci, pi = small

    def reconstruct(scene, x_meas, sigma, rng):
        R, t, _, _ = NS.ba_from_truth(scene, x_meas)
        R[5], t[5] = np.nan, np.nan                       # a view the pipeline failed to register
        return R, t

    def fragile(scene, x_meas, sigma, rng):
        if sigma > 0.5:
            raise ValueError("no initial pair")
        return scene.R, scene.t

    both = NS.run_noise_study(s, {"ba": reconstruct, "fragile": fragile}, [0.0, 1.0], {0.0: 1, 1.0: 3},
                              rng=np.random.default_rng(5))
    study = both["ba"]
    assert study.rot_deg[1.0].shape == (3, len(s.R)) and len(study.estimates[1.0]) == 3
    assert np.all(np.isnan(study.rot_deg[1.0][:, 5])) and np.all(np.isfinite(np.delete(study.rot_deg[1.0], 5, 1)))
    assert study.rms("rot")[0] < 1e-6 and study.rms("rot")[1] > 0 and study.n_ok(1.0) == 3
    assert both["fragile"].n_ok(0.0) == 1 and both["fragile"].n_ok(1.0) == 0
    assert len(both["fragile"].failures[1.0]) == 3 and np.isnan(both["fragile"].rms("rot")[1])
    pred = U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, 1.0)
    assert "ratio" in study.table(pred) and "every trial failed" in both["fragile"].table(pred)
    # a trial far beyond the bound is flagged as a wrong basin, the others are kept
    assert study.flag_wrong_basins(pred) == 0 and study.n_ok(1.0) == 3
    study.rot_deg[1.0][1, :3] = 30.0
    assert study.flag_wrong_basins(pred) == 1 and study.n_ok(1.0) == 2 and "wrong basin" in study.failures[1.0][-1]
    with pytest.raises(ValueError, match="at least one trial"):
        NS.run_noise_study(s, reconstruct, [1.0], 0, rng=np.random.default_rng(5))
    with pytest.raises(ValueError, match="pipelines"):
        NS.run_noise_study(s, {}, [1.0], 1, rng=np.random.default_rng(5))


def test_dino_prediction(dino):
    ci, pi, _ = observations(dino.x_true)
    p = U.predict_pose_errors(dino.R, dino.t, dino.X, ci, pi, dino.K, 1.0)
    assert p.cov.shape == (6 * 36, 6 * 36) and np.all(np.isfinite(p.cov))
    assert np.all(np.linalg.eigvalsh(p.cov) > -1e-12 * np.abs(p.cov).max())
    # an aligned covariance has the 7 aligned directions removed: rank 6V - 7
    w = np.linalg.eigvalsh(p.cov)
    assert np.sum(w < 1e-9 * w[-1]) == 7


def test_bad_input(small):
    s, ci, pi = small
    with pytest.raises(ValueError, match=r"R must have shape \(V, 3, 3\)"):
        U.predict_pose_errors(s.R[:, :2], s.t, s.X, ci, pi, s.K)
    with pytest.raises(ValueError, match="t must have shape"):
        U.predict_pose_errors(s.R, s.t[:-1], s.X, ci, pi, s.K)
    with pytest.raises(ValueError, match="at least 3 cameras"):
        U.alignment_map(s.R[:2], s.t[:2])
    with pytest.raises(ValueError, match="collinear"):
        U.alignment_map(np.stack([np.eye(3)] * 4), np.outer(np.arange(4.0), [1.0, 0, 0]))
    with pytest.raises(ValueError, match="rotation"):
        U.gauge_basis(2 * s.R, s.t, s.X)
    with pytest.raises(ValueError, match="finite"):
        U.predict_pose_errors(s.R, np.where(np.arange(3) == 0, np.nan, s.t), s.X, ci, pi, s.K)
    with pytest.raises(ValueError, match="out of range"):
        U.predict_pose_errors(s.R, s.t, s.X, ci, pi + 1, s.K)
    with pytest.raises(ValueError, match="sigma"):
        U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, sigma=-1.0)
    with pytest.raises(ValueError, match="method"):
        U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, method="qr")
    with pytest.raises(ValueError, match="jacobian must have shape"):
        U.predict_pose_errors(s.R, s.t, s.X, ci, pi, s.K, jacobian=np.zeros((3, 3)))
    # a point seen by one view only is not determined
    once = np.flatnonzero(pi == pi[0])[1:]
    keep = np.setdiff1d(np.arange(ci.size), once)
    with pytest.raises(ValueError, match="not determined"):
        U.predict_pose_errors(s.R, s.t, s.X, ci[keep], pi[keep], s.K)
    with pytest.raises(ValueError, match="rng"):
        NS.noisy_observations(s.x_true, 1.0, rng=0)
    with pytest.raises(ValueError, match="outlier_ratio"):
        NS.noisy_observations(s.x_true, 1.0, rng=np.random.default_rng(0), outlier_ratio=1.5)
    with pytest.raises(ValueError, match="image_size"):
        NS.noisy_observations(s.x_true, 1.0, rng=np.random.default_rng(0), outlier_ratio=0.1)
    with pytest.raises(ValueError, match="positive"):
        NS.loglog_slope([0.0, 1.0], [1.0, 2.0])
    with pytest.raises(ValueError, match="NaN error"):            # was a NaN slope, printed as a value
        NS.loglog_slope([1.0, 2.0, 4.0], [1.0, np.nan, 4.0])
    with pytest.raises(ValueError, match="same length"):
        NS.loglog_slope([1.0, 2.0, 4.0], [[1.0, 2.0, 4.0]])


def test_common_noise_scales_one_pattern(small):
    """With common random numbers the ML errors of one pattern scale with σ: the slope is ~1 per trial."""
    s, _, _ = small

    def ml(scene, x_meas, sigma, rng):
        return NS.ba_from_truth(scene, x_meas)[:2]

    st = NS.run_noise_study(s, ml, [0.25, 1.0, 4.0], 2, rng=np.random.default_rng(6), common_noise=True)
    per_trial = st.trial_rms("rot")                        # (levels, trials)
    assert per_trial.shape == (3, 2)
    assert np.allclose(per_trial / per_trial[1], np.array([0.25, 1.0, 4.0])[:, None], rtol=0.05)
    assert abs(NS.loglog_slope(st.sigmas, st.rms("centre")) - 1) < 0.05


def test_sfm_reaches_the_ml_optimum_and_beats_no_ba(small):
    """The full pipeline on σ = 0.5 px lands where BA from the truth does; without BA it drifts; σ = 0 is exact."""
    from labutils.sfm.incremental import incremental_sfm

    s, _, _ = small
    rng = np.random.default_rng(7)
    for sigma in (0.0, 0.5):
        x_meas, _ = NS.noisy_observations(s.x_true, sigma, rng=rng)
        rec = incremental_sfm(x_meas, s.K, rng=rng, threshold_px=10.0, init_min_angle_deg=1.0, loss="linear")
        R, t = NS.refine_reconstruction(rec, x_meas, s.K)
        rot, _ = pose_errors(R, t, s.R, s.t)
        if sigma == 0:
            assert rot.max() < 1e-6
            continue
        rot_ml, _ = pose_errors(*NS.ba_from_truth(s, x_meas)[:2], s.R, s.t)
        assert np.allclose(rot, rot_ml, rtol=0.02, atol=1e-3 * rot_ml.max())
        R0, t0, X0 = NS.reconstruct_without_ba(x_meas, s.K, rec.order, rng=rng)
        ok = np.isfinite(t0[:, 0])
        assert ok.sum() >= 3 and X0.shape == (s.n_points, 3)
        assert NS.rms_errors(*pose_errors(R0[ok], t0[ok], s.R[ok], s.t[ok]))[0] > 2 * NS.rms_errors(rot, rot)[0]
    with pytest.raises(ValueError, match="order"):
        NS.reconstruct_without_ba(x_meas, s.K, [0, 0, 1], rng=rng)
