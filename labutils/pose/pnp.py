"""Camera pose from known 3D points: minimal P3P (Lambda Twist), RANSAC, and non-linear refinement.

The pose maps world to camera, ``x_cam = R @ X + t``; pixels are ``K @ x_cam`` divided by depth.
References: Persson & Nordberg, "Lambda Twist: An Accurate Fast Robust Perspective Three Point (P3P)
Solver", ECCV 2018 (cited as LT); Hartley & Zisserman Sec. 7.1-7.2 (pose from known points) and
Sec. 4.7 (RANSAC).
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize
from numpy.typing import ArrayLike

from ..core.geometry import right_jacobian_so3, rotation_from_angle_axis
from ..core.ransac import ransac
from ..core.validation import (
    as_calibration,
    as_count,
    as_matrix,
    as_points,
    as_positive,
    as_rng,
    as_rotation,
)
from .p3p_scalar import _lambda_twist

# --------------------------------------------------------------------------------------------- helpers

def bearings(x: ArrayLike, K: ArrayLike) -> np.ndarray:
    """Unit viewing rays ``K⁻¹ [x; 1] / ‖·‖`` of pixels (all in front: positive z).

    Parameters
    ----------
    x : (N, 2) array_like
        Pixels.
    K : (3, 3) array_like
        Calibration (skew allowed).

    Returns
    -------
    y : (N, 3) ndarray
        Unit vectors in the camera frame.

    >>> bearings([[320., 240.]], [[800., 0, 320], [0, 800, 240], [0, 0, 1]])
    array([[0., 0., 1.]])
    """
    x = as_points(x, "x")
    K = as_calibration(K)
    r = np.linalg.solve(K, np.hstack([x, np.ones((len(x), 1))]).T).T
    r *= np.sign(r[:, 2:3])                     # K with K[2,2] < 0 would flip the rays
    return r / np.linalg.norm(r, axis=1, keepdims=True)


def reprojection_errors(X: ArrayLike, x: ArrayLike, K: ArrayLike, R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Pixel distance between ``x`` and the projection of ``X`` by one camera; ``inf`` for points not in front.

    (The multi-view version, for a whole reconstruction, is
    :meth:`labutils.sfm.Reconstruction.reprojection_errors`.)

    Parameters
    ----------
    X : (N, 3) array_like
    x : (N, 2) array_like
    K, R : (3, 3) array_like
    t : (3,) array_like

    Returns
    -------
    e : (N,) ndarray

    >>> reprojection_errors([[0., 0, 2], [0, 0, -2]], [[3., 4], [0, 0]], np.eye(3), np.eye(3), np.zeros(3))
    array([ 5., inf])
    """
    X = as_points(X, "X", dim=3)
    x = as_points(x, "x", like=(X, "X"))
    K, R, t = as_calibration(K), as_rotation(R), as_matrix(t, "t", (3,))
    return _reprojection_errors(X, x, K, R, t)


def _reprojection_errors(X, x, K, R, t):
    """The kernel of :func:`reprojection_errors` (trusts its input: the RANSAC loop calls it per hypothesis)."""
    P = X @ R.T + t
    u = P @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        d = u[:, :2] / u[:, 2:] - x
        e = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2)
    e[~(P[:, 2] > 0) | ~np.isfinite(e)] = np.inf
    return e


def _is_collinear(X, rel=1e-9):
    """True if the rows of X (N >= 2) lie on one line (or coincide), relative to their spread."""
    A = X - X.mean(0)
    s = np.linalg.svd(A, compute_uv=False)
    return s[0] == 0 or s[1] <= rel * s[0]


# ------------------------------------------------------------------------------------------------ P3P

def _cross(a, b):
    """Cross product of two 3-vectors (np.cross is slow on single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def p3p_bearings(X: ArrayLike, y: ArrayLike) -> list:
    """All poses that map three world points onto three viewing rays: Lambda Twist P3P (LT Alg. 1).

    Unknown depths ``λᵢ > 0`` put the points at ``λᵢ yᵢ`` in the camera frame. Rigid motion keeps
    distances, which gives three law-of-cosines equations ``λᵢ² + λⱼ² - 2 bᵢⱼ λᵢ λⱼ = aᵢⱼ``
    (``aᵢⱼ = ‖Xᵢ - Xⱼ‖²``, ``bᵢⱼ = yᵢ·yⱼ``). Two homogeneous combinations ``Λᵀ D₁ Λ = Λᵀ D₂ Λ = 0``
    are conics in ``Λ = (λ₁, λ₂, λ₃)``; the member ``D₀ = D₁ + γ D₂`` of their pencil with
    ``det D₀ = 0`` (a cubic in γ) is a pair of lines, which makes one unknown linear in the others.
    A quadratic then gives up to two solutions per line, up to four in all; each is polished by a few
    Gauss-Newton steps and turned into ``R, t`` by aligning two triangle edges.

    Parameters
    ----------
    X : (3, 3) array_like
        World points as rows, not collinear.
    y : (3, 3) array_like
        Their viewing rays in the camera frame as rows (any positive length; normalised here).

    Returns
    -------
    solutions : list of (R, t)
        Every real solution with all three points in front (positive depth), at most four;
        ``λᵢ yᵢ = R @ Xᵢ + t``. Empty when there is none.

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values, a zero ray, 3 coincident rays, or collinear (or coincident) world points.

    Examples
    --------
    >>> X = np.array([[0., 0, 4], [1, 0, 5], [0, 1, 6]])
    >>> sols = p3p_bearings(X, X / np.linalg.norm(X, axis=1, keepdims=True))
    >>> any(np.allclose(R, np.eye(3)) and np.allclose(t, 0) for R, t in sols)
    True
    """
    X = as_points(X, "X", dim=3, min_n=3)
    y = as_points(y, "y", dim=3, like=(X, "X"))
    if len(X) != 3:
        raise ValueError(f"P3P takes exactly 3 points; got {len(X)}")
    n = np.linalg.norm(y, axis=1)
    if np.any(n <= 0):
        raise ValueError("y has a zero-length ray")
    y = y / n[:, None]
    if max(np.linalg.norm(_cross(y[0], y[1])), np.linalg.norm(_cross(y[0], y[2]))) < 1e-10:
        raise ValueError("the 3 rays y coincide (one pixel thrice): no pose puts 3 non-collinear points on one ray")
    d12, d13, d23 = X[0] - X[1], X[0] - X[2], X[1] - X[2]
    a12, a13, a23 = d12 @ d12, d13 @ d13, d23 @ d23
    c = _cross(d12, d13)
    if min(a12, a13, a23) == 0 or c @ c <= 1e-12 * a12 * a13:      # sin² of the angle at X₁ below 1e-12
        raise ValueError("the 3 world points are collinear (or coincide): the pose is not determined")
    return _p3p_core(X, y, (a12, a13, a23), d12, d13, c)


def _p3p_sample(X, y):
    """P3P on one RANSAC sample (``X`` (3, 3), unit rays ``y`` (3, 3)): :func:`p3p_bearings` without its input checks;
    a degenerate sample (collinear or coincident points) has no solution."""
    d12, d13, d23 = X[0] - X[1], X[0] - X[2], X[1] - X[2]
    a12, a13, a23 = float(d12 @ d12), float(d13 @ d13), float(d23 @ d23)
    c = _cross(d12, d13)
    if min(a12, a13, a23) == 0 or c @ c <= 1e-12 * a12 * a13:
        return []
    return _p3p_core(X, y, (a12, a13, a23), d12, d13, c)


def _p3p_core(X, y, a, d12, d13, c):
    """Lambda Twist on a checked sample (:func:`labutils.pose.p3p_scalar._lambda_twist`, scalar arithmetic)."""
    return _lambda_twist(X, y, a, d12, d13, c)


def p3p(X: ArrayLike, x: ArrayLike, K: ArrayLike) -> list:
    """Minimal pose from three 2D-3D correspondences: Lambda Twist P3P on pixels.

    Parameters
    ----------
    X : (3, 3) array_like
        World points as rows, not collinear.
    x : (3, 2) array_like
        Their pixels.
    K : (3, 3) array_like
        Calibration (skew allowed).

    Returns
    -------
    solutions : list of (R, t)
        Up to four poses, ``x_cam = R @ X + t``, each with all three points in front and reprojecting
        them exactly (see :func:`p3p_bearings`).

    Raises
    ------
    ValueError
        Not exactly 3 points, wrong shapes, NaN/inf, singular K, or collinear world points.

    Examples
    --------
    >>> K = np.array([[800., 0, 320], [0, 800, 240], [0, 0, 1]])
    >>> X = np.array([[0., 0, 4], [1, 0, 5], [0, 1, 6]]); x = X @ K.T; x = x[:, :2] / x[:, 2:]
    >>> sols = p3p(X, x, K); 1 <= len(sols) <= 4
    True
    >>> bool(max(reprojection_errors(X, x, K, R, t).max() for R, t in sols) < 1e-9)
    True
    """
    X = as_points(X, "X", dim=3)
    x = as_points(x, "x", like=(X, "X"))
    if len(X) != 3:
        raise ValueError(f"P3P takes exactly 3 points; got {len(X)}")
    return p3p_bearings(X, bearings(x, K))


# ------------------------------------------------------------------------------------------ refinement

def pose_residuals(params, X, x, K, R0):
    """Reprojection residuals of the pose ``R = exp([w]×) R0``, ``t`` with ``params = (w, t)``.

    Parameters
    ----------
    params : (6,) array_like
        Angle-axis increment ``w`` (radians) applied to ``R0`` on the left, then ``t``.
    X : (N, 3) ndarray
    x : (N, 2) ndarray
    K, R0 : (3, 3) ndarray

    Returns
    -------
    r : (2N,) ndarray
        ``[u₀ - x₀, v₀ - y₀, u₁ - x₁, ...]`` in pixels.

    >>> K = np.eye(3); X = np.array([[0., 0, 2], [1, 0, 2], [0, 1, 3]])
    >>> pose_residuals(np.zeros(6), X, X[:, :2] / X[:, 2:], K, np.eye(3))
    array([0., 0., 0., 0., 0., 0.])
    """
    return _pose_residuals(*_check_pose_problem(params, X, x, K, R0))


def _check_pose_problem(params, X, x, K, R0):
    """The arguments of :func:`pose_residuals` and :func:`pose_jacobian`, checked (``ValueError`` by name)."""
    params = as_matrix(params, "params", (6,))
    X = as_points(X, "X", dim=3)
    x = as_points(x, "x", like=(X, "X"))
    return params, X, x, as_calibration(K, "K"), as_rotation(R0, "R0")


def _pose_residuals(params, X, x, K, R0):
    """:func:`pose_residuals` on checked input (the kernel the LM loop calls)."""
    R = rotation_from_angle_axis(params[:3]) @ R0
    u = (X @ R.T + params[3:]) @ K.T
    return (u[:, :2] / u[:, 2:] - x).ravel()


def pose_jacobian(params, X, x, K, R0):
    """Analytic Jacobian ``(2N, 6)`` of :func:`pose_residuals` with respect to ``(w, t)``.

    With ``p = R X + t`` and ``u = K p``: ``∂pix/∂p = (K[:2] - pix ⊗ K[2]) / u₃``, ``∂p/∂t = I`` and
    ``∂p/∂w = ∂(exp([w]×) q)/∂w = -exp([w]×) [q]× J_r(w) = -[R X]× exp([w]×) J_r(w)`` with
    ``q = R0 X`` and ``J_r`` the right Jacobian of SO(3) (at ``w = 0``: ``-[R X]×``).

    >>> X = np.array([[0., 0, 2], [1, 0, 2], [0, 1, 3]])
    >>> pose_jacobian(np.zeros(6), X, np.zeros((3, 2)), np.eye(3), np.eye(3)).shape
    (6, 6)
    """
    return _pose_jacobian(*_check_pose_problem(params, X, x, K, R0))


def _pose_jacobian(params, X, x, K, R0):
    """:func:`pose_jacobian` on checked input (the kernel the LM loop calls)."""
    w, t = params[:3], params[3:]
    E = rotation_from_angle_axis(w)
    RX = X @ (E @ R0).T                                   # (N, 3): R X
    u = (RX + t) @ K.T
    pix = u[:, :2] / u[:, 2:]
    A = (K[None, :2, :] - pix[:, :, None] * K[None, 2:3, :]) / u[:, 2, None, None]   # (N, 2, 3)
    S = np.zeros((len(X), 3, 3))                          # [RX]× for every point
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -RX[:, 2], RX[:, 1], -RX[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = RX[:, 2], -RX[:, 1], RX[:, 0]
    dp_dw = -S @ (E @ right_jacobian_so3(w))              # (N, 3, 3)
    J = np.concatenate([A @ dp_dw, A], axis=2)            # (N, 2, 6)
    return J.reshape(-1, 6)


def pose_covariance(X: ArrayLike, K: ArrayLike, R: ArrayLike, t: ArrayLike, sigma: float = 1.0) -> np.ndarray:
    """The covariance of a camera pose estimated from known points: ``σ² (JᵀJ)⁻¹``, the Cramér–Rao bound (H&Z Sec.
    5.2.2, backward propagation).

    With residuals ``r = u(θ) - x`` and pixels ``x = x_true + ε`` (ε Gaussian, σ per coordinate), the least-squares
    pose is off by ``δθ = (JᵀJ)⁻¹ Jᵀ ε`` to first order, with covariance ``σ² (JᵀJ)⁻¹``; no unbiased estimator does
    better. ``θ = (ω, δt)``: the rotation perturbed on the left, ``R̂ = exp([ω]×) R``, and ``t̂ = t + δt``; J (2N × 6)
    is :func:`pose_jacobian` at ω = 0: with ``p = R X + t`` and ``u = K p``, ``∂u/∂ω = A (-[R X]×)`` and
    ``∂u/∂t = A``, ``A = (K[:2] - ũ K[2]) / u₃`` (ũ the pixel).

    Parameters
    ----------
    X : (N, 3) array_like
        The known world points, N >= 3, in front of the camera.
    K, R : (3, 3) array_like
    t : (3,) array_like
    sigma : float
        Pixel noise per coordinate (0 gives the zero matrix).

    Returns
    -------
    cov : (6, 6) ndarray
        Covariance of ``(ω, δt)``: rotation (radians) first, then translation (world units).

    Raises
    ------
    ValueError
        Bad shapes or values, a point behind the camera, or a pose the points do not determine (JᵀJ singular:
        collinear points, or too few).

    Examples
    --------
    >>> X = np.array([[0., 0, 5], [1, 0, 5], [0, 1, 6], [1, 1, 4], [-1, 0.5, 5]])
    >>> cov = pose_covariance(X, np.diag([500., 500, 1]), np.eye(3), np.zeros(3), sigma=2.0)
    >>> cov.shape, bool(np.allclose(cov, cov.T)), bool(np.all(np.linalg.eigvalsh(cov) > 0))
    ((6, 6), True, True)
    """
    X = as_points(X, "X", dim=3, min_n=3)
    K = as_calibration(K, "K")
    R = as_rotation(R, "R")
    t = as_matrix(t, "t", (3,))
    sigma = as_positive(sigma, "sigma", allow_zero=True)
    depth = X @ R[2] + t[2]
    if not np.all(depth > 0):
        raise ValueError(f"X rows {np.flatnonzero(~(depth > 0))[:5].tolist()} are not in front of the camera (R, t)")
    J = _pose_jacobian(np.concatenate([np.zeros(3), t]), X, np.zeros((len(X), 2)), K, R)
    H = J.T @ J
    d = 1 / np.sqrt(np.diag(H))
    Hs = d[:, None] * H * d[None]                   # unit diagonal: radians and world units on one footing
    if np.linalg.cond(Hs) > 1e12:
        raise ValueError("the points do not determine the pose (JᵀJ is singular): collinear points, or too few")
    cov = sigma ** 2 * d[:, None] * np.linalg.inv(Hs) * d[None]
    return 0.5 * (cov + cov.T)


def refine_pose(X: ArrayLike, x: ArrayLike, K: ArrayLike, R: ArrayLike, t: ArrayLike, *, loss: str = "linear",
                f_scale: float = 1.0, max_nfev: int = 100) -> tuple:
    """Pose minimising the reprojection error (H&Z Sec. 7.2), over 6 parameters, with an analytic Jacobian.

    The rotation is updated as ``exp([w]×) R`` (an angle-axis increment, so no singularity at any
    starting rotation) and ``t`` directly; scipy's ``least_squares`` does Levenberg-Marquardt
    (``method='lm'``) for the plain squared error, a trust region for a robust loss.

    Parameters
    ----------
    X : (N, 3) array_like
        World points, N >= 3, not collinear.
    x : (N, 2) array_like
        Their pixels.
    K : (3, 3) array_like
    R : (3, 3) array_like
        Starting rotation.
    t : (3,) array_like
        Starting translation; every point must be in front of the starting camera.
    loss : {'linear', 'soft_l1', 'huber', 'cauchy', 'arctan'}
        scipy's loss on the squared residuals; ``f_scale`` (pixels) is its inlier scale.
    max_nfev : int

    Returns
    -------
    R : (3, 3) ndarray
    t : (3,) ndarray

    Raises
    ------
    ValueError
        Wrong shapes, NaN/inf, N < 3, collinear points, a point behind the starting camera, or an unknown loss.

    Examples
    --------
    >>> K = np.array([[800., 0, 320], [0, 800, 240], [0, 0, 1]])
    >>> X = np.random.default_rng(0).uniform(-1, 1, (20, 3)) + [0, 0, 6]
    >>> x = X @ K.T; x = x[:, :2] / x[:, 2:]
    >>> R, t = refine_pose(X, x, K, rotation_from_angle_axis([0.02, -0.01, 0.03]), [0.1, 0, 0])
    >>> np.allclose(R, np.eye(3), atol=1e-9) and np.allclose(t, 0, atol=1e-9)
    True
    """
    X = as_points(X, "X", dim=3, min_n=3)
    x = as_points(x, "x", like=(X, "X"))
    K = as_calibration(K)
    R0 = as_rotation(R, "R")
    t0 = as_matrix(t, "t", (3,))
    f_scale = as_positive(f_scale, "f_scale")
    max_nfev = as_count(max_nfev, "max_nfev", 1)
    if loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
        raise ValueError(f"loss must be one of 'linear', 'soft_l1', 'huber', 'cauchy', 'arctan'; got {loss!r}")
    if _is_collinear(X):
        raise ValueError("X is collinear (or all points coincide): the rotation about that line is not determined")
    behind = np.flatnonzero(X @ R0[2] + t0[2] <= 0)
    if behind.size:
        raise ValueError(f"{behind.size} of the {len(X)} points are behind the starting camera "
                         f"(rows {behind[:5].tolist()})")
    res = scipy.optimize.least_squares(
        _pose_residuals, np.concatenate([np.zeros(3), t0]), jac=_pose_jacobian, args=(X, x, K, R0),
        method="lm" if loss == "linear" else "trf", loss=loss, f_scale=f_scale, max_nfev=max_nfev,
        x_scale="jac")
    R_new = rotation_from_angle_axis(res.x[:3]) @ R0
    U, _, Vt = np.linalg.svd(R_new)
    return U @ Vt, res.x[3:].copy()


# ------------------------------------------------------------------------------------------------ RANSAC

@dataclass
class PnPResult:
    """What :func:`pnp_ransac` returns.

    Attributes
    ----------
    R : (3, 3) ndarray
    t : (3,) ndarray
        The pose, ``x_cam = R @ X + t``.
    inliers : (N,) bool ndarray
        Correspondences reprojecting within the threshold (after refinement, if any).
    n_iter : int
        RANSAC samples drawn.
    n_refine : int
        Refinement rounds.
    ransac_inliers : (N,) bool ndarray
        The inliers of the best RANSAC sample, before refinement.
    converged, p_chance : bool, float
        RANSAC reached its ``confidence``; its chance bound (:class:`labutils.core.ransac.RansacResult`).
    """

    R: np.ndarray
    t: np.ndarray
    inliers: np.ndarray = field(repr=False)
    n_iter: int
    n_refine: int
    ransac_inliers: np.ndarray = field(repr=False)
    converged: bool = True
    p_chance: float = np.nan

    @property
    def n_inliers(self):
        return int(self.inliers.sum())


def pnp_ransac(X: ArrayLike, x: ArrayLike, K: ArrayLike, *, rng: np.random.Generator, threshold_px: float = 2.0,
               confidence: float = 0.9999, max_iter: int = 10000, refine: bool = True) -> PnPResult:
    """Robust pose from 2D-3D correspondences: P3P in adaptive RANSAC, then refinement (H&Z Sec. 4.7, 7.2).

    Each minimal sample of 3 correspondences gives up to four P3P poses (:func:`p3p_bearings`);
    the generic loop (:func:`labutils.core.ransac`) scores every one by its inlier count, which also
    picks the right one of the four (no fourth point needed). A correspondence is an inlier when it
    reprojects within ``threshold_px`` pixels and lies in front of the camera. The loop stops once a
    sample free of outliers has been drawn with probability ``confidence`` (H&Z eq. 4.18). With
    ``refine`` the pose is then refined on the inliers (:func:`refine_pose`), the inliers are
    recomputed, and this is repeated until the set stops changing (at most 5 times). Pixels unrelated to the
    points (uniform in their ``w × h`` bounding box) would be inliers of a pose with probability at most
    ``π threshold_px² / (w h)``: a pose no better than that is refused (:mod:`labutils.core.ransac`).

    Parameters
    ----------
    X : (N, 3) array_like
        World points, N >= 4, not all collinear.
    x : (N, 2) array_like
        Their pixels (some may be wrong).
    K : (3, 3) array_like
        Calibration (skew allowed).
    rng : numpy.random.Generator
        Required.
    threshold_px : float
        Inlier threshold on the reprojection error in pixels.
    confidence : float
        In (0, 1).
    max_iter : int
        Most samples drawn.
    refine : bool

    Returns
    -------
    PnPResult
        ``.R, .t, .inliers`` and how it got there.

    Raises
    ------
    ValueError
        Wrong shapes, NaN/inf, N < 4, all points collinear, all pixels coincident, no ``rng``, every sample
        degenerate, or no pose better than chance (e.g. pure noise).

    Examples
    --------
    >>> rng = np.random.default_rng(0); K = np.array([[800., 0, 320], [0, 800, 240], [0, 0, 1]])
    >>> X = rng.uniform(-1, 1, (30, 3)) + [0, 0, 6]; x = X @ K.T; x = x[:, :2] / x[:, 2:]
    >>> x[:5] = rng.uniform(0, 640, (5, 2))
    >>> res = pnp_ransac(X, x, K, rng=rng)
    >>> bool(np.allclose(res.R, np.eye(3), atol=1e-9)), res.n_inliers, bool(res.inliers[5:].all()), res.converged
    (True, 25, True, True)
    """
    X = as_points(X, "X", dim=3, min_n=4)
    x = as_points(x, "x", like=(X, "X"), min_n=4)
    K = as_calibration(K)
    as_rng(rng)
    threshold_px = as_positive(threshold_px, "threshold_px")
    if _is_collinear(X):
        raise ValueError("all world points are collinear (or coincide): the pose is not determined")
    if (spread := np.ptp(x, axis=0)).max() <= threshold_px:
        raise ValueError(f"all pixels x coincide (within {spread.max():.3g} px <= threshold_px): no pose is determined")
    y = bearings(x, K)

    def fit(idx):                               # checked once above: the loop calls the kernels
        return _p3p_sample(X[idx], y[idx])

    def errors(model):
        return _reprojection_errors(X, x, K, *model)

    chance = min(1.0, np.pi * threshold_px**2 / max(spread.prod(), 1e-9))     # the disc's share of the pixels' box
    (R, t), inliers, n_iter = rr = ransac(len(X), 3, fit, errors, threshold_px, rng=rng, confidence=confidence,
                                          max_iter=max_iter, chance=chance)
    ransac_inliers = inliers.copy()
    if inliers.sum() < 4:
        raise ValueError(f"no pose explains more than the 3 sampled points ({n_iter} samples): "
                         "too many outliers or a threshold too small")
    n_refine = 0
    while refine and n_refine < 5:
        n_refine += 1
        R, t = refine_pose(X[inliers], x[inliers], K, R, t)
        new = reprojection_errors(X, x, K, R, t) < threshold_px
        if new.sum() < 4 or np.array_equal(new, inliers):
            break
        inliers = new
    return PnPResult(R=R, t=t, inliers=inliers, n_iter=n_iter, n_refine=n_refine, ransac_inliers=ransac_inliers,
                     converged=rr.converged, p_chance=rr.p_chance)
