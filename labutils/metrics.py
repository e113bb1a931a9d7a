"""Errors against ground truth: rotation and direction angles, similarity alignment, and the
theoretical residual of a maximum-likelihood estimate."""
import numpy as np

from ._validation import as_points


def rotation_error_deg(R_est, R_true):
    """Angle in degrees of ``R_est @ R_true.T`` (works on stacks ``(..., 3, 3)``).

    >>> from labutils.geometry import rotation_from_angle_axis
    >>> round(float(rotation_error_deg(rotation_from_angle_axis([0, 0, np.radians(2)]), np.eye(3))), 6)
    2.0
    """
    R_est, R_true = np.asarray(R_est, float), np.asarray(R_true, float)
    M = R_est @ np.swapaxes(R_true, -1, -2)
    # the chordal-safe form: atan2(|skew part|, trace part) is accurate near 0 and pi
    v = np.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], axis=-1)
    return np.degrees(np.arctan2(0.5 * np.linalg.norm(v, axis=-1), 0.5 * (np.trace(M, axis1=-2, axis2=-1) - 1)))


def angle_between_deg(a, b):
    """Angle in degrees between two vectors (e.g. translation directions), accurate near 0.

    >>> round(float(angle_between_deg([1, 0, 0], [1, 1, 0])), 6)
    45.0
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b)))


def align_similarity(src, dst):
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
    dst = as_points(dst, "dst", dim=3, min_n=3, like=src)
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


def align_cameras(R_est, t_est, R_true, t_true):
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
    R_est, R_true = np.asarray(R_est, float), np.asarray(R_true, float)
    t_est, t_true = np.asarray(t_est, float), np.asarray(t_true, float)
    C_est = -np.einsum("vji,vj->vi", R_est, t_est)
    C_true = -np.einsum("vji,vj->vi", R_true, t_true)
    s, Rs, ts = align_similarity(C_est, C_true)
    R_al = R_est @ Rs.T
    C_al = s * C_est @ Rs.T + ts
    t_al = -np.einsum("vij,vj->vi", R_al, C_al)
    return R_al, t_al, (s, Rs, ts)


def apply_similarity(sim, X):
    """Map points ``(N, 3)`` by ``sim = (s, R, t)``: ``s R X + t``."""
    s, R, t = sim
    return s * np.asarray(X, float) @ R.T + t


def pose_errors(R_est, t_est, R_true, t_true):
    """Per-camera errors after similarity alignment of the centres.

    Returns
    -------
    rot_deg : (V,) ndarray
        Rotation error in degrees.
    centre_rel : (V,) ndarray
        Centre error divided by the scene size (the RMS distance of the true centres from their mean).
    """
    R_al, t_al, _ = align_cameras(R_est, t_est, R_true, t_true)
    C_al = -np.einsum("vji,vj->vi", R_al, t_al)
    C_true = -np.einsum("vji,vj->vi", np.asarray(R_true, float), np.asarray(t_true, float))
    size = np.sqrt(((C_true - C_true.mean(0)) ** 2).sum(1).mean())
    return rotation_error_deg(R_al, R_true), np.linalg.norm(C_al - C_true, axis=1) / size


def ml_residual_bound(sigma, n_residuals, n_params):
    """Expected RMS residual at the ML optimum: ``sigma * sqrt(1 - d / N)`` (H&Z Result 5.2).

    For the gold-standard F from n correspondences, N = 4n image coordinates and d = 3n + 7, which
    gives ``sigma * sqrt((n - 7) / (4 n))``.

    >>> bool(np.isclose(ml_residual_bound(1.0, 4 * 50, 3 * 50 + 7), np.sqrt(43 / 200)))
    True
    """
    if n_params >= n_residuals:
        raise ValueError(f"need more residuals ({n_residuals}) than free parameters ({n_params})")
    return float(sigma * np.sqrt(1.0 - n_params / n_residuals))


def rms(r):
    """Root mean square of all entries."""
    r = np.asarray(r, float)
    return float(np.sqrt(np.mean(r ** 2)))
