"""Input checks shared by every module: clear ``ValueError`` messages that name the argument, what was expected
and what it got. Nothing here reshapes silently: a ``(3, V)`` array where ``(V, 3)`` is expected is an error."""
import numbers
import warnings

import numpy as np


def as_array(x, name, expected):
    """``x`` as a float array (any shape), or ``ValueError`` naming ``name`` and the ``expected`` shape when it is not
    numeric (a string, a ragged list).

    Complex and boolean arrays are refused, never cast (a complex number's imaginary part would be dropped, and
    ``True`` would pass as 1).

    >>> as_array([1 + 2j, 3], "x", "(N,)")
    Traceback (most recent call last):
    ...
    ValueError: x must be real; got a complex array (dtype complex128) of shape (2,): ...
    """
    if isinstance(x, (str, bytes)):
        raise ValueError(f"{name} must be a numeric array of shape {expected}; got the string {x!r:.40}")
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {expected}: {exc}") from None
    if raw.dtype.kind == "c":
        raise ValueError(f"{name} must be real; got a complex array (dtype {raw.dtype}) of shape {raw.shape}: "
                         "take .real only if the imaginary part is known to be zero")
    if raw.dtype.kind == "b" or raw.dtype == object and any(isinstance(v, (bool, np.bool_)) for v in raw.flat):
        raise ValueError(f"{name} must be a numeric array of shape {expected}; got booleans (dtype {raw.dtype})")
    try:
        a = np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array of shape {expected}: {exc}") from None
    return a


_as_float_array = as_array


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
    like : ndarray or (ndarray, str), optional
        When given, ``x`` must have as many rows as ``like`` (an array, or an array and its argument's name, which
        the message then names).

    Examples
    --------
    >>> as_points([[1, 2], [3, 4]], "x1").shape
    (2, 2)
    >>> as_points([[1, 2, 3]], "x1")
    Traceback (most recent call last):
    ...
    ValueError: x1 must have shape (N, 2) (points as rows); got shape (1, 3)
    """
    a = _as_float_array(x, name, f"(N, {dim})")
    if a.ndim != 2 or a.shape[1] != dim:
        hint = " — transposed? points are rows" if a.ndim == 2 and a.shape[0] == dim else ""
        raise ValueError(f"{name} must have shape (N, {dim}) (points as rows); got shape {a.shape}{hint}")
    if like is not None:
        other, other_name = like if isinstance(like, tuple) else (like, "the other point set")
        if a.shape[0] != np.shape(other)[0]:
            raise ValueError(f"{name} has {a.shape[0]} points but {other_name} has {np.shape(other)[0]}: "
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
    >>> as_matrix([1.0, np.nan, 0.0], "t", (3,))
    Traceback (most recent call last):
    ...
    ValueError: t has non-finite entries (NaN or inf)
    """
    a = _as_float_array(M, name, tuple(shape))
    if a.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}; got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has non-finite entries (NaN or inf)")
    return a


def as_vector3(t, name="t"):
    """A finite ``(3,)`` vector; a ``(3, 1)`` or ``(1, 3)`` array is refused (say ``t.ravel()`` if you mean it).

    >>> as_vector3([1, 2, 3]).shape
    (3,)
    """
    return as_matrix(t, name, (3,))


ROTATION_TOL = 1e-4   # largest |R Rᵀ - I| read as a rotation: published cameras print 6 digits (1e-6 off)
_ROUNDOFF = 1e-9      # closer than this: round-off of a computed rotation, returned as it is, without a word


class RotationProjectedWarning(UserWarning):
    """A matrix within :data:`ROTATION_TOL` of SO(3) was replaced by the nearest rotation (one line: the argument
    and the largest correction)."""


def as_rotation(R, name="R", tol=ROTATION_TOL):
    """Return ``R`` as a (3, 3) rotation (orthonormal, det +1), or raise ``ValueError``; within ``tol`` of one, the
    nearest rotation (see :func:`as_rotations`).

    >>> as_rotation(2 * np.eye(3))
    Traceback (most recent call last):
    ...
    ValueError: R is not a rotation matrix (orthonormal with det +1): |R Rᵀ - I| = 3, det R = 8
    """
    return as_rotations(as_matrix(R, name, (3, 3))[None], name, tol)[0]


def nearest_rotations(M):
    """The rotations nearest (Frobenius) to a ``(V, 3, 3)`` stack of near-rotations: ``U Vᵀ`` of each SVD."""
    U, _, Vt = np.linalg.svd(M)
    return U @ Vt


def as_rotations(R, name="R", tol=ROTATION_TOL, n=None, like_name=None):
    """Return ``R`` as a ``(V, 3, 3)`` stack of rotations, or raise ``ValueError`` naming the first bad one. The
    rule wherever a rotation is read: off SO(3) by round-off (1e-9), returned as it is; by at most ``tol`` (1e-4:
    printed to 6 digits), replaced by the nearest rotation (SVD) with a one-line :class:`RotationProjectedWarning`
    naming the argument and the largest correction; beyond ``tol``, or det < 0, an error.

    >>> as_rotations(np.stack([np.eye(3), -np.eye(3)]))
    Traceback (most recent call last):
    ...
    ValueError: R[1] is not a rotation matrix (orthonormal with det +1): |R Rᵀ - I| = 0, det R = -1
    """
    expected = "(V, 3, 3)" if n is None else f"({n}, 3, 3)"
    a = _as_float_array(R, name, expected)
    if a.ndim != 3 or a.shape[1:] != (3, 3) or (n is not None and a.shape[0] != n):
        match = f" to match {like_name}" if like_name and n is not None else ""
        raise ValueError(f"{name} must have shape {expected}{match}; got shape {a.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(a), axis=(1, 2)))
    if bad.size:
        who = f"{name}[{bad[0]}]" if len(a) > 1 or n is not None else name
        raise ValueError(f"{who} has non-finite entries (NaN or inf)")
    err = np.abs(a @ np.swapaxes(a, 1, 2) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(a)
    bad = np.flatnonzero((err > tol) | (det <= 0))
    if bad.size:
        k = int(bad[0])
        who = f"{name}[{k}]" if len(a) > 1 or n is not None else name
        raise ValueError(f"{who} is not a rotation matrix (orthonormal with det +1): "
                         f"|R Rᵀ - I| = {err[k]:.3g}, det R = {det[k]:.3g}")
    off = np.flatnonzero(err > _ROUNDOFF)
    if off.size:
        a = a.copy()
        near = nearest_rotations(a[off])
        change = np.abs(near - a[off]).max(axis=(1, 2))
        a[off] = near
        k = int(off[np.argmax(change)])
        who = f"{name}[{k}]" if len(a) > 1 or n is not None else name
        many = f" (and {off.size - 1} more)" if off.size > 1 else ""
        warnings.warn(f"{who} is {err[k]:.2g} off a rotation (within the tolerance {tol:g}){many}: replaced by the "
                      f"nearest rotation, largest correction {change.max():.2g}", RotationProjectedWarning,
                      stacklevel=3)
    return a


def as_translations(t, name="t", n=None, like_name=None):
    """Return ``t`` as a finite ``(V, 3)`` array (rows are the cameras' translations), or raise ``ValueError``.

    A ``(3, V)`` array (one column per camera) is refused with a hint, unless V = 3 makes the two readings
    indistinguishable: then the rows are read as the translations, as documented everywhere.

    >>> as_translations(np.zeros((3, 5)), n=5)
    Traceback (most recent call last):
    ...
    ValueError: t must have shape (5, 3) (one translation per row); got shape (3, 5) — transposed?
    """
    expected = "(V, 3)" if n is None else f"({n}, 3)"
    a = _as_float_array(t, name, expected)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        hint = " — transposed?" if a.ndim == 2 and a.shape[0] == 3 and (n is None or a.shape[1] == n) else ""
        match = f" to match the {n} rotations of {like_name}" if like_name and n is not None else ""
        raise ValueError(f"{name} must have shape {expected} (one translation per row{match}); got shape "
                         f"{a.shape}{hint}")
    bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
    if bad.size:
        raise ValueError(f"{name} has non-finite entries (NaN or inf) in rows {bad[:5].tolist()}")
    return a


def as_calibration(K, name="K", n_views=None, like_name=None):
    """A calibration matrix (or a stack), scaled so that ``K[2, 2] == 1``, or ``ValueError``.

    Parameters
    ----------
    K : (3, 3) or (V, 3, 3) array_like
        Skew allowed. Checked: finite, last row ``(0, 0, k)`` with ``k != 0``, invertible, and positive focal
        lengths ``K[0, 0] / k``, ``K[1, 1] / k`` (an RQ split whose signs were not fixed gives negative ones).
    name : str
    n_views : int, optional
        When given, a ``(3, 3)`` K is repeated for ``n_views`` views and a stack must have ``n_views`` entries;
        the result is then always ``(n_views, 3, 3)``.

    Returns
    -------
    (3, 3) or (V, 3, 3) ndarray

    Examples
    --------
    >>> as_calibration(2 * np.eye(3))[2, 2]
    np.float64(1.0)
    >>> as_calibration(np.eye(3), n_views=4).shape
    (4, 3, 3)
    >>> as_calibration(np.diag([800.0, 0.0, 1.0]))
    Traceback (most recent call last):
    ...
    ValueError: K is singular (det = 0): a calibration matrix must be invertible
    >>> as_calibration(np.diag([-800.0, -800.0, 1.0]))
    Traceback (most recent call last):
    ...
    ValueError: K must have positive focal lengths; got fx = -800, fy = -800 (with K[2, 2] = 1): ...
    """
    expected = "(3, 3)" if n_views is None else f"(3, 3) or ({n_views}, 3, 3)"
    a = _as_float_array(K, name, expected)
    single = a.shape == (3, 3)
    if single and n_views is not None:
        a = np.repeat(a[None], n_views, axis=0)
    elif not single and (a.ndim != 3 or a.shape[1:] != (3, 3) or n_views is None or a.shape[0] != n_views):
        match = f" (one per view of {like_name})" if like_name and n_views is not None else ""
        raise ValueError(f"{name} must have shape {expected}{match}; got shape {a.shape}")
    stack = a.reshape(-1, 3, 3)
    for k, Km in enumerate(stack):
        who = name if len(stack) == 1 or single else f"{name}[{k}]"
        if not np.all(np.isfinite(Km)):
            raise ValueError(f"{who} has non-finite entries (NaN or inf)")
        scale = np.abs(Km).max()
        if scale == 0:
            raise ValueError(f"{who} is all zeros (singular): not a calibration matrix")
        if np.any(np.abs(Km[2, :2]) > 1e-12 * scale) or Km[2, 2] == 0:
            raise ValueError(f"{who} is not a calibration matrix: its last row must be (0, 0, k) with k != 0; "
                             f"got {Km[2].tolist()}")
        Kn = Km / Km[2, 2]
        det = np.linalg.det(Kn)
        if abs(det) <= 1e-12 * np.abs(Kn).max() ** 3:
            raise ValueError(f"{who} is singular (det = {det:.3g}): a calibration matrix must be invertible")
        if Kn[0, 0] <= 0 or Kn[1, 1] <= 0:
            raise ValueError(f"{who} must have positive focal lengths; got fx = {Kn[0, 0]:.6g}, fy = {Kn[1, 1]:.6g} "
                             "(with K[2, 2] = 1): after an RQ split, flip the signs so that diag(K) > 0 "
                             "(negate the columns of K and the rows of R together)")
    out = stack / stack[:, 2:3, 2:3]
    return out[0] if single and n_views is None else out.reshape(a.shape)


def as_fundamental(F, name="F"):
    """F as a (3, 3) array of rank 2 with unit Frobenius norm, plus its right and left null vectors.

    Returns
    -------
    F : (3, 3) ndarray
        The nearest rank-2 matrix, scaled to unit norm (it differs from the input by at most 1e-7 relative).
    e1, e2 : (3,) ndarray
        ``F e1 = 0`` and ``e2ᵀ F = 0`` (the epipoles).

    Raises
    ------
    ValueError
        Wrong shape, non-finite entries, rank < 2, or clearly rank 3 (enforce rank 2 first).

    >>> as_fundamental(np.eye(3))
    Traceback (most recent call last):
    ...
    ValueError: F does not have rank 2 (singular values [1. 1. 1.] after scaling): enforce rank 2 first ...
    """
    F = as_matrix(F, name, (3, 3))
    U, s, Vt = np.linalg.svd(F)
    if s[0] == 0 or s[1] < 1e-12 * s[0]:
        raise ValueError(f"{name} has rank < 2 (singular values {s}): it is not a fundamental matrix")
    if s[2] > 1e-7 * s[0]:
        raise ValueError(f"{name} does not have rank 2 (singular values {s / s[0]} after scaling): "
                         "enforce rank 2 first (H&Z Sec. 11.1.1)")
    return (U[:, :2] * (s[:2] / s[0])) @ Vt[:2] / np.linalg.norm(s[:2] / s[0]), Vt[2], U[:, 2]


def as_essential(E, name="E", tol=1e-5):
    """``E`` as a finite (3, 3) essential matrix, or ``ValueError``: singular values (s, s, 0) within ``tol``
    relative (H&Z Result 9.17); ``E = I`` or a ``K2ᵀ F K1`` not projected onto the manifold is refused.

    >>> as_essential(np.eye(3))
    Traceback (most recent call last):
    ...
    ValueError: E is not an essential matrix: its singular values relative to the largest are [1. 1. 1.]; ...
    """
    E = as_matrix(E, name, (3, 3))
    s = np.linalg.svd(E, compute_uv=False)
    if s[0] == 0 or s[1] <= 1e-12 * s[0]:
        raise ValueError(f"{name} has rank < 2 (singular values {s}): not an essential matrix")
    if s[2] > tol * s[0] or s[0] - s[1] > tol * s[0]:
        raise ValueError(f"{name} is not an essential matrix: its singular values relative to the largest are "
                         f"{np.round(s / s[0], 6)}; an essential matrix has (1, 1, 0) (within {tol:g}); project it "
                         "first (U diag(1, 1, 0) Vᵀ, as essential_from_fundamental does)")
    return E


def as_camera_matrix(P, name="P"):
    """``P`` as a finite (3, 4) camera matrix of rank 3, or ``ValueError`` (a rank-deficient P has no centre).

    >>> as_camera_matrix(np.outer([1.0, 2, 3], [1.0, 0, 0, 1]))
    Traceback (most recent call last):
    ...
    ValueError: P has rank 1 (singular values [5.29 0.   0.  ]): a camera matrix has rank 3
    """
    P = as_matrix(P, name, (3, 4))
    s = np.linalg.svd(P, compute_uv=False)
    rank = int(np.sum(s > 1e-12 * s[0])) if s[0] > 0 else 0
    if rank < 3:
        raise ValueError(f"{name} has rank {rank} (singular values {np.round(s, 3)}): a camera matrix has rank 3")
    return P


def as_camera_matrices(Ps, name="Ps"):
    """A ``(V, 3, 4)`` stack of finite camera matrices of rank 3, or ``ValueError`` naming the first bad one."""
    a = _as_float_array(Ps, name, "(V, 3, 4)")
    if a.ndim != 3 or a.shape[1:] != (3, 4):
        raise ValueError(f"{name} must have shape (V, 3, 4); got shape {a.shape}")
    return np.stack([as_camera_matrix(P, f"{name}[{k}]") for k, P in enumerate(a)]) if len(a) else a


def as_indices(idx, name, n, *, length=None, like_name="camera_indices", what="item", holder=None):
    """A 1-D int64 array of indices in ``0..n-1`` (``n`` ``what``s, held by the argument ``holder``; ``length``
    entries, one per entry of ``like_name``, when given), or ``ValueError``. Integers only: a boolean mask is refused
    (NumPy would read ``True``/``False`` as 1/0), and so are floats; an index out of range is named.

    >>> as_indices(np.array([True, False]), "camera_indices", 3, what="camera")
    Traceback (most recent call last):
    ...
    ValueError: camera_indices must hold integer indices of cameras (0..2); got a boolean array: ...
    """
    try:
        a = np.asarray(idx)
    except ValueError as exc:
        raise ValueError(f"{name} must be a 1-D array of integer indices of {what}s: {exc}") from None
    if a.dtype.kind == "b":
        raise ValueError(f"{name} must hold integer indices of {what}s (0..{n - 1}); got a boolean array: "
                         "np.flatnonzero(mask) gives the indices of a mask")
    if a.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of integers; got shape {a.shape}")
    if length is not None and a.shape[0] != length:
        raise ValueError(f"{name} has {a.shape[0]} entries but {like_name} has {length}: one entry of each per "
                         "observation")
    if a.size and a.dtype.kind not in "iu":
        raise ValueError(f"{name} must hold integers (indices of {what}s); got dtype {a.dtype}")
    a = a.astype(np.int64)
    bad = np.flatnonzero((a < 0) | (a >= n))
    if bad.size:
        held = f" ({holder} has {n})" if holder else ""
        raise ValueError(f"{name}[{int(bad[0])}] = {int(a[bad[0]])} indexes a missing {what}: "
                         f"there are {n} {what}s{held}, valid indices 0..{n - 1}; "
                         f"{bad.size} entries are out of range")
    return a


def as_mask(mask, name, shape, like=None):
    """A boolean mask of ``shape`` (bools, or numbers all 0 or 1), or ``ValueError`` (naming ``like``, whence the
    shape, when given)."""
    try:
        a = np.asarray(mask)
    except ValueError as exc:
        raise ValueError(f"{name} must be a boolean array of shape {shape}: {exc}") from None
    if a.shape != tuple(shape) or a.dtype.kind not in "biuf" or (a.dtype.kind != "b" and a.size and
                                                                  not np.all((a == 0) | (a == 1))):
        raise ValueError(f"{name} must be a boolean array of shape {tuple(shape)}" + (f" (to match {like})" if like
                         else "") + f"; got shape {a.shape}, dtype {a.dtype}")
    return a.astype(bool)


def as_rng(rng, name="rng"):
    """``rng`` if it is a ``numpy.random.Generator``, else ``ValueError`` (no silent global random state).

    >>> as_rng(None)
    Traceback (most recent call last):
    ...
    ValueError: rng must be a numpy.random.Generator, e.g. np.random.default_rng(0); got None
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"{name} must be a numpy.random.Generator, e.g. np.random.default_rng(0); got {rng!r}")
    return rng


def as_positive(value, name, *, allow_zero=False, allow_inf=False):
    """A positive (or, with ``allow_zero``, non-negative) finite number, as float; ``ValueError`` otherwise.

    >>> as_positive(-1, "noise_px", allow_zero=True)
    Traceback (most recent call last):
    ...
    ValueError: noise_px must be a non-negative number; got -1
    """
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and not np.isnan(value)
    ok = ok and (value >= 0 if allow_zero else value > 0) and (allow_inf or np.isfinite(value))
    if not ok:
        what = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be a {what} number; got {value!r}")
    return float(value)


def as_fraction(value, name, *, closed=False):
    """A number in [0, 1) (or [0, 1] with ``closed``), as float; ``ValueError`` otherwise.

    >>> as_fraction(1.5, "outlier_ratio")
    Traceback (most recent call last):
    ...
    ValueError: outlier_ratio must be in [0, 1); got 1.5
    """
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and 0 <= value and (
        value <= 1 if closed else value < 1)
    if not ok:
        raise ValueError(f"{name} must be in [0, 1{']' if closed else ')'}; got {value!r}")
    return float(value)


def as_probability_open(value, name):
    """A number strictly between 0 and 1 (a RANSAC confidence), as float; ``ValueError`` otherwise.

    >>> as_probability_open(1.0, "confidence")
    Traceback (most recent call last):
    ...
    ValueError: confidence must be strictly between 0 and 1; got 1.0
    """
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and 0 < value < 1
    if not ok:
        raise ValueError(f"{name} must be strictly between 0 and 1; got {value!r}")
    return float(value)


def as_count(value, name, minimum=1):
    """An integer ``>= minimum`` (a Python or numpy int, or a float with an integral value), as int.

    >>> as_count(2.5, "n_views", 2)
    Traceback (most recent call last):
    ...
    ValueError: n_views must be an integer >= 2; got 2.5
    """
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and np.isfinite(value) and \
        float(value) == int(value) and int(value) >= minimum
    if not ok:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


def as_image_size(image_size, name="image_size", minimum=1):
    """An image size ``(width, height)`` of two integers ``>= minimum`` (in pixels), as a tuple of ints.

    >>> as_image_size((640, 480.0))
    (640, 480)
    >>> as_image_size((480, 640, 3))
    Traceback (most recent call last):
    ...
    ValueError: image_size must be (width, height); got (480, 640, 3)
    """
    if np.shape(image_size) != (2,):
        raise ValueError(f"{name} must be (width, height); got {image_size!r}")
    return tuple(as_count(v, name, minimum) for v in image_size)


def as_tracks(tracks, name="tracks", min_views=1, min_tracks=0):
    """Return a ``(V, T, 2)`` track array (pixels, NaN where a view does not see a track), or ``ValueError``.

    Refused: another shape, infinite values, an observation with one NaN coordinate, and ``-1`` markers (the VGG
    files' way of writing "unseen": convert with :func:`labutils.core.scene.nan_tracks`).

    >>> as_tracks(np.full((2, 3, 2), -1.0))
    Traceback (most recent call last):
    ...
    ValueError: tracks[0, 0] is (-1, -1): mark an unseen observation with NaN, not -1 ...
    """
    x = _as_float_array(tracks, name, "(V, T, 2)")
    if x.ndim != 3 or x.shape[2] != 2:
        raise ValueError(f"{name} must have shape (V, T, 2) (views, tracks, pixel), NaN where unseen; got {x.shape}")
    if x.shape[0] < min_views or x.shape[1] < min_tracks:
        raise ValueError(f"{name} needs at least {min_views} views and {min_tracks} tracks; got shape {x.shape}")
    if np.isinf(x).any():
        v, k = np.argwhere(np.isinf(x).any(-1))[0]
        raise ValueError(f"{name}[{v}, {k}] is infinite; mark an unseen observation with NaN")
    half = np.isnan(x[..., 0]) != np.isnan(x[..., 1])
    if half.any():
        v, k = np.argwhere(half)[0]
        raise ValueError(f"{name}[{v}, {k}] has one NaN coordinate: an unseen observation is NaN in both")
    marker = (x[..., 0] == -1) & (x[..., 1] == -1)
    if marker.any():
        v, k = np.argwhere(marker)[0]
        raise ValueError(f"{name}[{v}, {k}] is (-1, -1): mark an unseen observation with NaN, not -1 "
                         "(labutils.core.scene.nan_tracks converts a -1-marked array)")
    return x


def as_mesh(vertices, faces, allow_empty=False):
    """A triangle mesh: finite ``(N, 3)`` float vertices and ``(F, 3)`` int64 faces indexing them, or ``ValueError``.

    Faces must be integers (a float array is refused, even with integral values) in ``0..N-1``: ``-1`` would
    silently wrap to the last vertex. ``allow_empty``: zero faces are accepted (a mesh with nothing to draw), and
    then a single vertex is enough; otherwise a mesh needs a triangle and three vertices.

    >>> as_mesh(np.eye(3), [[0, 1, 2]])[1].dtype
    dtype('int64')
    >>> as_mesh(np.eye(3), [[0, 1, -1]])
    Traceback (most recent call last):
    ...
    ValueError: faces hold vertex indices 0..2; got -1..1
    """
    V = as_points(vertices, "vertices", dim=3, min_n=1 if allow_empty else 3)
    try:
        F = np.asarray(faces)
    except ValueError as exc:
        raise ValueError(f"faces must be an (F, 3) integer array of triangles: {exc}") from None
    if F.ndim != 2 or F.shape[1] != 3 or (F.size and F.dtype.kind not in "iu"):
        raise ValueError(f"faces must be an (F, 3) integer array of triangles; got shape {F.shape}, dtype {F.dtype}")
    if len(F) == 0:
        if not allow_empty:
            raise ValueError("faces is empty: a mesh needs at least one triangle")
        return V, np.zeros((0, 3), np.int64)
    if F.min() < 0 or F.max() >= len(V):
        raise ValueError(f"faces hold vertex indices 0..{len(V) - 1}; got {int(F.min())}..{int(F.max())}")
    return V, F.astype(np.int64)


def as_cameras(K, R, t):
    """Cameras of V views, some possibly not registered: ``(Ks (V, 3, 3), R (V, 3, 3), t (V, 3), registered (V,))``.

    A view that is not registered has R and t entirely NaN (kept as NaN); every other pose must be a rotation and
    a finite translation, and K one calibration or one per view.
    """
    R = as_array(R, "R", "(V, 3, 3)")
    t = as_array(t, "t", "(V, 3)")
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R must have shape (V, 3, 3); got shape {R.shape}")
    if t.shape != (len(R), 3):
        hint = " — transposed?" if t.shape == (3, len(R)) else ""
        raise ValueError(f"t must have shape ({len(R)}, 3) (one translation per row, to match R); got shape "
                         f"{t.shape}{hint}")
    registered = np.all(np.isfinite(R), axis=(1, 2)) & np.all(np.isfinite(t), axis=1)
    partial = ~registered & (np.any(np.isfinite(R), axis=(1, 2)) | np.any(np.isfinite(t), axis=1))
    if partial.any():
        raise ValueError(f"view {int(np.flatnonzero(partial)[0])} has a partly NaN pose: a view that is not "
                         "registered has R and t entirely NaN")
    if np.isinf(R).any() or np.isinf(t).any():
        raise ValueError("R and t must be finite (NaN rows mark views that are not registered); got inf")
    if not registered.any():
        raise ValueError("no view has a finite pose (R and t are all NaN)")
    R = R.copy()
    R[registered] = as_rotations(R[registered], "R")
    as_translations(t[registered], "t")
    Ks = as_calibration(K, "K", n_views=len(R))
    return Ks, R, t, registered


def as_visibility(visible, n_views, n_points, registered, name="visible", views="R", points="X"):
    """A ``(n_views, n_points)`` boolean mask of which view sees which point; a view that is not registered sees
    none."""
    try:
        vis = np.asarray(visible)
    except ValueError as exc:
        raise ValueError(f"{name} must be a ({n_views}, {n_points}) boolean mask: {exc}") from None
    if vis.shape != (n_views, n_points):
        hint = " — transposed? it is (views, points)" if vis.shape == (n_points, n_views) else ""
        raise ValueError(f"{name} must have shape ({n_views}, {n_points}) (one row per view of {views}, one column "
                         f"per point of {points}); got shape {vis.shape}{hint}")
    if vis.dtype != bool:
        raise ValueError(f"{name} must be a boolean mask; got dtype {vis.dtype}")
    ghost = vis[~registered].any(axis=1)
    if ghost.any():
        raise ValueError(f"{name}: view {int(np.flatnonzero(~registered)[ghost][0])} is not registered (NaN pose) "
                         "but sees points")
    return vis


def as_image(image, name):
    """An ``(H, W)`` or ``(H, W, 1 | 3 | 4)`` numeric image, at least 2×2."""
    img = np.asarray(image)
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)) or min(img.shape[:2]) < 2:
        raise ValueError(f"{name} must be an (H, W) or (H, W, 3) image; got shape {img.shape}")
    if img.dtype.kind not in "uif":
        raise ValueError(f"{name} must be numeric; got dtype {img.dtype}")
    return img
