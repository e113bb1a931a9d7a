"""Triangulation: linear (DLT) from two or more views (H&Z Sec. 12.2).

The optimal two-view method (H&Z Sec. 12.5) lives here too when it is added.
"""
import numpy as np

from ._validation import as_matrix, as_points


def _normalise_rows(A):
    return A / np.linalg.norm(A, axis=-1, keepdims=True)


def triangulate(P1, P2, x1, x2):
    """Linear (DLT) triangulation of corresponding pixels in two views (H&Z Sec. 12.2).

    Each point solves ``A X_h = 0`` with the four rows ``x P[2] - P[0]`` and ``y P[2] - P[1]`` of
    both cameras (rows scaled to unit norm), by SVD.

    Parameters
    ----------
    P1, P2 : (3, 4) array_like
        Camera matrices.
    x1, x2 : (N, 2) array_like
        Corresponding pixels.

    Returns
    -------
    X : (N, 3) ndarray
        World points (a point at infinity comes back with huge coordinates).

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values, mismatched lengths, or two identical cameras (no baseline).

    Examples
    --------
    >>> P1 = np.hstack([np.eye(3), np.zeros((3, 1))]); P2 = np.hstack([np.eye(3), [[-1.], [0], [0]]])
    >>> triangulate(P1, P2, [[0.2, 0.1]], [[0.0, 0.1]])
    array([[1. , 0.5, 5. ]])
    """
    P1, P2 = as_matrix(P1, "P1", (3, 4)), as_matrix(P2, "P2", (3, 4))
    x1 = as_points(x1, "x1")
    x2 = as_points(x2, "x2", like=x1)
    M1, M2 = P1 / np.linalg.norm(P1), P2 / np.linalg.norm(P2)
    if min(np.linalg.norm(M1 - M2), np.linalg.norm(M1 + M2)) < 1e-12:
        raise ValueError("P1 and P2 are the same camera: no baseline, nothing can be triangulated")
    return triangulate_multiview(np.stack([P1, P2]), np.stack([x1, x2]))


def triangulate_multiview(Ps, xs):
    """Linear (DLT) triangulation from V views, with missing observations (H&Z Sec. 12.2).

    Parameters
    ----------
    Ps : (V, 3, 4) array_like
        Camera matrices.
    xs : (V, N, 2) array_like
        Pixels of N points in each view, NaN where a view does not see a point.

    Returns
    -------
    X : (N, 3) ndarray
        NaN for points seen in fewer than two views.

    Examples
    --------
    >>> Ps = np.stack([np.hstack([np.eye(3), [[-c], [0], [0]]]) for c in (0., 1., 2.)])
    >>> X = np.array([[1.0, 0.5, 5.0]]); xs = np.stack([(X[:, :2] - [c, 0]) / 5 for c in (0., 1., 2.)])
    >>> xs[2, 0] = np.nan
    >>> np.round(triangulate_multiview(Ps, xs), 9)
    array([[1. , 0.5, 5. ]])
    """
    Ps = np.asarray(Ps, dtype=float)
    xs = np.asarray(xs, dtype=float)
    if Ps.ndim != 3 or Ps.shape[1:] != (3, 4):
        raise ValueError(f"Ps must have shape (V, 3, 4); got {Ps.shape}")
    if xs.ndim != 3 or xs.shape[0] != Ps.shape[0] or xs.shape[2] != 2:
        raise ValueError(f"xs must have shape (V, N, 2) with V = {Ps.shape[0]}; got {xs.shape}")
    if not np.all(np.isfinite(Ps)):
        raise ValueError("Ps has non-finite entries")
    seen = np.all(np.isfinite(xs), axis=-1)                      # (V, N)
    x = np.where(seen[..., None], xs, 0.0)
    # rows (V, N, 2, 4): x * P[2] - P[0], y * P[2] - P[1]
    A = x[..., None] * Ps[:, None, 2:3, :] - Ps[:, None, :2, :]
    A = _normalise_rows(A) * seen[..., None, None]
    A = A.transpose(1, 0, 2, 3).reshape(xs.shape[1], -1, 4)      # (N, 2V, 4)
    _, _, Vt = np.linalg.svd(A)
    X_h = Vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = X_h[:, :3] / X_h[:, 3:]
    X[seen.sum(0) < 2] = np.nan
    return X
