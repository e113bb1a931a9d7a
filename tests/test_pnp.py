import cv2
import numpy as np
import pytest

from labutils.core.geometry import angle_axis_from_rotation, rotation_from_angle_axis
from labutils.core.metrics import ml_residual_bound, rotation_error_deg
from labutils.core.ransac import ransac_iterations
from labutils.core.synthetic import make_scene
from labutils.pose.pnp import (
    bearings,
    p3p,
    p3p_bearings,
    pnp_ransac,
    pose_jacobian,
    pose_residuals,
    refine_pose,
    reprojection_errors,
)

K_SKEW = np.array([[900.0, -25.0, 330.0], [0.0, 850.0, 250.0], [0.0, 0.0, 1.0]])


def random_p3p(rng, K=K_SKEW):
    """Three points in front of a random camera, and their exact pixels."""
    R = rotation_from_angle_axis(rng.normal(size=3))
    t = rng.normal(size=3)
    X_cam = np.c_[rng.uniform(-1, 1, (3, 2)), rng.uniform(2, 8, 3)]
    X = (X_cam - t) @ R                      # R.T @ (X_cam - t), as rows
    x = X_cam @ K.T
    return X, x[:, :2] / x[:, 2:], R, t


def pose_distance(R1, t1, R2, t2):
    return max(np.abs(R1 - R2).max(), np.abs(t1 - t2).max() / max(1.0, np.abs(t2).max()))


def pnp_problem(rng, n=120, noise_px=0.5, outlier_ratio=0.3, K=K_SKEW, size=(640, 480)):
    """N world points seen by one camera, with noise and an exact fraction of uniform outliers."""
    R = rotation_from_angle_axis(rng.normal(size=3))
    t = np.array([0.1, -0.2, 5.0])
    X = rng.uniform([-1.5, -1.2, -1], [1.5, 1.2, 1], (n, 3)) @ R          # camera frame: the box + t
    x = (X @ R.T + t) @ K.T
    x = x[:, :2] / x[:, 2:] + rng.normal(scale=noise_px, size=(n, 2))
    out = np.zeros(n, bool)
    out[rng.choice(n, int(round(outlier_ratio * n)), replace=False)] = True
    x[out] = rng.uniform([0, 0], size, size=(out.sum(), 2))
    return X, x, R, t, out


# ---------------------------------------------------------------- P3P

def test_p3p_finds_true_pose_and_every_solution_reprojects(rng):
    counts = np.zeros(5, int)
    for _ in range(300):
        X, x, R, t = random_p3p(rng)
        sols = p3p(X, x, K_SKEW)
        counts[len(sols)] += 1
        assert min(pose_distance(Ri, ti, R, t) for Ri, ti in sols) < 1e-9
        for Ri, ti in sols:
            assert np.allclose(Ri @ Ri.T, np.eye(3), atol=1e-12) and np.linalg.det(Ri) > 0
            assert reprojection_errors(X, x, K_SKEW, Ri, ti).max() < 1e-8       # exact, and in front
    assert counts[0] == 0 and counts[2:].sum() > 0                              # several solutions do occur


def test_p3p_bearings_matches_pixel_version(rng):
    X, x, R, t = random_p3p(rng)
    a, b = p3p(X, x, K_SKEW), p3p_bearings(X, 3.0 * bearings(x, K_SKEW))     # rays of any length
    assert len(a) == len(b) and all(pose_distance(*p, *q) < 1e-12 for p, q in zip(a, b))


def test_p3p_same_solutions_as_opencv(rng):
    K = np.array([[800.0, 0.0, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])   # OpenCV ignores skew
    n_cv = 0
    for _ in range(100):
        X, x, R, t = random_p3p(rng, K)
        ours = p3p(X, x, K)
        for flag in (cv2.SOLVEPNP_P3P, cv2.SOLVEPNP_AP3P):
            _, rvecs, tvecs = cv2.solveP3P(X, x, K, None, flags=flag)
            for rv, tv in zip(rvecs, tvecs):
                Rc, tc = cv2.Rodrigues(rv)[0], tv.ravel()
                if reprojection_errors(X, x, K, Rc, tc).max() > 1e-4:
                    continue                                   # not a solution (OpenCV may return those)
                n_cv += 1
                assert min(pose_distance(Ro, to, Rc, tc) for Ro, to in ours) < 1e-6
    assert n_cv > 150


def test_p3p_keeps_only_points_in_front(rng):
    X, x, R, t = random_p3p(rng)
    X_behind = (-(X @ R.T + t) - t) @ R       # every point mirrored through the centre: same rays, negative depth
    for Ri, ti in p3p(X_behind, x, K_SKEW):
        assert np.all(X_behind @ Ri.T[:, 2] + ti[2] > 0)
        assert pose_distance(Ri, ti, R, t) > 1e-3


def test_p3p_bad_input(rng):
    X, x, R, t = random_p3p(rng)
    with pytest.raises(ValueError, match="exactly 3"):
        p3p(np.vstack([X, X[:1] + 1]), np.vstack([x, x[:1]]), K_SKEW)
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        p3p(X, np.c_[x, x[:, :1]], K_SKEW)
    with pytest.raises(ValueError, match="row by row"):
        p3p(X, x[:2], K_SKEW)
    with pytest.raises(ValueError, match="non-finite"):
        p3p(X, np.where([[True, True], [False, True], [True, True]], x, np.nan), K_SKEW)
    with pytest.raises(ValueError, match="collinear"):
        p3p(np.array([[0, 0, 5.0], [1, 1, 6], [2, 2, 7]]), x, K_SKEW)
    with pytest.raises(ValueError, match="singular"):
        p3p(X, x, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="zero-length"):
        p3p_bearings(X, [[0, 0, 1.0], [0, 0, 0], [0, 1, 1]])


# ---------------------------------------------------------------- refinement

def test_pose_jacobian_matches_finite_differences(rng):
    X, x, R, t, _ = pnp_problem(rng, n=15, outlier_ratio=0.0)
    params = np.r_[rng.normal(scale=0.3, size=3), t + rng.normal(scale=0.1, size=3)]   # away from w = 0
    J = pose_jacobian(params, X, x, K_SKEW, R)
    h = 1e-6
    J_fd = np.column_stack([(pose_residuals(params + h * e, X, x, K_SKEW, R)
                             - pose_residuals(params - h * e, X, x, K_SKEW, R)) / (2 * h) for e in np.eye(6)])
    assert J.shape == (30, 6)
    assert np.abs(J - J_fd).max() < 1e-5 * np.abs(J_fd).max()
    J0 = pose_jacobian(np.r_[np.zeros(3), t], X, x, K_SKEW, R)                          # and at w = 0
    J0_fd = np.column_stack([(pose_residuals(np.r_[np.zeros(3), t] + h * e, X, x, K_SKEW, R)
                              - pose_residuals(np.r_[np.zeros(3), t] - h * e, X, x, K_SKEW, R)) / (2 * h)
                             for e in np.eye(6)])
    assert np.abs(J0 - J0_fd).max() < 1e-5 * np.abs(J0_fd).max()


def test_refine_pose_recovers_truth_noise_free(rng):
    X, x, R, t, _ = pnp_problem(rng, n=30, noise_px=0.0, outlier_ratio=0.0)
    R0 = rotation_from_angle_axis([0.05, -0.03, 0.04]) @ R
    R1, t1 = refine_pose(X, x, K_SKEW, R0, t + [0.05, 0.02, -0.1])
    assert rotation_error_deg(R1, R) < 1e-8 and np.abs(t1 - t).max() < 1e-9
    R2, t2 = refine_pose(X, x, K_SKEW, R0, t, loss="huber", f_scale=2.0)
    assert rotation_error_deg(R2, R) < 1e-6 and np.abs(t2 - t).max() < 1e-7


def test_refine_pose_bad_input(rng):
    X, x, R, t, _ = pnp_problem(rng, n=10, outlier_ratio=0.0)
    with pytest.raises(ValueError, match="at least 3"):
        refine_pose(X[:2], x[:2], K_SKEW, R, t)
    with pytest.raises(ValueError, match="collinear"):
        refine_pose(np.outer(np.arange(5), [0.1, 0.2, 0.3]) + [0, 0, 5], x[:5], K_SKEW, np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="behind"):
        refine_pose(X, x, K_SKEW, R, -t)
    with pytest.raises(ValueError, match="loss"):
        refine_pose(X, x, K_SKEW, R, t, loss="l1")
    with pytest.raises(ValueError, match="non-finite"):
        refine_pose(X, x, K_SKEW, R, [0, np.nan, 5])


# ---------------------------------------------------------------- RANSAC

def test_pnp_ransac_noise_free_is_exact(rng):
    X, x, R, t, out = pnp_problem(rng, noise_px=0.0, outlier_ratio=0.4)
    res = pnp_ransac(X, x, K_SKEW, rng=rng)
    R1, t1, inl = res.R, res.t, res.inliers
    assert pose_distance(R1, t1, R, t) < 1e-9
    assert np.array_equal(inl, ~out)
    assert res.n_iter <= ransac_iterations(0.6, 3, 0.9999) + 1          # the adaptive stop


def test_pnp_ransac_inliers_and_error_band_tied_to_noise():
    """Over many trials the pose error, weighted by the predicted covariance σ²(JᵀJ)⁻¹, is χ²(6): mean 6."""
    rng = np.random.default_rng(7)
    sigma, d2, res2, n_res, recall, precision = 0.5, [], 0.0, 0, [], []
    for _ in range(40):
        X, x, R, t, out = pnp_problem(rng, n=100, noise_px=sigma, outlier_ratio=0.3)
        _res = pnp_ransac(X, x, K_SKEW, threshold_px=2.0, rng=rng)
        R1, t1, inl = _res.R, _res.t, _res.inliers
        recall.append((inl & ~out).sum() / (~out).sum())
        precision.append((inl & ~out).sum() / inl.sum())
        delta = np.r_[angle_axis_from_rotation(R1 @ R.T), t1 - t]                # in the (w, t) parameters
        J = pose_jacobian(np.r_[np.zeros(3), t], X[~out], x[~out], K_SKEW, R)
        d2.append(delta @ (J.T @ J) @ delta / sigma ** 2)
        r = reprojection_errors(X[inl], x[inl], K_SKEW, R1, t1)
        res2, n_res = res2 + (r ** 2).sum(), n_res + 2 * inl.sum()
    assert np.mean(recall) > 0.995 and min(recall) >= 0.97 and min(precision) == 1.0
    assert 4.0 < np.mean(d2) < 8.5                   # χ²(6) mean 6; sd of a 40-trial mean ≈ 0.55
    rms = np.sqrt(res2 / n_res)
    bound = ml_residual_bound(sigma, n_res, 6 * 40)
    assert abs(rms / bound - 1) < 0.05               # the residual at the optimum matches the noise


def test_pnp_ransac_agrees_with_opencv_on_its_inliers(rng):
    K = np.array([[800.0, 0.0, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])
    X, x, R, t, out = pnp_problem(rng, n=150, K=K)
    _res = pnp_ransac(X, x, K, rng=rng)
    R1, t1, inl = _res.R, _res.t, _res.inliers
    ok, rv, tv = cv2.solvePnP(X[inl], x[inl], K, None, flags=cv2.SOLVEPNP_ITERATIVE)
    assert ok and pose_distance(R1, t1, cv2.Rodrigues(rv)[0], tv.ravel()) < 1e-6   # same least-squares optimum


def test_pnp_ransac_bad_input(rng):
    X, x, R, t, out = pnp_problem(rng, n=20)
    with pytest.raises(ValueError, match="at least 4"):
        pnp_ransac(X[:3], x[:3], K_SKEW, rng=rng)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        pnp_ransac(X[:, :2], x, K_SKEW, rng=rng)
    with pytest.raises(ValueError, match="row by row"):
        pnp_ransac(X, x[:10], K_SKEW, rng=rng)
    with pytest.raises(ValueError, match="non-finite"):
        pnp_ransac(X, np.where(np.arange(20)[:, None] == 3, np.nan, x), K_SKEW, rng=rng)
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        pnp_ransac(X, x, K_SKEW[:2], rng=rng)
    with pytest.raises(ValueError, match="collinear"):
        pnp_ransac(np.outer(np.arange(20), [0.1, 0.2, 0.3]) + [0, 0, 5], x, K_SKEW, rng=rng)
    with pytest.raises(ValueError, match="rng"):
        pnp_ransac(X, x, K_SKEW, rng=None)
    with pytest.raises(ValueError, match="threshold"):
        pnp_ransac(X, x, K_SKEW, threshold_px=0.0, rng=rng)
    with pytest.raises(ValueError, match="no better than chance"):
        pnp_ransac(X[:6], rng.uniform(0, 640, (6, 2)), K_SKEW, rng=rng)        # nothing but outliers


def test_pnp_ransac_on_synthetic_turntable(rng):
    s = make_scene(300, 8, layout="turntable", noise_px=0.5, outlier_ratio=0.3, rng=rng)
    for i in range(s.n_views):
        vis = s.visible[i]
        _res = pnp_ransac(s.X[vis], s.x_meas[i, vis], s.K, rng=rng)
        inl = _res.inliers
        good = ~s.outliers[i, vis]
        assert (inl & good).sum() / good.sum() >= 0.97 and (inl & ~good).sum() <= 1
        assert rotation_error_deg(_res.R, s.R[i]) < 0.5


def test_pnp_ransac_on_dino(dino, rng):
    for i in (0, 12, 24):
        vis = dino.visible[i]
        X, x = dino.X[vis], dino.x_true[i, vis] + rng.normal(scale=0.5, size=(vis.sum(), 2))
        out = np.zeros(len(X), bool)
        out[rng.choice(len(X), int(round(0.3 * len(X))), replace=False)] = True
        x[out] = rng.uniform([0, 0], dino.image_size, size=(out.sum(), 2))
        _res = pnp_ransac(X, x, dino.K, rng=rng)
        R1, t1, inl = _res.R, _res.t, _res.inliers
        assert (inl & ~out).sum() / (~out).sum() >= 0.97 and not (inl & out).any()
        delta = np.r_[angle_axis_from_rotation(R1 @ dino.R[i].T), t1 - dino.t[i]]
        J = pose_jacobian(np.r_[np.zeros(3), dino.t[i]], X[~out], x[~out], dino.K, dino.R[i])
        assert delta @ (J.T @ J) @ delta / 0.5 ** 2 < 27.9        # χ²(6) 99.999 % quantile


def test_pnp_ransac_skips_collinear_samples_and_points_behind(rng):
    R = rotation_from_angle_axis([0.2, -0.1, 0.3])
    t = np.array([0.0, 0.0, 5.0])
    line = np.outer(np.linspace(-1, 1, 25), [1.0, 0.5, 0.2])          # most points on one line:
    X_cam = np.vstack([line, rng.uniform(-1, 1, (6, 3))]) + t          # most samples are collinear
    X = (X_cam - t) @ R
    x = X_cam @ K_SKEW.T
    x = x[:, :2] / x[:, 2:]
    res = pnp_ransac(X, x, K_SKEW, rng=rng)
    R1, t1, inl = res.R, res.t, res.inliers
    assert pose_distance(R1, t1, R, t) < 1e-9 and inl.all()
    # points mirrored through the camera centre have the same pixels but lie behind it: outliers
    behind = np.zeros(len(X), bool)
    behind[[3, 10, 27]] = True
    X_b = X.copy()
    X_b[behind] = (-(X_cam[behind] - t) - 2 * t) @ R                  # camera frame: -X_cam
    _res = pnp_ransac(X_b, x, K_SKEW, rng=rng)
    R2, t2, inl2 = _res.R, _res.t, _res.inliers
    assert pose_distance(R2, t2, R, t) < 1e-9 and np.array_equal(inl2, ~behind)
    assert np.all(np.isinf(reprojection_errors(X_b[behind], x[behind], K_SKEW, R, t)))


# ---------------------------------------------------------------- degenerate data, pure noise, chance (issue 21)

def test_coincident_pixels_are_refused(rng):
    X, x, R, t, out = pnp_problem(rng, n=40)
    with pytest.raises(ValueError, match="coincide"):
        pnp_ransac(X, np.tile(x[:1], (40, 1)), K_SKEW, rng=rng)       # was 40/40 inliers with t ≈ 1e16
    with pytest.raises(ValueError, match="coincide"):
        pnp_ransac(X, x[:1] + rng.uniform(-0.5, 0.5, (40, 2)), K_SKEW, rng=rng)   # within the 2 px threshold
    with pytest.raises(ValueError, match="coincide"):
        p3p(X[:3], np.tile(x[:1], (3, 1)), K_SKEW)                     # was two "solutions"


@pytest.mark.parametrize("n", [12, 40, 200])
def test_pnp_ransac_refuses_pure_noise(n):
    """Pixels unrelated to the points: the bound on the chance of an inlier, π τ² / (w h), is exact here (uniform
    pixels in their box), and the best of the poses tried keeps close to the binomial mean: p_chance ≈ 1 (the
    smallest of 80 such runs at τ = 1-12 px was 0.30), far above the 0.05 bar."""
    for seed, thr in enumerate((2.0, 8.0)):
        rng = np.random.default_rng(seed)
        X, _, _, _, _ = pnp_problem(rng, n=n)
        with pytest.raises(ValueError, match="no better than chance"):
            pnp_ransac(X, rng.uniform([0, 0], [640, 480], (n, 2)), K_SKEW, rng=rng, threshold_px=thr, max_iter=300)


def test_pnp_ransac_does_not_refuse_valid_problems():
    """No false refusal at 0.3-4 px of noise and 0-50 % outliers, threshold 3σ (at least 2 px). With N = 40 and
    half outliers, ~19 of the 20 inliers pass 3σ; the pixels span ≥ 300 × 250 px, so an unrelated pixel is an
    inlier with p ≤ π 12² / 75000 ≈ 6e-3 and p_chance ≤ 4 · 70 · C(37, 16) p¹⁶ ≈ 1e-23 (70 samples for 0.9999 at
    half inliers, ≤ 4 poses each); it is far smaller at lower noise. Asserted: below 1e-12."""
    worst = 0.0
    for seed in range(2):
        for sigma in (0.3, 1.0, 4.0):
            for ratio in (0.0, 0.3, 0.5):
                rng = np.random.default_rng(100 * seed + int(10 * sigma) + int(10 * ratio))
                X, x, R, t, out = pnp_problem(rng, n=40, noise_px=sigma, outlier_ratio=ratio)
                res = pnp_ransac(X, x, K_SKEW, rng=rng, threshold_px=max(2.0, 3 * sigma))
                assert res.converged and (res.inliers & ~out).sum() >= 0.9 * (~out).sum()
                worst = max(worst, res.p_chance)
    assert worst < 1e-12
