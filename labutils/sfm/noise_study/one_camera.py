"""One camera with known points (notebook 06, section 1): the Cramér–Rao prediction of its pose error and the Monte
Carlo that tests it. No gauge here: the known points fix the frame.

:func:`labutils.pose.pose_covariance` is the prediction ``σ² (JᵀJ)⁻¹`` for the pose error ``(φ, δt)``,
:func:`one_camera_trials` the Monte Carlo of P3P-RANSAC on noisy pixels, :func:`pose_error_vectors` the measured
errors, and :func:`nees` the normalised estimation error squared that tests the whole covariance (its mean is 6 when
the prediction is right).
"""
import numpy as np

from ...core.geometry import angle_axis_from_rotation
from ...core.validation import (
    as_array,
    as_calibration,
    as_count,
    as_matrix,
    as_points,
    as_positive,
    as_rng,
    as_rotation,
    as_rotations,
    as_translations,
)
from ...pose.pnp import pnp_ransac


def pose_error_vectors(R_est, t_est, R_true, t_true):
    """Pose errors as vectors ``(φ, δt)``: ``R_est = exp([φ]×) R_true`` and ``δt = t_est - t_true``.

    Parameters
    ----------
    R_est : (T, 3, 3) array_like
    t_est : (T, 3) array_like
        Estimates (e.g. one per Monte Carlo trial).
    R_true : (3, 3) array_like
    t_true : (3,) array_like

    Returns
    -------
    e : (T, 6) ndarray
        Radians and world units, the parameters of :func:`labutils.pose.pose_covariance`.

    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> e = pose_error_vectors(rotation_from_angle_axis([[0.01, 0, 0]]), [[0, 0, 1.5]], np.eye(3), [0, 0, 1])
    >>> np.round(e, 12)
    array([[0.01, 0.  , 0.  , 0.  , 0.  , 0.5 ]])
    """
    R_est = as_rotations(R_est, "R_est")
    t_est = as_translations(t_est, "t_est", n=len(R_est), like_name="R_est")
    R_true = as_rotation(R_true, "R_true")
    t_true = as_matrix(t_true, "t_true", (3,))
    return np.hstack([angle_axis_from_rotation(R_est @ R_true.T), t_est - t_true])


def nees(errors, cov):
    """Normalised estimation error squared, ``eᵀ Σ⁻¹ e`` for each error vector (Bar-Shalom et al., Sec. 5.4).

    When the errors are Gaussian with covariance ``cov`` each value is χ² with ``d`` degrees of freedom (``d`` the
    length of ``e``): mean ``d``, variance ``2 d``. Its mean over many trials tests the *whole* predicted covariance
    (scale, shape and correlations), not only its trace.

    Parameters
    ----------
    errors : (T, d) array_like
    cov : (d, d) array_like
        Symmetric positive definite.

    Returns
    -------
    (T,) ndarray

    >>> nees([[1.0, 0.0], [0.0, 2.0]], np.diag([1.0, 4.0]))
    array([1., 1.])
    """
    cov = as_array(cov, "cov", "(d, d)")
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1] or not np.all(np.isfinite(cov)):
        raise ValueError(f"cov must be a finite square (d, d) matrix; got shape {cov.shape}")
    e = as_points(errors, "errors", dim=cov.shape[0])
    try:
        L = np.linalg.cholesky(0.5 * (cov + cov.T))
    except np.linalg.LinAlgError:
        raise ValueError("cov is not positive definite") from None
    w = np.linalg.solve(L, e.T)
    return np.sum(w * w, axis=0)


def one_camera_trials(X, x_true, K, R, t, sigmas, n_trials, *, rng, threshold_sigmas=4.0):
    """Monte Carlo of one camera's pose from known points: P3P-RANSAC and refinement on noisy pixels (notebook 03).

    For each σ, ``n_trials`` times: add Gaussian noise of σ px to ``x_true``, estimate the pose with
    :func:`labutils.pose.pnp_ransac` (threshold ``threshold_sigmas · σ``, at least 1 px: no inlier is lost to it),
    and record the error vector of :func:`pose_error_vectors`.

    Parameters
    ----------
    X : (N, 3) array_like
    x_true : (N, 2) array_like
        The points and their noise-free pixels in the camera ``(R, t)``.
    K, R : (3, 3) array_like
    t : (3,) array_like
    sigmas : sequence of float
        Pixel noise levels, > 0.
    n_trials : int
    rng : numpy.random.Generator

    Returns
    -------
    dict float -> (n_trials, 6) ndarray
        The errors ``(φ, δt)`` of each trial.

    Examples
    --------
    >>> rng = np.random.default_rng(0); K = np.diag([800., 800, 1])
    >>> X = rng.uniform(-1, 1, (30, 3)) + [0, 0, 6]; x = X @ K.T; x = x[:, :2] / x[:, 2:]
    >>> e = one_camera_trials(X, x, K, np.eye(3), np.zeros(3), [0.5, 1.0], 3, rng=rng)
    >>> sorted(e), e[1.0].shape
    ([0.5, 1.0], (3, 6))
    """
    as_rng(rng)
    X = as_points(X, "X", dim=3, min_n=4)
    x_true = as_points(x_true, "x_true", like=(X, "X"))
    K = as_calibration(K, "K")
    R = as_rotation(R, "R")
    t = as_matrix(t, "t", (3,))
    n_trials = as_count(n_trials, "n_trials", 1)
    sigmas = as_array(sigmas, "sigmas", "(S,)")
    if sigmas.ndim != 1 or sigmas.size == 0:
        raise ValueError(f"sigmas must be a non-empty 1-D array of pixel noises; got shape {sigmas.shape}")
    sigmas = [as_positive(float(s), "sigmas") for s in sigmas]
    out = {}
    for s in sigmas:
        Rs, ts = np.empty((n_trials, 3, 3)), np.empty((n_trials, 3))
        for k in range(n_trials):
            x = x_true + rng.normal(scale=s, size=x_true.shape)
            pose = pnp_ransac(X, x, K, rng=rng, threshold_px=max(1.0, threshold_sigmas * s))
            Rs[k], ts[k] = pose.R, pose.t
        out[float(s)] = pose_error_vectors(Rs, ts, R, t)
    return out
