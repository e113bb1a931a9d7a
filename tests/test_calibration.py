"""Calibration (labutils.calibrate.camera, chessboard, rectification, calibrate): shapes and bad input, invariants,
the Jacobian against finite differences, recovery of synthetic truth, OpenCV side by side, the real chessboard
views, and the command line."""
import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.optimize import least_squares

from labutils.calibrate.camera import (
    CalibrationProblem,
    _intrinsic_map,
    calibrate_camera,
    calibrate_stereo,
    view_influence,
)
from labutils.calibrate.chessboard import (
    board_points,
    detect_corners,
    grid_line_residuals,
    load_chessboard,
    render_board,
    render_board_views,
    synthetic_board_views,
)
from labutils.calibrate.cli import main
from labutils.calibrate.lens import distort, project_points, undistort_normalised, undistort_points
from labutils.calibrate.rectification import (
    rectify_fusiello,
    rectify_image,
    rectify_points,
    remap_grid,
    undistort_image,
)
from labutils.calibrate.zhang import board_homography, intrinsics_from_homographies, pose_from_homography
from labutils.core.cli import write_all_atomically as write_atomically
from labutils.core.geometry import rotation_from_angle_axis
from labutils.core.lm import levenberg_marquardt
from labutils.core.metrics import ml_residual_bound
from labutils.data.formats import read_calibration
from labutils.data.paths import DataNotFoundError

ROOT = Path(__file__).resolve().parents[1]


def k_vector(K):
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])


def k_error(K_est, K_true):
    """Largest error of (fx, fy, cx, cy) as a fraction of the true focal length."""
    return float(np.abs(k_vector(K_est) - k_vector(K_true)).max() / K_true[0, 0])


@pytest.fixture(scope="module")
def left():
    try:
        return load_chessboard("left")
    except DataNotFoundError as exc:
        pytest.skip(f"real data missing: {str(exc).splitlines()[0]}")


@pytest.fixture(scope="module")
def right():
    try:
        return load_chessboard("right")
    except DataNotFoundError as exc:
        pytest.skip(f"real data missing: {str(exc).splitlines()[0]}")


@pytest.fixture(scope="module")
def rendered():
    """16 rendered views of the 9x6 board (known K, distortion, poses) and their detected corners."""
    rng = np.random.default_rng(2024)
    views = synthetic_board_views(rng=rng, n_views=16, noise_px=0.0, distance=(0.22, 0.35), max_tilt_deg=60)
    images = render_board_views(views, noise=2.0, rng=rng)
    return views, images, [detect_corners(img) for img in images]


# --- shapes and bad input ----------------------------------------------------------------------------------------

def test_project_points_refuses_a_column_t():
    """A (3, 1) t (OpenCV's tvec) is refused by name, not flattened: the house rule is never to reshape silently."""
    with pytest.raises(ValueError, match=r"t must have shape \(3,\)"):
        project_points([[0.0, 0.0, 2.0]], np.diag([500.0, 500, 1]), np.zeros(5), np.eye(3), np.zeros((3, 1)))


def test_distort_rejects_bad_input():
    with pytest.raises(ValueError, match=r"xn must have shape \(N, 2\)"):
        distort(np.zeros((3, 3)), np.zeros(5))
    with pytest.raises(ValueError, match="dist must hold 5 numbers"):
        distort(np.zeros((3, 2)), np.zeros(3))
    with pytest.raises(ValueError, match="non-finite"):
        distort(np.zeros((3, 2)), [np.nan, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="non-finite"):
        distort([[np.inf, 0.0]], np.zeros(5))


def test_undistort_refuses_points_beyond_the_fold():
    dist = [-0.5, 0, 0, 0, 0]                      # r_d = r - 0.5 r³ peaks at r_d = 0.544 (r = 0.816)
    assert np.allclose(distort(undistort_normalised([[0.5, 0.0]], dist), dist), [[0.5, 0.0]], atol=1e-12)
    with pytest.raises(ValueError, match="not invertible"):
        undistort_normalised([[0.6, 0.0]], dist)       # nothing maps there: no silent NaN


def test_project_points_rejects_points_behind_and_skew():
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    with pytest.raises(ValueError, match="not in front"):
        project_points([[0, 0, -1.0]], K, np.zeros(5), np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="zero skew"):
        project_points([[0, 0, 1.0]], K + [[0, 1, 0], [0, 0, 0], [0, 0, 0]], np.zeros(5), np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="R is not a rotation matrix"):          # it returned pixels
        project_points([[0, 0, 1.0]], K, np.zeros(5), 2 * np.eye(3), np.zeros(3))


def test_chessboard_functions_reject_bad_input():
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    x = board_points((4, 3), 10.0)[:, :2] + 5
    x[5, 0] = np.nan
    with pytest.raises(ValueError, match=r"x has non-finite coordinates \(NaN or inf\) in rows \[5\]"):
        grid_line_residuals(x, (4, 3))                                           # was numpy's LinAlgError
    with pytest.raises(ValueError, match="R is not a rotation matrix"):          # it drew an image
        render_board(K, np.zeros(5), 2 * np.eye(3), [0, 0, 0.5], image_size=(64, 48))
    for bad in [(640,), (640.5, 480), (640, 0)]:
        with pytest.raises(ValueError, match="image_size"):
            render_board(K, np.zeros(5), np.eye(3), [0, 0, 0.5], image_size=bad)
        with pytest.raises(ValueError, match="image_size"):
            synthetic_board_views(n_views=1, rng=np.random.default_rng(0), image_size=bad)


def test_board_homography_and_zhang_reject_bad_input():
    X = board_points((3, 3), 1.0)
    with pytest.raises(ValueError, match="plane Z = 0"):
        board_homography(X + [0, 0, 0.5], X[:, :2])
    with pytest.raises(ValueError, match="at least 3 views"):
        intrinsics_from_homographies(np.stack([np.eye(3)] * 2))
    with pytest.raises(ValueError, match=r"shape \(V, 3, 3\)"):
        intrinsics_from_homographies(np.eye(3))
    # boards that only translate (all parallel to the image): B is not determined
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    Hs = np.stack([K @ np.column_stack([[1.0, 0, 0], [0, 1.0, 0], [0.1 * k, 0.05 * k, 1 + 0.1 * k]]) for k in range(4)])
    with pytest.raises(ValueError, match="do not determine K"):
        intrinsics_from_homographies(Hs)


def test_calibrate_camera_rejects_bad_input():
    v = synthetic_board_views(rng=np.random.default_rng(0), n_views=3, noise_px=0.0)
    with pytest.raises(ValueError, match="at least 3 are needed"):
        calibrate_camera([v.X] * 2, v.x[:2], v.image_size)
    with pytest.raises(ValueError, match="object_points has 3 views but image_points has 2"):
        calibrate_camera([v.X] * 3, v.x[:2], v.image_size)
    bad = [x.copy() for x in v.x]
    bad[1][5] = np.nan
    with pytest.raises(ValueError, match=r"image_points\[1\] has non-finite"):
        calibrate_camera([v.X] * 3, bad, v.image_size)
    with pytest.raises(ValueError, match=r"image_points\[0\] has 53 points"):
        calibrate_camera([v.X] * 3, [v.x[0][:-1]] + v.x[1:], v.image_size)
    with pytest.raises(ValueError, match="image_size"):
        calibrate_camera([v.X] * 3, v.x, (640,))
    with pytest.raises(ValueError, match="image_size must be an integer >= 1; got 640.5"):
        calibrate_camera([v.X] * 3, v.x, (640.5, 480))          # was truncated to 640 without a word


@pytest.mark.parametrize("kwargs, words", [
    ({"image_size": (640.5, 480)}, "image_size must be an integer"),
    ({"image_size": (640, 0)}, "image_size must be an integer >= 1; got 0"),
    ({"image_size": (480, 640, 3)}, r"image_size must be \(width, height\)"),
    ({"image_size": (640, 480), "out_size": (320.5, 240)}, "out_size must be an integer"),
])
def test_remap_grid_refuses_a_bad_size(kwargs, words):
    with pytest.raises(ValueError, match=words):
        remap_grid(np.diag([500.0, 500.0, 1.0]), np.zeros(5), **kwargs)


def test_detect_corners_bad_input_and_missing_board():
    assert detect_corners(np.full((480, 640), 128, np.uint8)) is None
    with pytest.raises(ValueError, match="uint8"):
        detect_corners(np.zeros((480, 640)))
    with pytest.raises(ValueError, match="board must"):
        detect_corners(np.zeros((48, 64), np.uint8), board=(9,))


def test_rectify_rejects_degenerate_pairs():
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    with pytest.raises(ValueError, match="no baseline"):
        rectify_fusiello(K, K, np.eye(3), np.zeros(3))
    with pytest.raises(ValueError, match="forward motion"):
        rectify_fusiello(K, K, np.eye(3), [0, 0, -0.2])


# --- invariants and Jacobians ------------------------------------------------------------------------------------

def test_distort_jacobians_match_finite_differences(rng):
    xn = rng.uniform(-0.6, 0.6, (20, 2))
    dist = np.array([-0.27, 0.09, 0.0015, -0.0009, 0.05])
    _, d_xn, d_dist = distort(xn, dist, jac=True)
    h = 1e-7
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        fd = (distort(xn + e, dist) - distort(xn - e, dist)) / (2 * h)
        assert np.abs(fd - d_xn[:, :, k]).max() < 1e-7
    for k in range(5):
        e = np.zeros(5)
        e[k] = h
        fd = (distort(xn, dist + e) - distort(xn, dist - e)) / (2 * h)
        assert np.abs(fd - d_dist[:, :, k]).max() < 1e-7


def test_undistort_round_trip(rng):
    K = np.array([[536.0, 0, 342], [0, 536, 235], [0, 0, 1]])
    dist = [-0.2654, -0.0453, 0.0018, -0.0003, 0.2505]            # OpenCV's sample camera
    x = rng.uniform([0, 0], [640, 480], (200, 2))
    u = undistort_points(x, K, dist)
    xd = distort((u - K[:2, 2]) / [K[0, 0], K[1, 1]], dist) * [K[0, 0], K[1, 1]] + K[:2, 2]
    assert np.abs(xd - x).max() < 1e-9
    # and OpenCV's undistortPoints agrees (its fixed-point iteration stops earlier: 1e-3 px)
    u_cv = cv2.undistortPoints(x.reshape(-1, 1, 2), K, np.asarray(dist), P=K).reshape(-1, 2)
    assert np.abs(u_cv - u).max() < 1e-2


def _problem(rng, n_cams=1, free=True):
    v = synthetic_board_views(rng=rng, n_views=3, noise_px=0.3)
    X = np.vstack([v.X] * 3 * n_cams)
    x = np.vstack(v.x * n_cams)
    view = np.tile(np.repeat(np.arange(3), len(v.X)), n_cams)
    cam = np.repeat(np.arange(n_cams), 3 * len(v.X))
    theta0 = np.r_[k_vector(v.K), v.dist]
    A = [(_intrinsic_map(theta0, c == 1, False, False, False, False)[0] if free else np.zeros((9, 0)))
         for c in range(n_cams)]
    prob = CalibrationProblem(X, x, cam, view, np.stack([theta0] * n_cams), A)
    rig = ([rotation_from_angle_axis([0.02, -0.05, 0.01])], [np.array([-0.08, 0.002, 0.001])]) if n_cams == 2 \
        else ((), ())
    p = prob.pack(*rig, board_R=v.R, board_t=v.t) + rng.normal(scale=1e-3, size=prob.n_params)
    return prob, p


@pytest.mark.parametrize("n_cams, free", [(1, True), (2, True), (2, False)])
def test_jacobian_matches_finite_differences(rng, n_cams, free):
    prob, p = _problem(rng, n_cams, free)
    J = prob.jacobian(p)
    fd = np.empty_like(J)
    for k in range(prob.n_params):
        h = 1e-6 * max(1.0, abs(p[k]))
        e = np.zeros(prob.n_params)
        e[k] = h
        fd[:, k] = (prob.residuals(p + e) - prob.residuals(p - e)) / (2 * h)
    assert np.abs(J - fd).max() < 1e-6 * np.abs(J).max()      # central differences: error ~h² ≈ 1e-12 relative


def test_our_lm_reaches_scipys_optimum(rng):
    prob, p0 = _problem(rng)
    p, info = levenberg_marquardt(prob.residuals_and_jacobian, p0)
    ref = least_squares(prob.residuals, p0, jac=prob.jacobian, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert info["converged"] and abs(info["cost"] - ref.cost) < 1e-9 * ref.cost
    assert np.abs(p - ref.x).max() < 1e-6 * np.abs(ref.x).max()


def test_rectified_cameras_put_matches_on_one_row(rng):
    K1 = np.array([[520.0, 0, 330], [0, 515, 245], [0, 0, 1]])
    K2 = np.array([[540.0, 0, 310], [0, 538, 235], [0, 0, 1]])
    R = rotation_from_angle_axis([0.03, -0.08, 0.02])
    t = np.array([-0.1, 0.006, 0.01])
    rect = rectify_fusiello(K1, K2, R, t, (640, 480))
    X = rng.uniform([-1, -1, 2], [1, 1, 5], (50, 3))
    x1 = project_points(X, K1, np.zeros(5), np.eye(3), np.zeros(3))
    x2 = project_points(X, K2, np.zeros(5), R, t)
    y1, y2 = rectify_points(x1, K1, np.zeros(5), rect.H1), rectify_points(x2, K2, np.zeros(5), rect.H2)
    assert np.abs(y1[:, 1] - y2[:, 1]).max() < 1e-9
    depth = (X @ rect.R_rect.T)[:, 2]                        # disparity = f · baseline / depth (camera 2 on the right)
    assert np.allclose(y1[:, 0] - y2[:, 0], rect.K_new[0, 0] * rect.baseline / depth, rtol=1e-9)
    assert np.allclose(rect.R_rect @ rect.R_rect.T, np.eye(3)) and np.linalg.det(rect.R_rect) > 0


def test_remap_grid_undoes_the_distortion():
    K = np.array([[536.0, 0, 342], [0, 536, 235], [0, 0, 1]])
    dist = np.array([-0.2654, -0.0453, 0.0018, -0.0003, 0.2505])
    mx, my = remap_grid(K, dist, (640, 480))
    # the output pixel at the ideal position of a distorted pixel samples that distorted pixel
    x = np.array([[100.0, 80.0], [560.0, 400.0], [320.0, 60.0]])
    u = np.round(undistort_points(x, K, dist)).astype(int)
    src = np.column_stack([mx[u[:, 1], u[:, 0]], my[u[:, 1], u[:, 0]]])
    back = undistort_points(src, K, dist)
    assert np.abs(back - u).max() < 1e-3



def test_remap_grid_keeps_the_skew():
    """A skewed K (the dinosaur's is -78.6) with no distortion and no H: every output pixel samples itself. A map
    built from fx and fy alone shifts a pixel by skew · y_n (tens of pixels here)."""
    K = np.array([[3217.0, -78.6, 289.9], [0, 2292.0, -1070.0], [0, 0, 1]])
    mx, my = remap_grid(K, np.zeros(5), (720, 576))
    u, v = np.meshgrid(np.arange(720.0), np.arange(576.0))
    assert np.abs(mx - u).max() < 1e-3 and np.abs(my - v).max() < 1e-3

# --- recovery of synthetic truth --------------------------------------------------------------------------------

def test_noise_free_views_give_the_truth_exactly(rng):
    v = synthetic_board_views(rng=rng, n_views=5, noise_px=0.0)
    Hs = np.stack([board_homography(v.X, x) for x in v.x])
    # Zhang's closed form ignores the distortion: exact only without it
    v0 = synthetic_board_views(rng=rng, n_views=5, noise_px=0.0, dist=np.zeros(5))
    H0 = np.stack([board_homography(v0.X, x) for x in v0.x])
    assert k_error(intrinsics_from_homographies(H0, zero_skew=True), v0.K) < 1e-9
    R, t = pose_from_homography(H0[0], v0.K)
    assert np.allclose(R, v0.R[0], atol=1e-9) and np.allclose(t, v0.t[0], atol=1e-9)
    cal = calibrate_camera([v.X] * 5, v.x, v.image_size)
    assert k_error(cal.K, v.K) < 1e-10 and np.abs(cal.dist - v.dist).max() < 1e-9 and cal.rms_px < 1e-9
    assert np.allclose(cal.R, v.R, atol=1e-9) and np.allclose(cal.t, v.t, atol=1e-10)
    assert len(Hs) == 5


def test_noisy_corners_recover_K_to_a_tenth_of_a_percent():
    """0.1 px corner noise. How precise can K be? With 15 views of the 9x6 board the Cramér–Rao bound (σ²(JᵀJ)⁻¹ at
    the truth) gives σ(cx) ≈ 0.4 px = 0.08 % of f, so '0.1 %' would be a 1.3σ event there. 60 views of a 12x9 board
    bring σ(fx, fy, cx, cy) to ≤ 0.12 px: 0.1 % of f (0.54 px) is then ≥ 4.5σ, which chance does not cross. The
    distortion coefficients k2, k3 are correlated at -0.97 and have σ ≈ 0.01-0.02 at any realistic design, so
    'distortion to 1e-3' is checked where it matters, on the mapping: the distorted position of every ideal point
    inside the area the board covered, in normalised coordinates (1e-3 ≈ 0.5 px).
    """
    rng = np.random.default_rng(7)
    v = synthetic_board_views(rng=rng, n_views=60, noise_px=0.1, board=(12, 9), square=0.02, distance=(0.22, 0.35),
                              max_tilt_deg=60)
    cal = calibrate_camera([v.X] * 60, v.x, v.image_size)
    sd = np.array([cal.std[k] for k in ("fx", "fy", "cx", "cy")])
    assert 4 * sd.max() < 1e-3 * v.K[0, 0]                     # the design: 0.1 % is at least 4σ
    assert k_error(cal.K, v.K) < 1e-3
    # the distortion mapping, over the convex hull of the corners
    hull = cv2.convexHull(np.vstack(v.x).astype(np.float32))
    u, w = np.meshgrid(np.arange(0, 640, 10.0), np.arange(0, 480, 10.0))
    pix = np.column_stack([u.ravel(), w.ravel()])
    pix = pix[[cv2.pointPolygonTest(hull, (float(a), float(b)), False) >= 0 for a, b in pix]]
    xn = undistort_points(pix, v.K, v.dist, np.eye(3))
    assert np.abs(distort(xn, cal.dist) - distort(xn, v.dist)).max() < 1e-3
    # the intrinsic error weighted by its covariance is χ²(9): 99.99 % quantile 33.7
    th = np.r_[k_vector(cal.K), cal.dist] - np.r_[k_vector(v.K), v.dist]
    assert th @ np.linalg.solve(cal.cov[:9, :9], th) < 33.7
    # σ̂ per coordinate at the ML optimum: 0.1 · sqrt(1 - d/N); N = 12 960, so its relative sd is 1/sqrt(2N) = 0.6 %
    n_res, n_par = 2 * 60 * 108, 9 + 6 * 60
    rms_coord = cal.rms_px / np.sqrt(2)
    assert abs(rms_coord / ml_residual_bound(0.1, n_res, n_par) - 1) < 0.03


def test_rendered_images_detected_and_calibrated(rendered):
    views, images, corners = rendered
    assert all(c is not None for c in corners)
    err = []
    for c, xt in zip(corners, views.x_true):
        if np.abs(c[::-1] - xt).max() < np.abs(c - xt).max():     # the detector may start at the other end
            c = c[::-1]
        err.append(c - xt)
    err = np.vstack(err)
    rms_det = float(np.sqrt(np.mean(err ** 2)))
    assert rms_det < 0.08 and np.abs(err.mean(0)).max() < 0.01      # measured 0.03-0.04 px, unbiased
    cal = calibrate_camera([views.X] * len(corners), corners, views.image_size)
    assert k_error(cal.K, views.K) < 1e-3
    assert abs(cal.rms_px / np.sqrt(2) / rms_det - 1) < 0.2          # the fit's residual is the detection noise


def test_view_influence_share_is_the_information_a_view_adds(rendered):
    """share_v = tr(S_v S⁻¹)/q = 1 - tr(S₋ᵥ S⁻¹)/q, with S₋ᵥ the intrinsics' information of the calibration made
    without view v (from its own covariance, σ̂² (block of (JᵀJ)⁻¹)⁻¹): an independent computation of the shares."""
    views, _, corners = rendered
    cal = calibrate_camera([views.X] * 6, corners[:6], views.image_size)
    inf = view_influence(cal)
    ic = cal.problem.int_cols[0]

    def information(c):
        return np.linalg.inv(c.cov[np.ix_(ic, ic)]) * c.sigma_px ** 2

    S_inv = np.linalg.inv(information(cal))
    expected = [1 - np.trace(information(calibrate_camera([views.X] * 5, corners[:v] + corners[v + 1:6],
                                                          views.image_size)) @ S_inv) / len(ic) for v in range(6)]
    assert np.abs(inf["share"] - expected).max() < 0.01        # measured 0.0025 (shares 0.09-0.36)
    assert inf["dK"].shape == (6, 4) and np.all(np.isfinite(inf["dK_sigma"]))


def test_stereo_calibration_recovers_the_rig(rng):
    v = synthetic_board_views(rng=rng, n_views=8, noise_px=0.0, distance=(0.4, 0.5), max_tilt_deg=35)
    R_rig = rotation_from_angle_axis([0.01, -0.04, 0.005])
    t_rig = np.array([-0.06, 0.001, 0.002])
    K2 = np.array([[545.0, 0, 318], [0, 541, 244], [0, 0, 1]])
    d2 = np.array([-0.2, 0.05, -0.0005, 0.0007, 0.0])
    x2 = [project_points(v.X, K2, d2, R_rig @ R, R_rig @ t + t_rig) for R, t in zip(v.R, v.t)]
    cal1 = calibrate_camera([v.X] * 8, v.x, v.image_size)
    cal2 = calibrate_camera([v.X] * 8, x2, v.image_size)
    st = calibrate_stereo([v.X] * 8, v.x, x2, cal1, cal2)
    assert np.allclose(st.R, R_rig, atol=1e-9) and np.allclose(st.t, t_rig, atol=1e-10) and st.rms_px < 1e-9
    x2_flipped = [x2[0][::-1]] + x2[1:]          # view 0's corners found from the other end in camera 2
    cal2_flipped = calibrate_camera([v.X] * 8, x2_flipped, v.image_size)
    with pytest.raises(ValueError, match="same order in both images"):
        calibrate_stereo([v.X] * 8, v.x, x2_flipped, cal1, cal2_flipped)


def test_stereo_refining_intrinsics_keeps_what_each_camera_fixed(rng):
    """fix_intrinsics=False frees only what each camera's own calibration left free: k3 = 0, p = 0, fx = fy stay."""
    v = synthetic_board_views(rng=rng, n_views=8, noise_px=0.2, distance=(0.4, 0.5), max_tilt_deg=35)
    R_rig, t_rig = rotation_from_angle_axis([0.01, -0.04, 0.005]), np.array([-0.06, 0.001, 0.002])
    K2 = np.array([[543.0, 0, 318], [0, 543, 244], [0, 0, 1]])
    x2 = [project_points(v.X, K2, np.array([-0.2, 0.05, 0.001, -0.001, 0.02]), R_rig @ R, R_rig @ t + t_rig)
          + rng.normal(0, 0.2, (len(v.X), 2)) for R, t in zip(v.R, v.t)]
    cal1 = calibrate_camera([v.X] * 8, v.x, v.image_size, fix_k3=True, zero_tangential=True)
    cal2 = calibrate_camera([v.X] * 8, x2, v.image_size, fix_aspect_ratio=True)
    st = calibrate_stereo([v.X] * 8, v.x, x2, cal1, cal2, fix_intrinsics=False)
    assert np.all(st.dist1[2:] == 0) and st.K2[0, 0] / st.K2[1, 1] == pytest.approx(cal2.K[0, 0] / cal2.K[1, 1])
    assert not np.allclose(st.K1, cal1.K, rtol=0, atol=1e-9) and not np.allclose(st.dist2, cal2.dist, atol=1e-9)
    assert k_error(st.K2, K2) < 0.01 and np.abs(st.t - t_rig).max() < 0.002


# --- OpenCV side by side and the real views --------------------------------------------------------------------

def _opencv(views, flags):
    obj = [views.X.astype(np.float32)] * views.n_views
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, [x.astype(np.float32) for x in views.x], views.image_size,
                                             np.eye(3), None, flags=flags)
    return rms, K, dist.ravel()


@pytest.mark.parametrize("fix_aspect", [False, True])
def test_real_left_views_agree_with_opencv(left, fix_aspect):
    cal = calibrate_camera([left.X] * left.n_views, left.x, left.image_size, fix_aspect_ratio=fix_aspect)
    rms, K, dist = _opencv(left, cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect else 0)
    assert k_error(cal.K, K) < 1e-5 and np.abs(cal.dist - dist).max() < 1e-4       # measured: the same optimum
    assert abs(cal.rms_px / rms - 1) < 1e-5
    assert fix_aspect == (cal.K[0, 0] == cal.K[1, 1])


def test_real_stereo_pair_rectifies_to_rows(left, right):
    assert [n.replace("left", "right") for n in left.names] == right.names
    cal1 = calibrate_camera([left.X] * left.n_views, left.x, left.image_size)
    cal2 = calibrate_camera([right.X] * right.n_views, right.x, right.image_size)
    st = calibrate_stereo([left.X] * left.n_views, left.x, right.x, cal1, cal2)
    obj = [left.X.astype(np.float32)] * left.n_views
    out = cv2.stereoCalibrate(obj, [x.astype(np.float32) for x in left.x], [x.astype(np.float32) for x in right.x],
                              cal1.K, cal1.dist, cal2.K, cal2.dist, left.image_size, flags=cv2.CALIB_FIX_INTRINSIC)
    assert abs(out[0] / st.rms_px - 1) < 1e-4 and np.abs(out[6].ravel() - st.t).max() < 1e-6
    rect = rectify_fusiello(st.K1, st.K2, st.R, st.t, left.image_size)
    dy = np.concatenate([rectify_points(a, st.K1, st.dist1, rect.H1)[:, 1] - rectify_points(b, st.K2, st.dist2,
                                                                                            rect.H2)[:, 1]
                         for a, b in zip(left.x, right.x)])
    assert np.median(np.abs(dy)) < 1.0                 # the brief's check; measured 0.11 px (corner noise ~0.2 px)
    # in the rectified images themselves, the board found again lies on the same rows
    a = rectify_image(left.images[0], st.K1, st.dist1, rect.H1)
    b = rectify_image(right.images[0], st.K2, st.dist2, rect.H2)
    ca, cb = detect_corners(a), detect_corners(b)
    assert np.median(np.abs(ca[:, 1] - cb[:, 1])) < 1.0


def test_real_undistortion_straightens_the_rows(left):
    cal = calibrate_camera([left.X] * left.n_views, left.x, left.image_size)
    before = np.sqrt(np.mean(np.concatenate([grid_line_residuals(x) for x in left.x]) ** 2))
    after = np.sqrt(np.mean(np.concatenate([grid_line_residuals(undistort_points(x, cal.K, cal.dist))
                                            for x in left.x]) ** 2))
    # after undistortion only the corner noise is left: a line fit residual of about σ̂ · sqrt(1 - 2/n) ≈ 0.13 px
    assert after < 0.2 < 0.5 < before
    und = undistort_image(left.images[2], cal.K, cal.dist)
    c = detect_corners(und)
    assert np.sqrt(np.mean(grid_line_residuals(c) ** 2)) < 0.2


# --- the command line --------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def photo_dir(tmp_path_factory, rendered):
    d = tmp_path_factory.mktemp("photos")
    views, images, _ = rendered
    for k, img in enumerate(images[:5]):
        cv2.imwrite(str(d / f"board{k:02d}.png"), img)
    return d


def _cli(*args, cwd):
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "labutils.calibrate", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, env=env)


def test_cli_calibrates_and_writes_k_for_sfm(tmp_path, photo_dir, rendered):
    (tmp_path / "broken.png").write_text("not an image")
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((480, 640), 200, np.uint8))
    old = os.umask(0o022)
    try:
        r = _cli(f"{photo_dir}/*.png", tmp_path / "broken.png", tmp_path / "blank.png", "--board", "9x6", "--square",
                 "0.025", "--out", "calib.json", "--k-out", "K.txt", cwd=tmp_path)
    finally:
        os.umask(old)
    assert r.returncode == 0, r.stderr
    d = json.loads((tmp_path / "calib.json").read_text())
    assert set(d) >= {"K", "dist", "rms_px", "image_size", "views_used", "views_rejected"}
    assert len(d["views_used"]) == 5 and d["image_size"] == [640, 480]
    assert {Path(v["image"]).name: v["reason"][:10] for v in d["views_rejected"]} == {
        "broken.png": "unreadable", "blank.png": "board not "}
    K = read_calibration(tmp_path / "K.txt", 1)[0]                     # the format of python -m labutils.sfm
    assert np.allclose(K, d["K"], rtol=1e-9) and k_error(K, rendered[0].K) < 5e-3
    for f in ("calib.json", "K.txt"):
        assert stat.S_IMODE((tmp_path / f).stat().st_mode) == 0o644
    assert "calibrated from 5 of 7 images (2 skipped)" in r.stdout and "[####################] 7/7" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["K.txt", "blank.png", "broken.png", "calib.json"]


def test_cli_help():
    r = _cli("--help", cwd=ROOT)
    assert r.returncode == 0 and "--board" in r.stdout


@pytest.mark.parametrize("case, message", [
    ("too_few", r"^error: .*: 2 usable views of 3 images; at least 3 are needed \(rejected: .*broken.png: unreadable"),
    ("sizes", r"^error: .*small.png: image size 32x24 differs from 640x480"),
    ("no_match", r"^error: nothing\*.png: no file matches this pattern$"),
    ("no_folder", r"^error: missing/calib.json: the folder missing does not exist \(--out\)$"),
    ("bad_board", r"^error: argument --board: expected COLUMNSxROWS"),
    ("undistort_alone", r"^error: --undistort and --undistort-out go together"),
    ("undistort_in_place", r"^error: .*board01.png: --undistort-out \(for .*board01.png\) is an input photo "
                           r"\(.*board01.png\); it would be overwritten: choose another file$"),
    ("k_out_is_out", r"^error: calib.json: --k-out and --out name the same file \(calib.json\); give each its own "
                     r"file$"),
])
def test_cli_failures_are_one_line_and_write_nothing(tmp_path, photo_dir, case, message):
    import re
    imgs = sorted(photo_dir.glob("*.png"))
    (tmp_path / "broken.png").write_text("not an image")
    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((24, 32), np.uint8))
    args = {"too_few": [imgs[0], imgs[1], tmp_path / "broken.png"],
            "sizes": [imgs[0], tmp_path / "small.png", imgs[1]],
            "no_match": ["nothing*.png"],
            "no_folder": [imgs[0]],
            "bad_board": [imgs[0]],
            "undistort_alone": [imgs[0], "--undistort", imgs[1]],
            "undistort_in_place": [*imgs, "--undistort", imgs[1], "--undistort-out", photo_dir],
            "k_out_is_out": [*imgs]}[case]
    board = "9-6" if case == "bad_board" else "9x6"
    out = "missing/calib.json" if case == "no_folder" else "calib.json"
    k_out = "calib.json" if case == "k_out_is_out" else "K.txt"
    before = sorted(p.name for p in tmp_path.iterdir())
    photos_before = {p.name: p.read_bytes() for p in photo_dir.iterdir()}
    r = _cli(*args, "--board", board, "--out", out, "--k-out", k_out, "--quiet", cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and re.search(message, r.stderr.strip()), r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == before          # nothing written, no temporary file
    assert {p.name: p.read_bytes() for p in photo_dir.iterdir()} == photos_before     # the photos untouched


def test_cli_undistorts_photos(tmp_path, photo_dir, rendered):
    (tmp_path / "und").mkdir()
    r = _cli(f"{photo_dir}/*.png", "--board", "9x6", "--out", "calib.json", "--undistort",
             photo_dir / "board00.png", "--undistort-out", "und", "--quiet", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    img = cv2.imread(str(tmp_path / "und" / "board00.png"), cv2.IMREAD_GRAYSCALE)
    c = detect_corners(img)                     # the board's rows are straight in the undistorted photo
    assert c is not None and np.sqrt(np.mean(grid_line_residuals(c) ** 2)) < 0.1


def test_write_failure_leaves_nothing(tmp_path, monkeypatch):
    def full(fd):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match="a.json: cannot write \\(No space left on device\\)"):
        write_atomically({str(tmp_path / "a.json"): "{}", str(tmp_path / "K.txt"): "1 0 0\n"})
    assert list(tmp_path.iterdir()) == []


def test_main_write_failure_exit_2(tmp_path, photo_dir, monkeypatch, capsys):
    monkeypatch.setattr(os, "fsync", lambda fd: (_ for _ in ()).throw(OSError(28, "No space left on device")))
    code = main([str(p) for p in sorted(photo_dir.glob("*.png"))[:3]] + ["--board", "9x6", "--out",
                                                                          str(tmp_path / "c.json"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("error: ") and "No space left" in err and len(err.splitlines()) == 1
    assert err.startswith(f"error: {tmp_path / 'c.json'}: cannot write") and "unexpected" not in err
    assert list(tmp_path.iterdir()) == []


def test_render_board_is_the_camera_model(rendered):
    """The renderer draws with our model: a view rendered again matches, and a corner's neighbourhood is symmetric."""
    views, images, _ = rendered
    img = render_board(views.K, views.dist, views.R[0], views.t[0])
    assert np.abs(img.astype(int) - images[0].astype(int)).max() <= 12          # only the noise (σ = 2) differs
    with pytest.raises(ValueError, match="needs rng"):
        render_board(views.K, views.dist, views.R[0], views.t[0], noise=1.0)


def test_synthetic_stereo_views_are_consistent():
    """The notebook's fallback: both cameras see every board, corners in board order, the rig as documented."""
    from labutils.calibrate.chessboard import RIG_R, RIG_T, synthetic_stereo_views
    left_s, right_s = synthetic_stereo_views(n_views=3, rng=np.random.default_rng(3))
    for views in (left_s, right_s):
        assert len(views.images) == 3 and views.source == "synthetic"
        for x, xt in zip(views.x, views.x_true):
            assert np.abs(x - xt).max() < 0.3                       # detected, in the order of board_points
    assert np.allclose(right_s.R, RIG_R @ left_s.R) and np.allclose(right_s.t, left_s.t @ RIG_R.T + RIG_T)


def test_large_images_are_searched_small_and_refined_at_full_size(rendered):
    views, images, _ = rendered
    big = cv2.resize(images[1], None, fx=3, fy=3, interpolation=cv2.INTER_CUBIC)        # 1920x1440
    x = detect_corners(big)
    xt = (views.x_true[1] + 0.5) * 3 - 0.5                                               # pixel centres at integers
    x = x[::-1] if np.abs(x[::-1] - xt).max() < np.abs(x - xt).max() else x
    assert np.sqrt(np.mean((x - xt) ** 2)) < 0.3          # the 640x480 detection error (0.04 px) times 3, and margin


def test_refinement_that_does_not_converge_is_an_error():
    v = synthetic_board_views(rng=np.random.default_rng(5), n_views=4, noise_px=0.2)
    with pytest.raises(ValueError, match="did not converge in 2 iterations"):
        calibrate_camera([v.X] * 4, v.x, v.image_size, max_iter=2)
