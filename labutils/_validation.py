"""Input checks shared by every module: clear ``ValueError`` messages that name the argument."""
import numpy as np


def as_points(x, name, dim=2, min_n=1, like=None):
    """Return ``x`` as a float ``(N, dim)`` array, or raise ``ValueError`` naming the problem.

    Parameters
    ----------
    x : array_like
        Points as rows.
    name : str
        The argument's name, used in the error message.
    dim : int
        Columns expected (2 for pixels, 3 for world points).
    min_n : int
        Fewest rows accepted.
    like : ndarray, optional
        When given, ``x`` must have as many rows as ``like``.

    Examples
    --------
    >>> as_points([[1, 2], [3, 4]], "x1").shape
    (2, 2)
    >>> as_points([[1, 2, 3]], "x1")
    Traceback (most recent call last):
    ...
    ValueError: x1 must have shape (N, 2) (points as rows); got shape (1, 3)
    """
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape (N, {dim}): {exc}") from None
    if a.ndim != 2 or a.shape[1] != dim:
        raise ValueError(f"{name} must have shape (N, {dim}) (points as rows); got shape {a.shape}")
    if like is not None and a.shape[0] != np.shape(like)[0]:
        raise ValueError(f"{name} has {a.shape[0]} points but the other point set has {np.shape(like)[0]}: "
                         "correspondences must pair up row by row")
    if a.shape[0] < min_n:
        raise ValueError(f"{name} has {a.shape[0]} points; at least {min_n} are needed")
    if not np.all(np.isfinite(a)):
        bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
        raise ValueError(f"{name} has non-finite coordinates (NaN or inf) in rows {bad[:5].tolist()}"
                         + (" ..." if bad.size > 5 else ""))
    return a


def as_matrix(M, name, shape):
    """Return ``M`` as a finite float array of exactly ``shape``, or raise ``ValueError``.

    Examples
    --------
    >>> as_matrix(np.eye(3), "K", (3, 3)).dtype
    dtype('float64')
    """
    try:
        a = np.asarray(M, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {shape}: {exc}") from None
    if a.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}; got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has non-finite entries (NaN or inf)")
    return a


def as_rotation(R, name="R", tol=1e-6):
    """Return ``R`` as a (3, 3) rotation (orthonormal, det +1), or raise ``ValueError``."""
    a = as_matrix(R, name, (3, 3))
    if np.abs(a @ a.T - np.eye(3)).max() > tol or np.linalg.det(a) < 0:
        raise ValueError(f"{name} must be a rotation matrix (orthonormal, det +1)")
    return a
