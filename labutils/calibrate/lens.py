"""The lens: OpenCV's camera model with distortion (Brown–Conrady), its inverse, and projection.

A point ``x_cam`` in the camera frame is seen at

    (x, y) = x_cam[:2] / x_cam[2]                                                (normalised coordinates)
    r² = x² + y²,   radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
    x_d = x · radial + 2 p1 x y + p2 (r² + 2 x²)
    y_d = y · radial + p1 (r² + 2 y²) + 2 p2 x y                                 (:func:`distort`)
    u = fx x_d + cx,   v = fy y_d + cy                                            (zero skew, like OpenCV)

``dist = (k1, k2, p1, p2, k3)``, OpenCV's order, so that the numbers compare with ``cv2.calibrateCamera``.
"""
import numpy as np

from ..core.validation import as_array, as_calibration, as_matrix, as_points, as_rotation, as_vector3

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


# ---------------------------------------------------------------------------------------------------------------
# the distortion model
# ---------------------------------------------------------------------------------------------------------------

def as_distortion(dist, name="dist"):
    """``(k1, k2, p1, p2, k3)`` as a finite ``(5,)`` array (4 numbers: k3 = 0; None: no distortion), or ``ValueError``.

    >>> as_distortion([0.1, 0.0, 0.0, 0.0])
    array([0.1, 0. , 0. , 0. , 0. ])
    """
    d = as_array(dist, name, "(5,)").ravel() if dist is not None else np.zeros(5)
    if d.size == 4:
        d = np.r_[d, 0.0]
    if d.shape != (5,):
        raise ValueError(f"{name} must hold 5 numbers (k1, k2, p1, p2, k3) or 4 (k3 = 0); got shape {np.shape(dist)}")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"{name} has non-finite entries (NaN or inf)")
    return d


def as_intrinsics(K, name="K"):
    """A calibration matrix (:func:`labutils.core.validation.as_calibration`) that is also upper triangular with
    positive focal lengths, as the camera model here needs, or ``ValueError``."""
    K = as_calibration(K, name)
    if K[1, 0] != 0:
        raise ValueError(f"{name} must be upper triangular; got K[1, 0] = {K[1, 0]:.6g}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{name} must have positive focal lengths; got fx = {K[0, 0]:.6g}, fy = {K[1, 1]:.6g}")
    return K


def distort(xn, dist, jac=False):
    """Apply OpenCV's lens distortion to normalised image points (Brown–Conrady; see the module docstring).

    Parameters
    ----------
    xn : (N, 2) array_like
        Ideal normalised coordinates ``x_cam[:2] / x_cam[2]``.
    dist : (5,) array_like
        ``(k1, k2, p1, p2, k3)`` (4 numbers: k3 = 0).
    jac : bool
        Also return the derivatives.

    Returns
    -------
    xd : (N, 2) ndarray
        Distorted normalised coordinates.
    d_xn : (N, 2, 2) ndarray
        ``∂xd/∂xn`` (only with ``jac=True``).
    d_dist : (N, 2, 5) ndarray
        ``∂xd/∂(k1, k2, p1, p2, k3)`` (only with ``jac=True``).

    Examples
    --------
    >>> distort([[0.5, 0.0]], [-0.2, 0, 0, 0, 0])          # 0.5 · (1 - 0.2 · 0.25)
    array([[0.475, 0.   ]])
    >>> distort([[0.1, -0.2]], np.zeros(5))
    array([[ 0.1, -0.2]])
    """
    return apply_distortion(as_points(xn, "xn", min_n=0), as_distortion(dist), jac)


def apply_distortion(xn, dist, jac=False):
    """:func:`distort` without the input checks (the inner loop of calibration); same arguments and returns."""
    k1, k2, p1, p2, k3 = dist
    x, y = xn[:, 0], xn[:, 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = np.column_stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                          y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y])
    if not jac:
        return xd
    d_radial_dr2 = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    d_xn = np.empty((len(xn), 2, 2))
    d_xn[:, 0, 0] = radial + 2 * x * x * d_radial_dr2 + 2 * p1 * y + 6 * p2 * x
    d_xn[:, 0, 1] = 2 * x * y * d_radial_dr2 + 2 * p1 * x + 2 * p2 * y
    d_xn[:, 1, 0] = 2 * x * y * d_radial_dr2 + 2 * p1 * x + 2 * p2 * y
    d_xn[:, 1, 1] = radial + 2 * y * y * d_radial_dr2 + 6 * p1 * y + 2 * p2 * x
    if jac == "xn":
        return xd, d_xn
    d_dist = np.empty((len(xn), 2, 5))
    d_dist[:, 0, 0], d_dist[:, 1, 0] = x * r2, y * r2
    d_dist[:, 0, 1], d_dist[:, 1, 1] = x * r2 ** 2, y * r2 ** 2
    d_dist[:, 0, 2], d_dist[:, 1, 2] = 2 * x * y, r2 + 2 * y * y
    d_dist[:, 0, 3], d_dist[:, 1, 3] = r2 + 2 * x * x, 2 * x * y
    d_dist[:, 0, 4], d_dist[:, 1, 4] = x * r2 ** 3, y * r2 ** 3
    return xd, d_xn, d_dist


def undistort_normalised(xd, dist, max_iter=50, tol=1e-13):
    """Invert :func:`distort` by Newton's method: the ideal normalised points seen at ``xd``.

    The model has no closed-form inverse. Newton's method with the 2×2 Jacobian of :func:`distort`, started at
    ``xd``, converges in a few steps wherever the model is invertible (OpenCV's ``undistortPoints`` uses a
    fixed-point iteration instead, which is slower to converge for strong distortion).

    Parameters
    ----------
    xd : (N, 2) array_like
        Distorted normalised coordinates.
    dist : (5,) array_like
    max_iter : int
    tol : float
        Stop when every point reproduces ``xd`` to ``tol`` (normalised units).

    Returns
    -------
    xn : (N, 2) ndarray

    Raises
    ------
    ValueError
        If a point does not converge: it lies where the distortion model folds over (beyond the radius where
        ``r_d(r)`` stops increasing), so no unique ideal point maps to it.

    Examples
    --------
    >>> dist = [-0.3, 0.1, 0.001, -0.002, 0.02]
    >>> xn = np.array([[0.3, -0.2], [0.0, 0.0], [-0.5, 0.4]])
    >>> bool(np.abs(undistort_normalised(distort(xn, dist), dist) - xn).max() < 1e-12)
    True
    """
    xd = as_points(xd, "xd", min_n=0)
    dist = as_distortion(dist)
    xn = xd.copy()
    todo = np.arange(len(xd))                  # points not converged yet
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            if not todo.size:
                break
            f, J = apply_distortion(xn[todo], dist, jac="xn")
            e = f - xd[todo]
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            xn[todo, 0] -= (J[:, 1, 1] * e[:, 0] - J[:, 0, 1] * e[:, 1]) / det
            xn[todo, 1] -= (-J[:, 1, 0] * e[:, 0] + J[:, 0, 0] * e[:, 1]) / det
            todo = todo[~(np.abs(e).max(axis=1) < tol)]
        if len(xd):
            ok = np.all(np.isfinite(xn), axis=1)
            f, J = apply_distortion(np.where(ok[:, None], xn, 0.0), dist, jac="xn")
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            # converged, and on the branch where the model is still one-to-one (it preserves orientation there)
            ok &= (np.abs(f - xd).max(axis=1) < 1e3 * tol) & (det > 0)
            bad = np.flatnonzero(~ok)
            if bad.size:
                raise ValueError(f"cannot undistort {bad.size} of {len(xd)} points (e.g. row {bad[0]}, xd = "
                                 f"{xd[bad[0]].round(4).tolist()}): they lie where the distortion "
                                 f"{dist.round(5).tolist()} is not invertible (the model folds over beyond some "
                                 "radius)")
    return xn


def undistort_points(x, K, dist, K_new=None):
    """Pixels of a distorted image → pixels of the ideal (undistorted) pinhole camera ``K_new``.

    Parameters
    ----------
    x : (N, 2) array_like
        Measured pixels.
    K : (3, 3) array_like
    dist : (5,) array_like
    K_new : (3, 3) array_like, optional
        The ideal camera (default ``K``); the identity gives normalised coordinates.

    Returns
    -------
    (N, 2) ndarray

    Examples
    --------
    >>> K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]]); dist = [-0.2, 0.05, 0, 0, 0]
    >>> x = project_points([[0.1, 0.05, 1.0]], K, dist, np.eye(3), np.zeros(3))
    >>> undistort_points(x, K, dist).round(9)
    array([[370., 265.]])
    """
    x = as_points(x, "x", min_n=0)
    K = as_intrinsics(K)
    K_new = K if K_new is None else as_matrix(K_new, "K_new", (3, 3))
    xd = (x - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T
    xn = undistort_normalised(xd, dist)
    xh = np.hstack([xn, np.ones((len(xn), 1))]) @ K_new.T
    return xh[:, :2] / xh[:, 2:]


def project_points(X, K, dist, R, t):
    """Project world points through a camera with lens distortion: ``(N, 3) -> (N, 2)`` pixels.

    ``x_cam = R @ X + t``, then the model of the module docstring. Zero skew: ``K[0, 1]`` must be 0.

    Raises
    ------
    ValueError
        If a point is not in front of the camera (depth <= 0).

    Examples
    --------
    >>> K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]])
    >>> project_points([[0.0, 0.0, 2.0], [0.2, 0.0, 2.0]], K, np.zeros(5), np.eye(3), np.zeros(3))
    array([[320., 240.],
           [370., 240.]])
    """
    X = as_points(X, "X", dim=3, min_n=0)
    K = as_intrinsics(K)
    if K[0, 1] != 0:
        raise ValueError(f"K must have zero skew (K[0, 1] = 0) for this model; got {K[0, 1]:.6g}")
    R = as_rotation(R, "R")
    t = as_vector3(t, "t")
    Xc = X @ R.T + t
    if np.any(Xc[:, 2] <= 0):
        bad = np.flatnonzero(Xc[:, 2] <= 0)
        raise ValueError(f"{bad.size} points are not in front of the camera (depth <= 0), e.g. row {bad[0]}")
    xd = distort(Xc[:, :2] / Xc[:, 2:], dist)
    return xd * [K[0, 0], K[1, 1]] + K[:2, 2]
