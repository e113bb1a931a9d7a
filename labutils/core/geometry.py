"""Homogeneous coordinates, rotations and pinhole cameras.

Conventions (see the package docstring): ``x_cam = R @ X + t``, ``C = -R.T @ t``,
``P = K @ [R | t]``; points are rows; a homogeneous copy has the suffix ``_h``.
"""
import math

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from .validation import as_array, as_calibration, as_camera_matrix, as_matrix, as_points, as_rotation, as_rotations


def homogeneous(x: ArrayLike) -> np.ndarray:
    """Append a column of ones: ``(N, d) -> (N, d + 1)``.

    >>> homogeneous(np.zeros((2, 2)))
    array([[0., 0., 1.],
           [0., 0., 1.]])
    """
    x = as_array(x, "x", "(N, 2) or (N, 3)")
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise ValueError(f"x must have shape (N, 2) or (N, 3) (points as rows); got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("x has non-finite coordinates (NaN or inf)")
    return np.hstack([x, np.ones((x.shape[0], 1))])


def dehomogeneous(x_h: ArrayLike) -> np.ndarray:
    """Divide by the last column and drop it: ``(N, d + 1) -> (N, d)``.

    A point at infinity (last coordinate 0) has no finite coordinates: ``ValueError`` names its rows.

    >>> dehomogeneous(np.array([[2., 4., 2.]]))
    array([[1., 2.]])
    """
    x_h = as_array(x_h, "x_h", "(N, 3) or (N, 4)")
    if x_h.ndim != 2 or x_h.shape[1] not in (3, 4):
        raise ValueError(f"x_h must have shape (N, 3) or (N, 4) (homogeneous points as rows); got shape {x_h.shape}")
    if not np.all(np.isfinite(x_h)):
        raise ValueError("x_h has non-finite coordinates (NaN or inf)")
    inf = np.flatnonzero(x_h[:, -1] == 0)
    if inf.size:
        raise ValueError(f"x_h rows {inf[:5].tolist()} have last coordinate 0: points at infinity")
    return x_h[:, :-1] / x_h[:, -1:]


def skew(v: ArrayLike) -> np.ndarray:
    """The cross-product matrix ``[v]×`` with ``skew(v) @ w == np.cross(v, w)`` (H&Z A4.5), of one vector or of each
    row of a stack.

    Parameters
    ----------
    v : (3,) or (N, 3) array_like

    Returns
    -------
    (3, 3) or (N, 3, 3) ndarray

    >>> skew([1., 2., 3.]) @ np.array([4., 5., 6.])
    array([-3.,  6., -3.])
    >>> skew(np.eye(3)).shape
    (3, 3, 3)
    """
    v = as_array(v, "v", "(3,) or (N, 3)")
    if v.shape != (3,) and not (v.ndim == 2 and v.shape[1] == 3):
        raise ValueError(f"v must have shape (3,) or (N, 3); got {v.shape}" + (" (transposed?)" if v.ndim == 2
                                                                             and v.shape[0] == 3 else ""))
    if not np.all(np.isfinite(v)):
        raise ValueError("v must be finite (no NaN or inf)")
    return _skew(v)


def _skew(v):
    """``[v]×`` without checks, for a (3,) vector or an (N, 3) stack (the loops inside the package)."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = np.zeros_like(x)
    return np.stack([np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2)


def _aa_coefficients(theta):
    """``sin θ/θ``, ``(1 - cos θ)/θ²``, ``(θ - sin θ)/θ³``, accurate near θ = 0."""
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    t2 = theta ** 2
    a = np.where(small, 1 - t2 / 6, np.sin(th) / th)
    b = np.where(small, 0.5 - t2 / 24, (1 - np.cos(th)) / th ** 2)
    c = np.where(small, 1 / 6 - t2 / 120, (th - np.sin(th)) / th ** 3)
    return a, b, c


def _angle_axis_stack(w, name):
    """``w`` as a finite ``(n, 3)`` array and whether it was a single ``(3,)`` vector."""
    w = as_array(w, name, "(3,) or (V, 3)")
    single = w.shape == (3,)
    if not single and (w.ndim != 2 or w.shape[1] != 3):
        raise ValueError(f"{name} must have shape (3,) or (V, 3) (angle-axis vectors as rows); got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"{name} has non-finite entries (NaN or inf)")
    return (w[None], True) if single else (w, False)


def rotation_from_angle_axis(w: ArrayLike) -> np.ndarray:
    """Rotation matrix from an angle-axis vector, ``R = exp([w]×)`` (Rodrigues' formula; H&Z A4.3.2).

    The angle is ``|w|`` radians about the axis ``w / |w|``. Vectorised: a stack of vectors gives a stack of
    rotations.

    Parameters
    ----------
    w : (3,) or (V, 3) array_like

    Returns
    -------
    R : (3, 3) or (V, 3, 3) ndarray

    Examples
    --------
    >>> np.round(rotation_from_angle_axis([0, 0, np.pi / 2]), 6) + 0.0
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    >>> rotation_from_angle_axis(np.zeros((4, 3))).shape
    (4, 3, 3)
    """
    w, single = _angle_axis_stack(w, "w")
    if single:                      # one rotation: the same formula without the stacking (called in inner loops)
        x, y, z = w[0]
        theta = math.sqrt(x * x + y * y + z * z)
        a, b, _ = (float(c) for c in _aa_coefficients(theta))
        W = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
        return np.eye(3) + a * W + b * (W @ W)
    a, b, _ = _aa_coefficients(np.linalg.norm(w, axis=1))
    W = _skew(w)
    return np.eye(3) + a[:, None, None] * W + b[:, None, None] * (W @ W)


def angle_axis_from_rotation(R: ArrayLike) -> np.ndarray:
    """Angle-axis vector of a rotation matrix, the inverse of :func:`rotation_from_angle_axis` (angle in [0, π]).

    Parameters
    ----------
    R : (3, 3) or (V, 3, 3) array_like
        Rotations (orthonormal, det +1, to 1e-4: nearer than that, the nearest rotation is taken).

    Returns
    -------
    w : (3,) or (V, 3) ndarray

    Raises
    ------
    ValueError
        If a matrix is not a rotation (e.g. ``2 I``, a reflection, zeros) or has non-finite entries.

    Examples
    --------
    >>> w = np.array([0.1, -0.2, 0.3])
    >>> np.allclose(angle_axis_from_rotation(rotation_from_angle_axis(w)), w)
    True
    >>> angle_axis_from_rotation(np.diag([1.0, 1.0, -1.0]))
    Traceback (most recent call last):
    ...
    ValueError: R is not a rotation matrix (orthonormal with det +1): ...
    """
    R = as_array(R, "R", "(3, 3) or (V, 3, 3)")
    single = R.shape == (3, 3)
    Rs = as_rotations(R[None] if single else R, "R")
    # sin θ · axis from the skew part, cos θ from the trace: θ = atan2 of the two is accurate at every angle.
    v = np.stack([Rs[:, 2, 1] - Rs[:, 1, 2], Rs[:, 0, 2] - Rs[:, 2, 0], Rs[:, 1, 0] - Rs[:, 0, 1]], axis=1)
    sin = 0.5 * np.linalg.norm(v, axis=1)
    cos = 0.5 * (np.trace(Rs, axis1=1, axis2=2) - 1)
    theta = np.arctan2(sin, cos)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(sin[:, None] > 0, theta[:, None] * v / (2 * sin[:, None]), 0.0)
        # 0.1 <= θ <= 3: arccos is as accurate, and gives the same bits as before (fits started from it repeat)
        mid = (cos <= np.cos(0.1)) & (cos >= np.cos(3.0))
        th = np.arccos(cos[mid])
        out[mid] = (th / (2 * np.sin(th)))[:, None] * v[mid]
    # beyond 3 the skew part shrinks as sin θ: the axis from the symmetric part, (1 - cos θ) a aᵀ
    wide = np.flatnonzero(cos < np.cos(3.0))
    if wide.size:
        S = 0.5 * (Rs[wide] + np.swapaxes(Rs[wide], 1, 2)) - cos[wide, None, None] * np.eye(3)
        j = np.argmax(np.diagonal(S, axis1=1, axis2=2), axis=1)
        axis = S[np.arange(wide.size), :, j]
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        axis *= np.where(np.einsum("ni,ni->n", axis, v[wide]) < 0, -1.0, 1.0)[:, None]
        out[wide] = theta[wide, None] * axis
    return out[0] if single else out


def left_jacobian_so3(w: ArrayLike) -> np.ndarray:
    """Left Jacobian of SO(3), ``J_l(ω) = I + (1 - cos θ)/θ² [ω]× + (θ - sin θ)/θ³ [ω]×²``.

    It maps a change of the angle-axis vector to the rotation change applied on the **left**:
    ``exp([ω + δ]×) ≈ exp([J_l(ω) δ]×) exp([ω]×)``, hence ``∂(R(ω) X)/∂ω = -[R X]× J_l(ω)`` (bundle adjustment,
    where the parameters are the angle-axis vectors themselves). The right Jacobian is its transpose.

    Parameters
    ----------
    w : (3,) or (V, 3) array_like

    Returns
    -------
    J : (3, 3) or (V, 3, 3) ndarray

    Examples
    --------
    >>> w, d = np.array([0.3, -0.2, 0.5]), 1e-7 * np.array([1.0, 2.0, -1.0])
    >>> lhs = rotation_from_angle_axis(w + d)
    >>> rhs = rotation_from_angle_axis(left_jacobian_so3(w) @ d) @ rotation_from_angle_axis(w)
    >>> bool(np.abs(lhs - rhs).max() < 1e-12)
    True
    """
    w, single = _angle_axis_stack(w, "w")
    _, b, c = _aa_coefficients(np.linalg.norm(w, axis=1))
    W = _skew(w)
    J = np.eye(3) + b[:, None, None] * W + c[:, None, None] * (W @ W)
    return J[0] if single else J


def right_jacobian_so3(w: ArrayLike) -> np.ndarray:
    """Right Jacobian of SO(3), ``J_r(ω) = J_l(-ω) = J_l(ω)ᵀ``: ``exp([ω + δ]×) ≈ exp([ω]×) exp([J_r(ω) δ]×)``.

    The same idea as :func:`left_jacobian_so3` with the small rotation applied on the **right** (in the body
    frame). The two are tied by ``exp([ω]×) J_r(ω) = J_l(ω)``, so the derivative of ``exp([ω]×) Y`` with respect
    to ``ω`` has two equal forms: ``-[exp([ω]×) Y]× exp([ω]×) J_r(ω)``, as pose refinement writes it
    (notebook 03, :func:`labutils.pose.pose_jacobian`), and ``-[exp([ω]×) Y]× J_l(ω)``, as bundle adjustment
    does (notebook 04, :func:`labutils.bundle.reprojection_jacobian`).

    Examples
    --------
    >>> w = np.array([0.3, -0.2, 0.5])
    >>> bool(np.allclose(right_jacobian_so3(w), left_jacobian_so3(w).T))
    True
    """
    w, single = _angle_axis_stack(w, "w")
    J = left_jacobian_so3(-w)
    return J[0] if single else J


def P_from_KRt(K: ArrayLike, R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Camera matrix ``P = K @ [R | t]`` (H&Z eq. 6.8).

    >>> P_from_KRt(np.eye(3), np.eye(3), np.zeros(3)).shape
    (3, 4)
    """
    K = as_matrix(K, "K", (3, 3))
    as_calibration(K, "K")
    R = as_rotation(R, "R")
    t = as_matrix(t, "t", (3,))
    return K @ np.hstack([R, t[:, None]])


def KRt_from_P(P):
    """Split ``P`` into ``K, R, t`` by RQ decomposition (H&Z Sec. 6.2.4).

    K is upper triangular with a positive diagonal and ``K[2, 2] == 1``; R is a proper rotation
    (det +1). P is defined up to scale, so its sign is chosen to make det R = +1; the points
    in front of the camera are then those with ``(R @ X + t)[2] > 0`` — for the dinosaur data set
    read :func:`labutils.data.load_dino`, whose world frame is mirrored.

    Parameters
    ----------
    P : (3, 4) array_like

    Returns
    -------
    K : (3, 3) ndarray
    R : (3, 3) ndarray
    t : (3,) ndarray

    >>> K0 = np.array([[800., 2, 320], [0, 780, 240], [0, 0, 1]])
    >>> R0 = rotation_from_angle_axis([0.1, 0.2, -0.3]); t0 = np.array([1., 2, 3])
    >>> K, R, t = KRt_from_P(-2.0 * P_from_KRt(K0, R0, t0))
    >>> np.allclose(K, K0) and np.allclose(R, R0) and np.allclose(t, t0)
    True
    """
    P = as_matrix(P, "P", (3, 4))
    M = P[:, :3]
    if abs(np.linalg.det(M)) <= 1e-12 * np.abs(M).max() ** 3:
        raise ValueError("P has a singular left 3x3 block: it is not a finite projective camera")
    K, R = scipy.linalg.rq(M)
    D = np.diag(np.sign(np.diag(K)))
    K, R = K @ D, D @ R
    t = np.linalg.solve(K, P[:, 3])
    if np.linalg.det(R) < 0:
        R, t = -R, -t
    K = K / K[2, 2]
    return K, R, t


def project(P: ArrayLike, X: ArrayLike) -> np.ndarray:
    """Project world points through ``P``: ``(N, 3) -> (N, 2)`` pixels.

    A point on the camera's principal plane (depth 0) projects to infinity: ``ValueError`` names it.

    >>> project(np.hstack([np.eye(3), np.zeros((3, 1))]), [[2., 4., 2.]])
    array([[1., 2.]])
    >>> project(np.hstack([np.eye(3), np.zeros((3, 1))]), [[2., 4.]])
    Traceback (most recent call last):
    ...
    ValueError: X must have shape (N, 3) (points as rows); got shape (1, 2)
    """
    P = as_camera_matrix(P, "P")
    X = as_points(X, "X", dim=3)
    x_h = X @ P[:, :3].T + P[:, 3]
    bad = np.flatnonzero(x_h[:, 2] == 0)
    if bad.size:
        raise ValueError(f"X rows {bad[:5].tolist()} lie on the camera's principal plane (depth 0): "
                         "their images are at infinity")
    return x_h[:, :2] / x_h[:, 2:]


def camera_center(R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Camera centre ``C = -Rᵀ t`` in world coordinates, for one camera or a stack.

    Parameters
    ----------
    R : (3, 3) or (V, 3, 3) array_like
    t : (3,) or (V, 3) array_like

    Returns
    -------
    C : (3,) or (V, 3) ndarray
        NaN rows stay NaN (an unregistered camera of a reconstruction).

    >>> camera_center(np.eye(3), [1., 2., 3.])
    array([-1., -2., -3.])
    >>> camera_center(np.stack([np.eye(3)] * 2), np.ones((2, 3))).shape
    (2, 3)
    """
    R, t = as_array(R, "R", "(3, 3) or (V, 3, 3)"), as_array(t, "t", "(3,) or (V, 3)")
    if np.isinf(R).any() or np.isinf(t).any():
        raise ValueError("R and t must not hold inf (NaN marks a camera that is not there)")
    if R.shape == (3, 3) and t.shape == (3,):
        return -np.einsum("vji,vj->vi", _registered_rotations(R[None]), t[None])[0]
    if R.ndim != 3 or R.shape[1:] != (3, 3) or t.shape != (R.shape[0], 3):
        raise ValueError(f"R and t must have shapes (3, 3) and (3,), or (V, 3, 3) and (V, 3); got {R.shape} and "
                         f"{t.shape}" + (" — t transposed?" if t.shape == (3, R.shape[0]) else ""))
    return -np.einsum("vji,vj->vi", _registered_rotations(R), t)


def _registered_rotations(R):
    """The rows of a ``(V, 3, 3)`` stack that are finite, checked as rotations; NaN rows kept as they are."""
    ok = np.all(np.isfinite(R), axis=(1, 2))
    if ok.all():
        return as_rotations(R, "R")
    R = R.copy()
    R[ok] = as_rotations(R[ok], "R")
    return R


def relative_pose(R1: ArrayLike, t1: ArrayLike, R2: ArrayLike, t2: ArrayLike) -> tuple:
    """Pose of camera 2 in the frame of camera 1: ``x_cam2 = R @ x_cam1 + t``.

    Returns ``R = R2 @ R1.T`` and ``t = t2 - R @ t1``: with camera 1 as ``[I | 0]`` camera 2 is ``[R | t]``.

    >>> R, t = relative_pose(np.eye(3), np.zeros(3), np.eye(3), np.ones(3))
    >>> t
    array([1., 1., 1.])
    """
    R1, R2 = as_rotation(R1, "R1"), as_rotation(R2, "R2")
    t1, t2 = as_matrix(t1, "t1", (3,)), as_matrix(t2, "t2", (3,))
    R = R2 @ R1.T
    return R, t2 - R @ t1


def depths(R: ArrayLike, t: ArrayLike, X: ArrayLike) -> np.ndarray:
    """Depth ``(R @ X + t)[2]`` of each world point in a camera: ``(N, 3) -> (N,)``.

    >>> depths(np.eye(3), np.zeros(3), [[0., 0., 2.]])
    array([2.])
    """
    X = as_points(X, "X", dim=3)
    return X @ as_rotation(R, "R")[2] + as_matrix(t, "t", (3,))[2]


def pixels_and_depths(K: ArrayLike, R: ArrayLike, t: ArrayLike, X: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(N, 2)`` and depths ``(N,)`` of world points in one camera ``K [R | t]``; NaN rows of ``X`` stay NaN,
    and a point at depth 0 projects to inf.

    >>> x, z = pixels_and_depths(np.eye(3), np.eye(3), np.zeros(3), [[2., 4., 2.], [np.nan] * 3])
    >>> x.tolist(), z.tolist()
    ([[1.0, 2.0], [nan, nan]], [2.0, nan])
    """
    K, R, t = as_calibration(K, "K"), as_rotation(R, "R"), as_matrix(t, "t", (3,))
    X = as_array(X, "X", "(N, 3)")
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"X must have shape (N, 3) (points as rows); got shape {X.shape}")
    c = X @ R.T + t
    with np.errstate(divide="ignore", invalid="ignore"):
        q = c @ K.T
        return q[:, :2] / q[:, 2:], c[:, 2]
