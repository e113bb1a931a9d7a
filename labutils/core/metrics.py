"""Errors against ground truth: rotation and direction angles, similarity alignment, and the
theoretical residual of a maximum-likelihood estimate."""
import numpy as np
from numpy.typing import ArrayLike

from .geometry import camera_center
from .validation import as_array, as_count, as_points, as_positive, as_rotations, as_translations, as_vector3


def _rotation_stack(R, name):
    """``R`` of shape (..., 3, 3) checked as rotations; returns the checked array with its shape kept."""
    a = as_array(R, name, "(3, 3) or (..., 3, 3)")
    if a.ndim < 2 or a.shape[-2:] != (3, 3):
        raise ValueError(f"{name} must have shape (3, 3) or (..., 3, 3); got shape {a.shape}")
    return as_rotations(a.reshape(-1, 3, 3), name).reshape(a.shape)


def rotation_error_deg(R_est: ArrayLike, R_true: ArrayLike) -> np.ndarray:
    """Angle in degrees of ``R_est @ R_true.T`` (works on stacks ``(..., 3, 3)``).

    Raises ``ValueError`` if either is not a rotation (NaN, inf, a reflection, a scaled matrix).

    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> round(float(rotation_error_deg(rotation_from_angle_axis([0, 0, np.radians(2)]), np.eye(3))), 6)
    2.0
    """
    R_est, R_true = _rotation_stack(R_est, "R_est"), _rotation_stack(R_true, "R_true")
    M = R_est @ np.swapaxes(R_true, -1, -2)
    # the chordal-safe form: atan2(|skew part|, trace part) is accurate near 0 and pi
    v = np.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], axis=-1)
    return np.degrees(np.arctan2(0.5 * np.linalg.norm(v, axis=-1), 0.5 * (np.trace(M, axis1=-2, axis2=-1) - 1)))


def angle_between_deg(a: ArrayLike, b: ArrayLike) -> float:
    """Angle in degrees between two 3-vectors (e.g. translation directions), accurate near 0.

    >>> round(float(angle_between_deg([1, 0, 0], [1, 1, 0])), 6)
    45.0
    >>> angle_between_deg([0, 0, 0], [1, 0, 0])
    Traceback (most recent call last):
    ...
    ValueError: a is the zero vector: it has no direction
    """
    a, b = as_vector3(a, "a"), as_vector3(b, "b")
    for v, name in ((a, "a"), (b, "b")):
        if not np.linalg.norm(v) > 0:
            raise ValueError(f"{name} is the zero vector: it has no direction")
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b))))


def align_similarity(src: ArrayLike, dst: ArrayLike) -> tuple:
    """Least-squares similarity ``dst ≈ s * R @ src + t`` (Umeyama 1991).

    Parameters
    ----------
    src, dst : (N, 3) array_like
        Corresponding points, N >= 3, not all collinear.

    Returns
    -------
    s : float
    R : (3, 3) ndarray
        A proper rotation.
    t : (3,) ndarray

    >>> rng = np.random.default_rng(0); A = rng.normal(size=(10, 3))
    >>> s, R, t = align_similarity(A, 2 * A + 1)
    >>> round(s, 9), np.allclose(R, np.eye(3)), np.allclose(t, 1)
    (2.0, True, True)
    """
    src = as_points(src, "src", dim=3, min_n=3)
    dst = as_points(dst, "dst", dim=3, min_n=3, like=(src, "src"))
    mu_s, mu_d = src.mean(0), dst.mean(0)
    A, B = src - mu_s, dst - mu_d
    var_s = (A ** 2).sum() / len(A)
    U, S, Vt = np.linalg.svd(B.T @ A / len(A))
    if S[1] < 1e-12 * max(S[0], 1e-300):
        raise ValueError("the points are collinear (or coincide): a similarity is not determined")
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / var_s)
    return s, R, mu_d - s * R @ mu_s


def align_cameras(R_est: ArrayLike, t_est: ArrayLike, R_true: ArrayLike, t_true: ArrayLike) -> tuple:
    """Align an estimated reconstruction to the truth by the similarity that best maps the camera centres.

    Parameters
    ----------
    R_est, R_true : (V, 3, 3) array_like
    t_est, t_true : (V, 3) array_like
        Poses, ``x_cam = R @ X + t``; V >= 3 cameras whose centres are not collinear.

    Returns
    -------
    R_aligned : (V, 3, 3) ndarray
    t_aligned : (V, 3) ndarray
        The estimated poses in the true frame (and scale).
    sim : tuple (s, R, t)
        The similarity ``X_true ≈ s R X_est + t``; apply it to points with :func:`apply_similarity`.
    """
    R_est = as_rotations(R_est, "R_est")
    R_true = as_rotations(R_true, "R_true", n=len(R_est), like_name="R_est")
    t_est = as_translations(t_est, "t_est", n=len(R_est), like_name="R_est")
    t_true = as_translations(t_true, "t_true", n=len(R_est), like_name="R_est")
    C_est = camera_center(R_est, t_est)
    s, Rs, ts = align_similarity(C_est, camera_center(R_true, t_true))
    R_al = R_est @ Rs.T
    C_al = s * C_est @ Rs.T + ts
    t_al = -np.einsum("vij,vj->vi", R_al, C_al)
    return R_al, t_al, (s, Rs, ts)


def apply_similarity(sim: tuple, X: ArrayLike) -> np.ndarray:
    """Map points ``(N, 3)`` by ``sim = (s, R, t)``: ``s R X + t`` (NaN rows stay NaN).

    >>> apply_similarity((2.0, np.eye(3), np.ones(3)), [[1.0, 0.0, 0.0]])
    array([[3., 1., 1.]])
    """
    s, R, t = sim
    X = np.asarray(X, float)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"X must have shape (N, 3) (points as rows); got shape {X.shape}")
    return s * X @ R.T + t


def pose_errors(R_est: ArrayLike, t_est: ArrayLike, R_true: ArrayLike, t_true: ArrayLike) -> tuple:
    """Per-camera errors after similarity alignment of the centres.

    Returns
    -------
    rot_deg : (V,) ndarray
        Rotation error in degrees.
    centre_rel : (V,) ndarray
        Centre error divided by the scene size (the RMS distance of the true centres from their mean).
    """
    R_al, t_al, _ = align_cameras(R_est, t_est, R_true, t_true)
    C_al = camera_center(R_al, t_al)
    C_true = camera_center(np.asarray(R_true, float), np.asarray(t_true, float))
    size = np.sqrt(((C_true - C_true.mean(0)) ** 2).sum(1).mean())
    return rotation_error_deg(R_al, R_true), np.linalg.norm(C_al - C_true, axis=1) / size


def ml_residual_bound(sigma: float, n_residuals: int, n_params: int) -> float:
    """Expected RMS residual at the ML optimum: ``sigma * sqrt(1 - d / N)`` (H&Z Result 5.2).

    For the gold-standard F from n correspondences, N = 4n image coordinates and d = 3n + 7, which
    gives ``sigma * sqrt((n - 7) / (4 n))``.

    >>> bool(np.isclose(ml_residual_bound(1.0, 4 * 50, 3 * 50 + 7), np.sqrt(43 / 200)))
    True
    """
    sigma = as_positive(sigma, "sigma", allow_zero=True)
    n_residuals, n_params = as_count(n_residuals, "n_residuals", 1), as_count(n_params, "n_params", 0)
    if n_params >= n_residuals:
        raise ValueError(f"need more residuals ({n_residuals}) than free parameters ({n_params})")
    return float(sigma * np.sqrt(1.0 - n_params / n_residuals))


def rms(r: ArrayLike) -> float:
    """Root mean square of all entries (NaN if there are none).

    >>> rms([3.0, 4.0]) ** 2
    12.5
    """
    r = as_array(r, "r", "(any shape)")
    if r.size == 0 or not np.all(np.isfinite(r)):
        raise ValueError(f"r must be a non-empty array of finite numbers; got shape {r.shape}"
                         + ("" if r.size == 0 else " with NaN or inf"))
    return float(np.sqrt(np.mean(r ** 2)))


def up_to_sign_scale(A: ArrayLike, B: ArrayLike) -> float:
    """Largest entry of ``A/‖A‖ ∓ B/‖B‖`` for the better sign: 0 when A and B agree up to scale and sign.

    F, E, H and homogeneous vectors are defined up to scale (and sign); this is the one way the workbook
    compares them.

    >>> up_to_sign_scale([[1.0, 2.0]], [[-2.0, -4.0]])
    0.0
    """
    A, B = as_array(A, "A", "(any)"), as_array(B, "B", "(any)")
    if A.shape != B.shape:
        raise ValueError(f"A and B must have the same shape; got {A.shape} and {B.shape}")
    nA, nB = np.linalg.norm(A), np.linalg.norm(B)
    if not (np.isfinite(nA) and np.isfinite(nB) and nA > 0 and nB > 0):
        raise ValueError("A and B must be finite and non-zero")
    A, B = A / nA, B / nB
    return float(min(np.abs(A - B).max(), np.abs(A + B).max()))
