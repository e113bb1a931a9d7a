"""Homogeneous coordinates, rotations and pinhole cameras.

Conventions (see the package docstring): ``x_cam = R @ X + t``, ``C = -R.T @ t``,
``P = K @ [R | t]``; points are rows; a homogeneous copy has the suffix ``_h``.
"""
import numpy as np
import scipy.linalg

from ._validation import as_matrix, as_points


def homogeneous(x):
    """Append a column of ones: ``(N, d) -> (N, d + 1)``.

    >>> homogeneous(np.zeros((2, 2)))
    array([[0., 0., 1.],
           [0., 0., 1.]])
    """
    x = np.asarray(x, dtype=float)
    return np.hstack([x, np.ones((x.shape[0], 1))])


def dehomogeneous(x_h):
    """Divide by the last column and drop it: ``(N, d + 1) -> (N, d)``.

    >>> dehomogeneous(np.array([[2., 4., 2.]]))
    array([[1., 2.]])
    """
    x_h = np.asarray(x_h, dtype=float)
    return x_h[:, :-1] / x_h[:, -1:]


def skew(v):
    """The cross-product matrix ``[v]×`` with ``skew(v) @ w == np.cross(v, w)`` (H&Z A4.5).

    >>> skew([1., 2., 3.]) @ np.array([4., 5., 6.])
    array([-3.,  6., -3.])
    """
    x, y, z = np.asarray(v, dtype=float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation_from_angle_axis(w):
    """Rotation matrix from an angle-axis vector ``w`` (angle ``|w|`` in radians; Rodrigues' formula).

    Parameters
    ----------
    w : (3,) array_like

    Returns
    -------
    R : (3, 3) ndarray

    >>> np.round(rotation_from_angle_axis([0, 0, np.pi / 2]), 6)
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    """
    w = np.asarray(w, dtype=float).reshape(3)
    theta = np.linalg.norm(w)
    if theta < 1e-12:
        return np.eye(3) + skew(w)
    k = skew(w / theta)
    return np.eye(3) + np.sin(theta) * k + (1 - np.cos(theta)) * (k @ k)


def angle_axis_from_rotation(R):
    """Angle-axis vector of a rotation matrix (inverse of :func:`rotation_from_angle_axis`).

    >>> w = np.array([0.1, -0.2, 0.3])
    >>> np.allclose(angle_axis_from_rotation(rotation_from_angle_axis(w)), w)
    True
    """
    R = as_matrix(R, "R", (3, 3))
    cos = np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)
    theta = np.arccos(cos)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if theta < 1e-6:
        return 0.5 * v
    if np.pi - theta < 1e-4:
        # near pi: axis from the symmetric part, sign fixed by v
        B = (R + np.eye(3)) / 2
        axis = B[np.argmax(np.diag(B))]
        axis = axis / np.linalg.norm(axis)
        if axis @ v < 0:
            axis = -axis
        return theta * axis
    return theta / (2 * np.sin(theta)) * v


def P_from_KRt(K, R, t):
    """Camera matrix ``P = K @ [R | t]`` (H&Z eq. 6.8).

    >>> P_from_KRt(np.eye(3), np.eye(3), np.zeros(3)).shape
    (3, 4)
    """
    K = as_matrix(K, "K", (3, 3))
    R = as_matrix(R, "R", (3, 3))
    t = as_matrix(np.asarray(t, dtype=float).reshape(-1), "t", (3,))
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


def project(P, X):
    """Project world points through ``P``: ``(N, 3) -> (N, 2)`` pixels.

    >>> project(np.hstack([np.eye(3), np.zeros((3, 1))]), [[2., 4., 2.]])
    array([[1., 2.]])
    """
    P = as_matrix(P, "P", (3, 4))
    X = np.asarray(X, dtype=float).reshape(-1, 3)
    return dehomogeneous(homogeneous(X) @ P.T)


def camera_center(R, t):
    """Camera centre ``C = -R.T @ t`` in world coordinates.

    >>> camera_center(np.eye(3), [1., 2., 3.])
    array([-1., -2., -3.])
    """
    return -np.asarray(R, dtype=float).T @ np.asarray(t, dtype=float).reshape(3)


def relative_pose(R1, t1, R2, t2):
    """Pose of camera 2 in the frame of camera 1: ``x_cam2 = R @ x_cam1 + t``.

    Returns ``R = R2 @ R1.T`` and ``t = t2 - R @ t1``: with camera 1 as ``[I | 0]`` camera 2 is ``[R | t]``.

    >>> R, t = relative_pose(np.eye(3), np.zeros(3), np.eye(3), np.ones(3))
    >>> t
    array([1., 1., 1.])
    """
    R1, R2 = np.asarray(R1, float), np.asarray(R2, float)
    R = R2 @ R1.T
    return R, np.asarray(t2, float).reshape(3) - R @ np.asarray(t1, float).reshape(3)


def depths(R, t, X):
    """Depth ``(R @ X + t)[2]`` of each world point in a camera: ``(N, 3) -> (N,)``."""
    X = as_points(X, "X", dim=3)
    return X @ np.asarray(R, float)[2] + np.asarray(t, float).reshape(3)[2]
