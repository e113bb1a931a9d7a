"""Camera calibration from views of a planar board: Zhang's method, the lens distortion model, and its refinement.

Z. Zhang, "A flexible new technique for camera calibration", IEEE PAMI 22(11), 2000 (cited as Zhang);
H&Z Sec. 8.5 and 8.8 (the image of the absolute conic, ω = K⁻ᵀK⁻¹).

The camera model is OpenCV's (:mod:`labutils.calibrate.lens`): a board point ``X`` (on the plane Z = 0 of the board
frame) in view v is at ``x_cam = R_v @ X + t_v`` and seen through the lens at :func:`labutils.calibrate.distort`
of its normalised coordinates. The reprojection RMS reported everywhere is OpenCV's:
``sqrt(mean over points of |x_proj - x_meas|²)`` (per point, not per coordinate).

The pipeline (:func:`calibrate_camera`)
--------------------------------------
1. a homography per view, board ``(X, Y)`` → pixels (:func:`labutils.calibrate.board_homography`, the normalised
DLT
   of H&Z Alg. 4.2);
2. the closed-form K from the homographies: each gives two linear constraints on the image of the absolute
   conic ``B = K⁻ᵀK⁻¹`` (:func:`labutils.calibrate.intrinsics_from_homographies`, Zhang Sec. 3.1);
3. each view's pose from its homography and K (:func:`labutils.calibrate.pose_from_homography`, Zhang Sec. 3.1);
4. Levenberg–Marquardt over K, the distortion and every pose, minimising the reprojection error with an
   analytic Jacobian (:class:`CalibrationProblem`, :func:`labutils.core.levenberg_marquardt`;
   Zhang Sec. 3.2–3.3).

The same least-squares problem, with a second camera rigidly attached to the first, calibrates a stereo rig
(:func:`calibrate_stereo`). Why our own LM rather than :func:`scipy.optimize.least_squares`: the problem is
small and dense (13 views: 1,404 residuals, 87 parameters), so the normal equations are an 87×87 solve; our
loop is 30 lines the notebook can show, it keeps JᵀJ at the optimum for the covariance σ̂²(JᵀJ)⁻¹, and the tests
check that it reaches the same optimum as scipy's.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..core.geometry import angle_axis_from_rotation, left_jacobian_so3, rotation_from_angle_axis, skew
from ..core.lm import levenberg_marquardt
from ..core.validation import as_image_size, as_points
from .lens import INTRINSIC_NAMES, apply_distortion, as_intrinsics
from .zhang import as_board_points, board_homography, intrinsics_from_homographies, pose_from_homography

__all__ = ["CalibrationProblem", "CalibrationResult", "calibration_problem", "calibrate_camera", "view_influence",
           "StereoCalibration", "calibrate_stereo"]

# ---------------------------------------------------------------------------------------------------------------
# the least-squares problem: one or more rigidly attached cameras, one board pose per view
# ---------------------------------------------------------------------------------------------------------------

def _intrinsic_map(theta0, fix_aspect_ratio, fix_principal_point, zero_tangential, fix_k3, fix_distortion):
    """(A, names): the free intrinsic parameters δ enter as ``theta = theta0 + A @ δ``."""
    cols, names = [], []
    e = np.eye(9)
    if fix_aspect_ratio:
        cols.append(np.r_[theta0[0] / theta0[1], 1.0, np.zeros(7)])     # fx = a f, fy = f (a fixed)
        names.append("f")
    else:
        cols += [e[0], e[1]]
        names += ["fx", "fy"]
    if not fix_principal_point:
        cols += [e[2], e[3]]
        names += ["cx", "cy"]
    if not fix_distortion:
        cols += [e[4], e[5]]
        names += ["k1", "k2"]
        if not zero_tangential:
            cols += [e[6], e[7]]
            names += ["p1", "p2"]
        if not fix_k3:
            cols.append(e[8])
            names.append("k3")
    return (np.column_stack(cols) if cols else np.zeros((9, 0))), names


class CalibrationProblem:
    """The reprojection residuals and their analytic Jacobian for C rigidly attached cameras and V board poses.

    Parameters (in this order in the vector ``p``): for each camera c its free intrinsics δ_c
    (``theta_c = theta0_c + A_c δ_c``, ``theta = (fx, fy, cx, cy, k1, k2, p1, p2, k3)``); for each camera c >= 1
    its pose relative to camera 0, ``(ω_c, t_c)`` (6, angle-axis and translation: ``x_cam_c = R_c x_cam_0 + t_c``);
    for each view v the board pose ``(ω_v, t_v)`` in camera 0 (6). One camera (C = 1) is plain calibration
    (Zhang Sec. 3.2); two are a stereo rig.

    Residual rows ``2i, 2i + 1`` are ``project(point i) - x_i`` in pixels.

    Parameters
    ----------
    X : (M, 3) array_like
        Board points of every observation (Z = 0 not required here).
    x : (M, 2) array_like
        Their measured pixels.
    cam, view : (M,) int array_like
        Camera and view of each observation.
    theta0 : (C, 9) array_like
        Intrinsics at which δ = 0.
    A : list of C (9, q_c) arrays
        How the free intrinsics enter (see :func:`calibrate_camera` for the options).
    intrinsic_names : list of C lists of str, optional
        Names of each camera's free intrinsics (for printing).
    """

    def __init__(self, X, x, cam, view, theta0, A, intrinsic_names=None):
        self.X = as_points(X, "X", dim=3)
        self.x = as_points(x, "x", like=self.X)
        self.cam = np.asarray(cam, int).ravel()
        self.view = np.asarray(view, int).ravel()
        if self.cam.shape != (len(self.X),) or self.view.shape != (len(self.X),):
            raise ValueError(f"cam and view must have shape ({len(self.X)},); got {self.cam.shape}, {self.view.shape}")
        self.theta0 = np.asarray(theta0, float).reshape(-1, 9)
        self.n_cams = len(self.theta0)
        self.n_views = int(self.view.max()) + 1
        self.A = [np.asarray(a, float).reshape(9, -1) for a in A]
        if len(self.A) != self.n_cams:
            raise ValueError(f"A must hold one (9, q) matrix per camera ({self.n_cams}); got {len(self.A)}")
        self.intrinsic_names = intrinsic_names or [[f"δ{j}" for j in range(a.shape[1])] for a in self.A]
        q = [a.shape[1] for a in self.A]
        self.int_cols = np.split(np.arange(sum(q)), np.cumsum(q)[:-1])
        o = sum(q)
        self.rig_cols = [None] + [np.arange(o + 6 * (c - 1), o + 6 * c) for c in range(1, self.n_cams)]
        o += 6 * (self.n_cams - 1)
        self.view_cols = [np.arange(o + 6 * v, o + 6 * v + 6) for v in range(self.n_views)]
        self.n_params = o + 6 * self.n_views

    # -- packing --------------------------------------------------------------------------------------------
    def pack(self, rig_R=(), rig_t=(), board_R=(), board_t=(), delta=None):
        """The parameter vector from rig poses (C - 1), board poses (V) and the intrinsic deltas (default 0)."""
        p = np.zeros(self.n_params)
        if delta is not None:
            for c, d in enumerate(delta):
                p[self.int_cols[c]] = d
        for c in range(1, self.n_cams):
            p[self.rig_cols[c]] = np.r_[angle_axis_from_rotation(rig_R[c - 1]), rig_t[c - 1]]
        for v in range(self.n_views):
            p[self.view_cols[v]] = np.r_[angle_axis_from_rotation(board_R[v]), board_t[v]]
        return p

    def theta(self, p):
        """``(C, 9)`` intrinsics ``(fx, fy, cx, cy, k1, k2, p1, p2, k3)`` at ``p``."""
        return np.stack([self.theta0[c] + self.A[c] @ p[self.int_cols[c]] for c in range(self.n_cams)])

    def K_dist(self, p, c=0):
        th = self.theta(p)[c]
        return np.array([[th[0], 0.0, th[2]], [0.0, th[1], th[3]], [0.0, 0.0, 1.0]]), th[4:].copy()

    def board_poses(self, p):
        """``R (V, 3, 3)``, ``t (V, 3)`` of the board in camera 0."""
        w = np.stack([p[c[:3]] for c in self.view_cols])
        return rotation_from_angle_axis(w), np.stack([p[c[3:]] for c in self.view_cols])

    def rig_poses(self, p):
        """``R (C, 3, 3)``, ``t (C, 3)`` of each camera relative to camera 0 (camera 0: identity)."""
        w = np.zeros((self.n_cams, 3))
        t = np.zeros((self.n_cams, 3))
        for c in range(1, self.n_cams):
            w[c], t[c] = p[self.rig_cols[c][:3]], p[self.rig_cols[c][3:]]
        return rotation_from_angle_axis(w), t

    # -- residuals and Jacobian -----------------------------------------------------------------------------
    def _evaluate(self, p, jac):
        Rv, tv = self.board_poses(p)
        Rc, tc = self.rig_poses(p)
        th = self.theta(p)[self.cam]                               # (M, 9)
        RX = np.einsum("mij,mj->mi", Rv[self.view], self.X)
        Y = RX + tv[self.view]                                     # in camera 0
        RY = np.einsum("mij,mj->mi", Rc[self.cam], Y)
        Xc = RY + tc[self.cam]
        z = Xc[:, 2]
        if np.any(z <= 0):
            raise ValueError(f"{np.sum(z <= 0)} board points are behind a camera at these parameters")
        xn = Xc[:, :2] / z[:, None]
        M = len(self.X)
        xd, dxd, ddist = np.empty((M, 2)), np.empty((M, 2, 2)), np.empty((M, 2, 5))
        for c in range(self.n_cams):
            sel = self.cam == c
            xd[sel], dxd[sel], ddist[sel] = apply_distortion(xn[sel], self.theta(p)[c, 4:], jac=True)
        f = th[:, :2]
        r = (xd * f + th[:, 2:4] - self.x).ravel()
        if not jac:
            return r
        dth = np.zeros((M, 2, 9))                                  # ∂pixel/∂(fx, fy, cx, cy, k1, k2, p1, p2, k3)
        dth[:, 0, 0], dth[:, 1, 1] = xd[:, 0], xd[:, 1]
        dth[:, 0, 2] = dth[:, 1, 3] = 1.0
        dth[:, :, 4:] = ddist * f[:, :, None]
        x, y = xn[:, 0], xn[:, 1]
        dxn = np.zeros((M, 2, 3))
        dxn[:, 0, 0] = dxn[:, 1, 1] = 1 / z
        dxn[:, 0, 2], dxn[:, 1, 2] = -x / z, -y / z
        dXc = f[:, :, None] * np.einsum("mij,mjk->mik", dxd, dxn)     # ∂pixel/∂Xc (M, 2, 3)
        rows = np.arange(2 * M).reshape(M, 2)
        blocks = []                                                 # (rows (m, 2), first column (m,), values (m, 2, k))
        for c in range(self.n_cams):
            sel = np.flatnonzero(self.cam == c)
            cols = self.int_cols[c]
            if len(cols):
                blocks.append((rows[sel], np.full(len(sel), cols[0]), dth[sel] @ self.A[c]))
            if c >= 1:
                Jl = left_jacobian_so3(p[self.rig_cols[c][:3]][None])[0]
                dw = -np.einsum("mij,jk->mik", skew(RY[sel]), Jl)        # ∂Xc/∂ω_c = -[R_c Y]× J_l(ω_c)
                blocks.append((rows[sel], np.full(len(sel), self.rig_cols[c][0]),
                               np.concatenate([dXc[sel] @ dw, dXc[sel]], axis=2)))
        wv = np.stack([p[c[:3]] for c in self.view_cols])
        dXc_dY = dXc @ Rc[self.cam]                                 # ∂pixel/∂Y = ∂pixel/∂Xc · R_c
        dw = -np.einsum("mij,mjk->mik", skew(RX), left_jacobian_so3(wv)[self.view])   # ∂Y/∂ω_v
        col0 = np.array([vc[0] for vc in self.view_cols])[self.view]
        blocks.append((rows, col0, np.concatenate([dXc_dY @ dw, dXc_dY], axis=2)))
        ii, jj, vv = [], [], []
        for rr, c0, val in blocks:
            k = val.shape[2]
            ii.append(np.broadcast_to(rr[:, :, None], val.shape).ravel())
            jj.append(np.broadcast_to(c0[:, None, None] + np.arange(k), val.shape).ravel())
            vv.append(val.ravel())
        J = sp.csr_matrix((np.concatenate(vv), (np.concatenate(ii), np.concatenate(jj))), shape=(2 * M, self.n_params))
        return r, J

    def residuals(self, p):
        """``(2M,)`` pixel residuals, rows ``2i, 2i + 1`` = ``project(X_i) - x_i``."""
        return self._evaluate(np.asarray(p, float), jac=False)

    def jacobian(self, p):
        """``(2M, n_params)`` analytic Jacobian of :meth:`residuals`, dense."""
        return self._evaluate(np.asarray(p, float), jac=True)[1].toarray()

    def residuals_and_jacobian(self, p):
        """Residuals and the Jacobian as a ``scipy.sparse`` CSR matrix (each row has at most q + 12 entries)."""
        return self._evaluate(np.asarray(p, float), jac=True)


# ---------------------------------------------------------------------------------------------------------------
# calibrating one camera
# ---------------------------------------------------------------------------------------------------------------

@dataclass
class CalibrationResult:
    """A calibrated camera: intrinsics, distortion, a board pose per view, and how well it fits.

    Attributes
    ----------
    K : (3, 3) ndarray
    dist : (5,) ndarray
        ``(k1, k2, p1, p2, k3)``.
    R, t : (V, 3, 3), (V, 3) ndarray
        Board pose of each view, ``x_cam = R @ X + t``.
    rms_px : float
        ``sqrt(mean |x_proj - x|²)`` over all points (OpenCV's definition).
    per_view_rms : (V,) ndarray
    residuals : list of (N_v, 2) ndarray
        ``x_proj - x`` per view.
    image_size : (w, h)
    free : list of str
        Names of the free intrinsic parameters.
    sigma_px : float
        σ̂ per coordinate, ``sqrt(Σr² / (2M - n_params))``.
    std : dict
        Standard deviation of each intrinsic (``fx ... k3``; 0 when fixed) from ``σ̂² (JᵀJ)⁻¹``.
    cov : (n_params, n_params) ndarray
        ``σ̂² (JᵀJ)⁻¹`` of all parameters (free intrinsics, then 6 per view).
    K_init : (3, 3) ndarray
        Zhang's closed-form K, the starting point.
    n_iter : int
    costs : list of float
    """

    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    rms_px: float
    per_view_rms: np.ndarray
    residuals: list
    image_size: tuple
    free: list
    sigma_px: float
    std: dict
    cov: np.ndarray
    K_init: np.ndarray
    n_iter: int
    costs: list = field(default_factory=list)
    problem: object = field(default=None, repr=False)
    p: np.ndarray = field(default=None, repr=False)

    def summary(self):
        K, d = self.K, self.dist
        return (f"{len(self.R)} views: fx = {K[0, 0]:.2f} ± {self.std['fx']:.2f}, fy = {K[1, 1]:.2f} ± "
                f"{self.std['fy']:.2f}, c = ({K[0, 2]:.2f}, {K[1, 2]:.2f}) px; dist = "
                f"[{', '.join(f'{v:.5f}' for v in d)}]; RMS {self.rms_px:.4f} px")


def _check_views(object_points, image_points, min_views, what="image_points"):
    if len(object_points) != len(image_points):
        raise ValueError(f"object_points has {len(object_points)} views but {what} has {len(image_points)}")
    if len(image_points) < min_views:
        raise ValueError(f"{what} has {len(image_points)} views; at least {min_views} are needed to calibrate "
                         "(each view of a planar board gives 2 constraints on the 4-5 unknowns of K)")
    Xs = [as_board_points(X, f"object_points[{v}]") for v, X in enumerate(object_points)]
    xs = [as_points(x, f"{what}[{v}]", min_n=4, like=X) for v, (X, x) in enumerate(zip(Xs, image_points))]
    return Xs, xs


def _stack(Xs, xs, cam=0):
    view = np.concatenate([np.full(len(X), v) for v, X in enumerate(Xs)])
    return np.vstack(Xs), np.vstack(xs), np.full(len(view), cam), view


def _covariance(J, r):
    dof = len(r) - J.shape[1]
    if dof <= 0:
        raise ValueError(f"{len(r)} residuals for {J.shape[1]} parameters: not enough to calibrate")
    sigma2 = float(r @ r / dof)
    JtJ = J.T @ J
    JtJ = JtJ.toarray() if sp.issparse(JtJ) else JtJ
    try:
        cov = sigma2 * np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:
        cov = np.full(JtJ.shape, np.inf)
    return np.sqrt(sigma2), cov


def calibrate_camera(object_points, image_points, image_size, *, fix_aspect_ratio=False, fix_principal_point=False,
                     zero_tangential=False, fix_k3=False, fix_distortion=False, K_init=None, max_iter=100, tol=1e-12):
    """Calibrate a camera from views of a planar board: Zhang's closed form, then Levenberg–Marquardt (Zhang Sec. 3).

    Parameters
    ----------
    object_points : list of (N_v, 3) array_like
        Board points of each view, on the plane Z = 0 (e.g. :func:`labutils.calibrate.board_points`).
    image_points : list of (N_v, 2) array_like
        Their detected pixels, row by row.
    image_size : (w, h)
    fix_aspect_ratio : bool
        ``fx / fy`` fixed (OpenCV's ``CALIB_FIX_ASPECT_RATIO`` with an identity initial K: ``fx = fy``).
    fix_principal_point, zero_tangential, fix_k3, fix_distortion : bool
        Like OpenCV's ``CALIB_FIX_PRINCIPAL_POINT`` (at Zhang's estimate, or ``K_init``'s), ``CALIB_ZERO_TANGENT_DIST``,
        ``CALIB_FIX_K3`` (k3 = 0), and all five coefficients 0.
    K_init : (3, 3) array_like, optional
        Start here instead of Zhang's closed form.
    max_iter, tol :
        For :func:`levenberg_marquardt`.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ValueError
        Fewer than 3 views, mismatched shapes, non-planar board points, views that do not determine K, or a
        refinement that does not converge.

    Examples
    --------
    >>> from labutils.calibrate.chessboard import board_points, synthetic_board_views
    >>> views = synthetic_board_views(n_views=6, noise_px=0.0, rng=np.random.default_rng(0))
    >>> cal = calibrate_camera([views.X] * 6, views.x_true, views.image_size)
    >>> bool(np.allclose(cal.K, views.K, rtol=1e-8) and np.allclose(cal.dist, views.dist, atol=1e-8))
    True
    """
    prob, p0, K0 = calibration_problem(object_points, image_points, image_size, fix_aspect_ratio=fix_aspect_ratio,
                                       fix_principal_point=fix_principal_point, zero_tangential=zero_tangential,
                                       fix_k3=fix_k3, fix_distortion=fix_distortion, K_init=K_init)
    p, info = levenberg_marquardt(prob.residuals_and_jacobian, p0, max_iter=max_iter, tol=tol)
    _require_convergence(info, max_iter)
    return _result(prob, p, info, K0, as_image_size(image_size), prob.intrinsic_names[0])


def _require_convergence(info, max_iter):
    if not info["converged"]:
        rms = np.sqrt(2 * np.mean(info["r"] ** 2))
        raise ValueError(f"Levenberg–Marquardt did not converge in {max_iter} iterations (RMS {rms:.3g} px): the views "
                         "do not determine the camera well (too few, too similar, or wrongly detected corners)")


def calibration_problem(object_points, image_points, image_size, *, fix_aspect_ratio=False, fix_principal_point=False,
                        zero_tangential=False, fix_k3=False, fix_distortion=False, K_init=None):
    """The least-squares problem of :func:`calibrate_camera` and its starting point (steps 1–3 of Zhang's method).

    Homographies, the closed-form K (zero skew; ``fx = fy`` with ``fix_aspect_ratio``), each view's pose, and zero
    distortion give the start ``p0`` of the refinement. Arguments as for :func:`calibrate_camera`.

    Returns
    -------
    problem : CalibrationProblem
        One camera; its free intrinsics are named in ``problem.intrinsic_names[0]``.
    p0 : (n_params,) ndarray
    K0 : (3, 3) ndarray
        The closed-form K (or ``K_init``).
    """
    Xs, xs = _check_views(object_points, image_points, 3)
    w, h = as_image_size(image_size)
    Hs = np.stack([board_homography(X, x) for X, x in zip(Xs, xs)])
    if K_init is None:
        K0 = intrinsics_from_homographies(Hs, zero_skew=True, equal_focal=fix_aspect_ratio, image_size=(w, h))
    else:
        K0 = as_intrinsics(K_init, "K_init")
    poses = [pose_from_homography(H, K0) for H in Hs]
    theta0 = np.r_[K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2], np.zeros(5)]
    A, names = _intrinsic_map(theta0, fix_aspect_ratio, fix_principal_point, zero_tangential, fix_k3, fix_distortion)
    prob = CalibrationProblem(*_stack(Xs, xs), theta0[None], [A], [names])
    return prob, prob.pack(board_R=[R for R, _ in poses], board_t=[t for _, t in poses]), K0


def _result(prob, p, info, K0, image_size, names):
    r = info["r"].reshape(-1, 2)
    K, dist = prob.K_dist(p)
    R, t = prob.board_poses(p)
    sigma, cov = _covariance(info["J"], info["r"])
    A = prob.A[0]
    cov_theta = A @ cov[np.ix_(prob.int_cols[0], prob.int_cols[0])] @ A.T
    std = dict(zip(INTRINSIC_NAMES, np.sqrt(np.maximum(np.diag(cov_theta), 0))))
    per_view = [r[prob.view == v] for v in range(prob.n_views)]
    return CalibrationResult(
        K=K, dist=dist, R=R, t=t, rms_px=float(np.sqrt(np.mean(np.sum(r ** 2, 1)))),
        per_view_rms=np.array([np.sqrt(np.mean(np.sum(e ** 2, 1))) for e in per_view]), residuals=per_view,
        image_size=tuple(image_size), free=list(names), sigma_px=sigma, std=std, cov=cov, K_init=K0,
        n_iter=info["n_iter"], costs=info["costs"], problem=prob, p=p)


def view_influence(cal, leave_one_out=True):
    """How much each view contributes to the intrinsics: its share of the information, and K without it.

    The intrinsics' information matrix, with every board pose eliminated (the Schur complement, H&Z A6.3), is a
    sum over views, ``S = Σ_v S_v`` with ``S_v = A_vᵀA_v - A_vᵀB_v (B_vᵀB_v)⁻¹ B_vᵀA_v`` (``A_v``, ``B_v``: the
    Jacobian's rows of view v, columns of the intrinsics and of its pose). A view's **share** is
    ``tr(S_v S⁻¹) / q`` (q free intrinsics): the shares sum to 1; removing a view of share s raises the variances of
    the intrinsics by about ``1 / (1 - s)`` on average (to first order, in the metric of ``S``).

    Parameters
    ----------
    cal : CalibrationResult
    leave_one_out : bool
        Also recalibrate without each view (starting at the solution), and report the change of K.

    Returns
    -------
    dict
        ``share (V,)``; with ``leave_one_out``: ``dK (V, 4)``, the change of ``(fx, fy, cx, cy)`` in pixels when
        the view is left out, ``dK_sigma (V, 4)`` the same in standard deviations, and ``rms_px (V,)`` of the
        other views' fit.
    """
    prob = cal.problem
    J = prob.residuals_and_jacobian(cal.p)[1].tocsc()
    ic = prob.int_cols[0]
    q = len(ic)
    S_v = []
    for v in range(prob.n_views):
        rows = np.flatnonzero(np.repeat(prob.view == v, 2))
        Av, Bv = J[rows][:, ic].toarray(), J[rows][:, prob.view_cols[v]].toarray()
        S_v.append(Av.T @ Av - Av.T @ Bv @ np.linalg.solve(Bv.T @ Bv, Bv.T @ Av))
    S_inv = np.linalg.inv(np.sum(S_v, axis=0))
    out = {"share": np.array([np.trace(S @ S_inv) / q for S in S_v])}
    if leave_one_out:
        dK, rms = [], []
        sd = np.array([cal.std[k] for k in ("fx", "fy", "cx", "cy")])
        for v in range(prob.n_views):
            keep = prob.view != v
            others = [u for u in range(prob.n_views) if u != v]
            sub = CalibrationProblem(prob.X[keep], prob.x[keep], prob.cam[keep],
                                     np.searchsorted(others, prob.view[keep]), prob.theta0, prob.A,
                                     prob.intrinsic_names)
            p0 = np.r_[cal.p[ic], np.concatenate([cal.p[prob.view_cols[u]] for u in others])]
            p, info = levenberg_marquardt(sub.residuals_and_jacobian, p0)
            K = sub.K_dist(p)[0]
            dK.append(np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2]] - np.r_[cal.K[0, 0], cal.K[1, 1], cal.K[0, 2],
                                                                        cal.K[1, 2]])
            rms.append(np.sqrt(np.mean(info["r"] ** 2) * 2))
        out["dK"] = np.array(dK)
        out["dK_sigma"] = out["dK"] / np.where(sd > 0, sd, np.inf)
        out["rms_px"] = np.array(rms)
    return out


# ---------------------------------------------------------------------------------------------------------------
# a stereo rig
# ---------------------------------------------------------------------------------------------------------------

@dataclass
class StereoCalibration:
    """Two calibrated cameras and the pose of camera 2 relative to camera 1 (``x_cam2 = R @ x_cam1 + t``).

    Attributes
    ----------
    K1, dist1, K2, dist2 : ndarray
    R : (3, 3) ndarray
    t : (3,) ndarray
    rms_px : float
        Over both images, OpenCV's definition (per point).
    R_init, t_init : ndarray
        The relative pose from the separate per-view board poses, before the joint refinement.
    spread_deg : float
        Largest angle between a single pair's relative rotation and ``R_init``: views disagree when it is large.
    board_R, board_t : (V, 3, 3), (V, 3) ndarray
        Board poses in camera 1.
    std_t : (3,) ndarray
        Standard deviation of t from ``σ̂² (JᵀJ)⁻¹``.
    """

    K1: np.ndarray
    dist1: np.ndarray
    K2: np.ndarray
    dist2: np.ndarray
    R: np.ndarray
    t: np.ndarray
    rms_px: float
    R_init: np.ndarray
    t_init: np.ndarray
    spread_deg: float
    board_R: np.ndarray
    board_t: np.ndarray
    std_t: np.ndarray
    n_iter: int


def _mean_rotation(Rs):
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def calibrate_stereo(object_points, image_points1, image_points2, cal1, cal2, *, fix_intrinsics=True, max_iter=100,
                     tol=1e-12):
    """Calibrate a stereo rig: the relative pose from the board poses, then a joint refinement.

    Each view v gives the board pose in both cameras, so ``R_v = R2_v R1_vᵀ`` and ``t_v = t2_v - R_v t1_v``; their
    average (the rotation nearest to ``Σ R_v``, the mean t) starts Levenberg–Marquardt over the relative pose and
    the board poses (and, unless ``fix_intrinsics``, both cameras' intrinsics), minimising the reprojection error
    in both images at once (the problem of :class:`CalibrationProblem` with two cameras).

    Parameters
    ----------
    object_points : list of (N_v, 3)
        Board points of each view, seen in both images.
    image_points1, image_points2 : list of (N_v, 2)
        Their pixels in camera 1 and camera 2, in the same order.
    cal1, cal2 : CalibrationResult
        Each camera calibrated on its own (with the same views, in the same order).
    fix_intrinsics : bool
        Keep both cameras' K and distortion as calibrated (default). False refines them too, each camera over the
        parameters its own calibration left free: what it fixed (``fix_aspect_ratio``, ``zero_tangential``,
        ``fix_k3``, ...) stays fixed.

    Returns
    -------
    StereoCalibration

    Raises
    ------
    ValueError
        Mismatched views, or a view whose relative pose disagrees with the others by more than 10° (e.g. the
        board's corners detected in opposite orders in the two images).
    """
    Xs, x1s = _check_views(object_points, image_points1, 1, "image_points1")
    _, x2s = _check_views(object_points, image_points2, 1, "image_points2")
    if len(cal1.R) != len(Xs) or len(cal2.R) != len(Xs):
        raise ValueError(f"cal1 and cal2 must come from the same {len(Xs)} views; they have {len(cal1.R)} and "
                         f"{len(cal2.R)}")
    Rv = cal2.R @ np.swapaxes(cal1.R, 1, 2)
    tv = cal2.t - np.einsum("vij,vj->vi", Rv, cal1.t)
    R0 = _mean_rotation(Rv)
    t0 = tv.mean(0)
    ang = np.degrees(np.arccos(np.clip((np.trace(Rv @ R0.T, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    if ang.max() > 10:
        v = int(np.argmax(ang))
        raise ValueError(f"view {v}'s relative pose is {ang[v]:.1f}° from the others' average: are the corners of "
                         "this view in the same order in both images?")
    X1, xa, c1, v1 = _stack(Xs, x1s, 0)
    X2, xb, c2, v2 = _stack(Xs, x2s, 1)
    theta0 = np.stack([np.r_[c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2], c.dist] for c in (cal1, cal2)])
    if fix_intrinsics:
        A = [np.zeros((9, 0)), np.zeros((9, 0))]
        names = [[], []]
    else:                 # each camera keeps the free set of its own calibration (fx = fy, k3 = 0, ... stay so)
        A = [cal1.problem.A[0], cal2.problem.A[0]]
        names = [list(cal1.free), list(cal2.free)]
    prob = CalibrationProblem(np.vstack([X1, X2]), np.vstack([xa, xb]), np.r_[c1, c2], np.r_[v1, v2], theta0, A,
                              names)
    p0 = prob.pack(rig_R=[R0], rig_t=[t0], board_R=cal1.R, board_t=cal1.t)
    p, info = levenberg_marquardt(prob.residuals_and_jacobian, p0, max_iter=max_iter, tol=tol)
    _require_convergence(info, max_iter)
    Rc, tc = prob.rig_poses(p)
    bR, bt = prob.board_poses(p)
    r = info["r"].reshape(-1, 2)
    _, cov = _covariance(info["J"], info["r"])
    std_t = np.sqrt(np.maximum(np.diag(cov)[prob.rig_cols[1][3:]], 0))
    (K1, d1), (K2, d2) = prob.K_dist(p, 0), prob.K_dist(p, 1)
    return StereoCalibration(K1=K1, dist1=d1, K2=K2, dist2=d2, R=Rc[1], t=tc[1],
                             rms_px=float(np.sqrt(np.mean(np.sum(r ** 2, 1)))), R_init=R0, t_init=t0,
                             spread_deg=float(ang.max()), board_R=bR, board_t=bt, std_t=std_t,
                             n_iter=info["n_iter"])
