"""The reprojection model of bundle adjustment: camera parameters, the residuals, their analytic Jacobian and its
sparsity (H&Z Sec. 18.1, A6.3; Triggs et al., "Bundle Adjustment — A Modern Synthesis", 2000).

Parametrisation and column order (used by every bundle-adjustment function)
--------------------------------------------------------------------------
``camera_params`` is ``(V, k)``: per camera the angle-axis vector ``ω`` (3, ``R = exp([ω]×)``,
Rodrigues), the translation ``t`` (3) with ``x_cam = R @ X + t``, and for the BAL model also
``f, k1, k2`` (so ``k = 6`` or ``k = 9``). The parameter vector is
``[camera_params.ravel(), points_3d.ravel()]``: camera ``c`` owns columns ``k·c … k·c + k - 1``
(``ω1 ω2 ω3 t1 t2 t3 [f k1 k2]``), point ``j`` owns columns ``k·V + 3j … k·V + 3j + 2``.
Residual rows are ``2i`` (x) and ``2i + 1`` (y) of observation ``i``. The Jacobian is the exact
derivative with respect to these *additive* parameters (angle-axis included, see
:func:`reprojection_jacobian`), so ``J`` from here gives the Gauss–Newton covariance
``σ² (JᵀJ)⁻¹`` of exactly these parameters once the gauge columns are removed.

Camera models
-------------
- ``'pinhole'`` (our data; ``camera_params`` has 6 columns and ``K`` is given, shared ``(3, 3)`` or
  per camera ``(V, 3, 3)``): ``x = K x_cam``, dehomogenised; y down, z forward.
- ``'bal'`` ("Bundle Adjustment in the Large", Agarwal et al. 2010; 9 columns, ``K=None``):
  ``P = R X + t``, ``p = -P[:2] / P[2]`` (the camera looks down -z), pixel
  ``f · (1 + k1‖p‖² + k2‖p‖⁴) · p`` about the image centre, y up.
"""
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from ..core.geometry import angle_axis_from_rotation, left_jacobian_so3, rotation_from_angle_axis
from ..core.validation import as_array, as_calibration, as_count, as_points, as_rotations, as_translations
from ..core.validation import as_indices as _as_indices


def camera_params_from_Rt(R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Pack poses into ``camera_params``: ``(V, 3, 3), (V, 3) -> (V, 6)`` = ``[ω (angle-axis), t]``.

    >>> R = np.stack([np.eye(3), rotation_from_angle_axis([0.1, -0.2, 0.3])]); t = np.ones((2, 3))
    >>> cp = camera_params_from_Rt(R, t); cp.shape
    (2, 6)
    >>> R2, t2 = Rt_from_camera_params(cp); bool(np.allclose(R2, R) and np.allclose(t2, t))
    True
    >>> camera_params_from_Rt(np.stack([np.eye(3)] * 4), np.ones((3, 4)))
    Traceback (most recent call last):
    ...
    ValueError: t must have shape (4, 3) (one translation per row to match the 4 rotations of R); got shape ...
    """
    R = as_rotations(R, "R")
    t = as_translations(t, "t", n=len(R), like_name="R")
    return np.hstack([angle_axis_from_rotation(R) if len(R) else np.zeros((0, 3)), t])


def Rt_from_camera_params(camera_params: ArrayLike) -> tuple:
    """Unpack ``camera_params (V, 6 or 9)`` into ``R (V, 3, 3)`` and ``t (V, 3)`` (see :func:`camera_params_from_Rt`).

    >>> R, t = Rt_from_camera_params(np.zeros((2, 6))); R.shape, t.shape
    ((2, 3, 3), (2, 3))
    """
    cp = as_array(camera_params, "camera_params", "(V, 6) or (V, 9)")
    if cp.ndim != 2 or cp.shape[1] not in (6, 9):
        raise ValueError(f"camera_params must have shape (V, 6) or (V, 9); got {cp.shape}")
    if not np.all(np.isfinite(cp)):
        raise ValueError("camera_params has non-finite entries (NaN or inf)")
    return rotation_from_angle_axis(cp[:, :3]), cp[:, 3:6].copy()


def as_indices(a, name, n_obs, upper, what, *, upper_name=None):
    """``a`` as a 1-D int64 array of indices in ``0..upper - 1`` (of ``what``s, held by ``upper_name``), with
    ``n_obs`` entries (those of ``camera_indices``) when given, or ``ValueError`` naming the problem
    (:func:`labutils.core.validation.as_indices`: integers only, never booleans)."""
    return _as_indices(a, name, upper, length=n_obs, what=what, holder=upper_name)


def check_calibrations(K, n_cameras, k):
    """Return the (V, 3, 3) stack of calibrations (normalised so K[2] = [0, 0, 1]) or None for BAL."""
    if k == 9:
        if K is not None:
            raise ValueError("camera_params has 9 columns (the BAL model with f, k1, k2): pass K=None")
        return None
    if k != 6:
        raise ValueError(f"camera_params must have 6 columns (angle-axis, t) or 9 (BAL: + f, k1, k2); got {k}")
    if K is None:
        raise ValueError("the pinhole model (6 camera parameters) needs the calibration K, (3, 3) or (V, 3, 3)")
    return as_calibration(K, "K", n_views=n_cameras)


def check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K, need_2d=True):
    cp = as_array(camera_params, "camera_params", "(V, 6) or (V, 9)")
    if cp.ndim != 2 or cp.shape[1] not in (6, 9) or cp.shape[0] < 1:
        raise ValueError(f"camera_params must have shape (V, 6) or (V, 9) with V >= 1; got {cp.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(cp), axis=1))
    if bad.size:
        raise ValueError(f"camera_params has non-finite values (NaN or inf) for camera(s) {bad[:5].tolist()}")
    X = as_points(points_3d, "points_3d", dim=3)
    V, M = cp.shape[0], X.shape[0]
    ci = as_indices(camera_indices, "camera_indices", None, V, "camera", upper_name="camera_params")
    pi = as_indices(point_indices, "point_indices", ci.shape[0], M, "point", upper_name="points_3d")
    x = as_points(points_2d, "points_2d", dim=2, like=(ci, "camera_indices")) if need_2d else None
    Ks = check_calibrations(K, V, cp.shape[1])
    return cp, X, ci, pi, x, Ks


@np.errstate(divide="ignore", invalid="ignore")       # depth 0 gives inf: the callers refuse it
def project_observations(cp, X, ci, pi, Ks, jac=False):
    """Predicted pixels ``(n, 2)`` and, if ``jac``, the blocks ``Jc (n, 2, k)`` and ``Jp (n, 2, 3)``.

    ``Ks`` is None (BAL model) or ``(V, 3, 3)`` calibrations with last row ``[0, 0, 1]``.
    """
    n, k = ci.shape[0], cp.shape[1]
    Ro = rotation_from_angle_axis(cp[:, :3])[ci]                 # (n, 3, 3)
    RX = np.einsum("nij,nj->ni", Ro, X[pi])                      # R X
    P = RX + cp[ci, 3:6]                                          # x_cam = R X + t
    iz = 1.0 / P[:, 2]
    if Ks is not None:                                            # pinhole: x = K x_cam, dehomogenised
        shared = Ks.shape[0] == 1 or bool(np.all(Ks == Ks[0]))
        xn = P[:, :2] * iz[:, None]
        if shared:
            A = Ks[0, :2, :2]
            u = xn @ A.T + Ks[0, :2, 2]
        else:
            A = Ks[ci, :2, :2]
            u = (A @ xn[:, :, None])[:, :, 0] + Ks[ci, :2, 2]
    else:                                                         # BAL: looks down -z, radial distortion
        f, k1, k2 = cp[ci, 6], cp[ci, 7], cp[ci, 8]
        p = -P[:, :2] * iz[:, None]
        r2 = (p ** 2).sum(1)
        d = 1 + k1 * r2 + k2 * r2 ** 2
        u = (f * d)[:, None] * p
    if not jac:
        return u
    # ∂u/∂x_cam (n, 2, 3) through the normalised point xn = x_cam[:2] / z, written straight into the columns of t
    # (∂x_cam/∂t = I), element-wise: batched products of tiny matrices are slow in numpy
    Jc = np.empty((n, 2, k))
    du_dP = Jc[:, :, 3:6]
    if Ks is not None:                                            # A [[1/z, 0, -xn0/z], [0, 1/z, -xn1/z]]
        Aiz = (A if A.ndim == 3 else A[None]) * iz[:, None, None]
        du_dP[:, :, :2] = Aiz
        du_dP[:, :, 2] = -np.einsum("nab,nb->na", Aiz, xn)
    else:                                                         # ∂u/∂p = s I + p qᵀ, p = -xn
        s, q = f * d, (2 * f * (k1 + 2 * k2 * r2))[:, None] * p
        du_dP[:, :, :2] = -(s[:, None, None] * np.eye(2) + p[:, :, None] * q[:, None, :]) * iz[:, None, None]
        du_dP[:, :, 2] = -p * ((s + (q * p).sum(1)) * iz)[:, None]
    # ∂x_cam/∂ω = -[R X]× J_l(ω): row g of ∂u/∂x_cam times -[a]× is (a × g)ᵀ
    a0, a1, a2 = RX[:, 0:1], RX[:, 1:2], RX[:, 2:3]
    g0, g1, g2 = du_dP[:, :, 0], du_dP[:, :, 1], du_dP[:, :, 2]
    G = np.empty((n, 2, 3))
    G[:, :, 0] = a1 * g2 - a2 * g1
    G[:, :, 1] = a2 * g0 - a0 * g2
    G[:, :, 2] = a0 * g1 - a1 * g0
    Jc[:, :, 0:3] = G @ left_jacobian_so3(cp[:, :3])[ci]
    if Ks is None:
        Jc[:, :, 6] = d[:, None] * p
        Jc[:, :, 7] = (f * r2)[:, None] * p
        Jc[:, :, 8] = (f * r2 ** 2)[:, None] * p
    Jp = du_dP @ Ro                                               # ∂x_cam/∂X = R
    return u, Jc, Jp


def reprojection_residuals(camera_params: ArrayLike, points_3d: ArrayLike, camera_indices: ArrayLike,
                           point_indices: ArrayLike, points_2d: ArrayLike, K: ArrayLike) -> np.ndarray:
    """Reprojection errors in pixels, predicted minus observed (H&Z eq. 18.1).

    Parameters
    ----------
    camera_params : (V, 6) or (V, 9) array_like
        ``[ω, t]`` per camera (angle-axis, ``x_cam = R X + t``), or ``[ω, t, f, k1, k2]`` (BAL model).
    points_3d : (M, 3) array_like
    camera_indices, point_indices : (n_obs,) int array_like
        Which camera and which point each observation belongs to.
    points_2d : (n_obs, 2) array_like
        Observed pixels.
    K : (3, 3) or (V, 3, 3) array_like, or None
        Calibration (pinhole model; last row ``[0, 0, 1]``, skew allowed), or None with 9 columns (BAL model).

    Returns
    -------
    r : (2 · n_obs,) ndarray
        ``[u_0 - x_0, v_0 - y_0, u_1 - x_1, …]``: rows ``2i`` and ``2i + 1`` belong to observation ``i``.

    Examples
    --------
    >>> cp = np.array([[0., 0, 0, 0, 0, 5]]); X = np.array([[0., 0, 0], [1, 0, 0]])
    >>> K = np.array([[100., 0, 50], [0, 100, 40], [0, 0, 1]])
    >>> reprojection_residuals(cp, X, [0, 0], [0, 1], [[50., 40.], [70., 41.]], K)
    array([ 0., -0.,  0., -1.])
    """
    cp, X, ci, pi, x, Ks = check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K)
    return (project_observations(cp, X, ci, pi, Ks) - x).ravel()


def jacobian_structure(ci, pi, V, M, k):
    """Column indices ``(n, 2, k + 3)`` of the non-zeros of each Jacobian row (camera block, then point block)."""
    cols = np.empty((ci.shape[0], 2, k + 3), np.int64)
    cols[:, :, :k] = (k * ci)[:, None, None] + np.arange(k)
    cols[:, :, k:] = (k * V + 3 * pi)[:, None, None] + np.arange(3)
    return cols


def assemble_jacobian(Jc, Jp, cols, n_cols, keep=None, colmap=None):
    """CSR matrix from the per-observation blocks; optionally keep only some entries and renumber columns."""
    data = np.concatenate([Jc, Jp], axis=2).ravel()
    idx = cols.ravel()
    n_rows, per_row = 2 * Jc.shape[0], Jc.shape[2] + 3
    if keep is None:
        indptr = np.arange(n_rows + 1, dtype=np.int64) * per_row
        return sp.csr_matrix((data, idx, indptr), shape=(n_rows, n_cols))
    counts = keep.reshape(n_rows, per_row).sum(1)
    indptr = np.concatenate([[0], np.cumsum(counts)])
    return sp.csr_matrix((data[keep], colmap[idx[keep]], indptr), shape=(n_rows, n_cols))


def reprojection_jacobian(camera_params: ArrayLike, points_3d: ArrayLike, camera_indices: ArrayLike,
                          point_indices: ArrayLike, K: ArrayLike):
    """Analytic Jacobian of :func:`reprojection_residuals` with respect to ``[camera_params, points_3d]``.

    The chain rule per observation (``P = R X + t`` the point in the camera):

    - ``∂P/∂ω = -[R X]× J_l(ω)`` with ``J_l`` the left Jacobian of SO(3) (:func:`left_jacobian_so3`): the
      exact derivative with respect to the angle-axis parameters themselves (not a local perturbation);
    - ``∂P/∂t = I``, ``∂P/∂X = R``;
    - pinhole: ``∂u/∂P = K[:2, :2] · [[1/z, 0, -x/z²], [0, 1/z, -y/z²]]``;
      BAL: ``p = -P[:2]/z``, ``u = f d p`` with ``d = 1 + k1‖p‖² + k2‖p‖⁴``, so
      ``∂u/∂p = f (d I + 2 (k1 + 2 k2 ‖p‖²) p pᵀ)``, ``∂u/∂(f, k1, k2) = (d p, f‖p‖² p, f‖p‖⁴ p)``.

    Parameters
    ----------
    camera_params, points_3d, camera_indices, point_indices, K
        As in :func:`reprojection_residuals` (no observed pixels needed).

    Returns
    -------
    J : (2 · n_obs, k · V + 3 · M) scipy.sparse.csr_matrix
        Row ``2i + a`` is coordinate ``a`` (0: x, 1: y) of observation ``i``. Column ``k·c + j`` is
        parameter ``j`` of camera ``c`` (``ω1 ω2 ω3 t1 t2 t3`` then ``f k1 k2`` for BAL), column
        ``k·V + 3p + j`` is coordinate ``j`` of point ``p``. Each row has ``k + 3`` stored entries.
        The Gauss–Newton covariance of the parameters, ``σ² (JᵀJ)⁻¹``, needs the gauge columns removed
        first (e.g. ``BundleResult.free`` from :func:`bundle_adjust`).

    Examples
    --------
    >>> cp = np.zeros((2, 6)); cp[:, 5] = 5; X = np.zeros((3, 3))
    >>> J = reprojection_jacobian(cp, X, [0, 1, 1], [0, 1, 2], np.eye(3))
    >>> J.shape, J.nnz
    ((6, 21), 54)
    """
    cp, X, ci, pi, _, Ks = check_problem(camera_params, points_3d, camera_indices, point_indices, None, K,
                                          need_2d=False)
    _, Jc, Jp = project_observations(cp, X, ci, pi, Ks, jac=True)
    V, k = cp.shape
    return assemble_jacobian(Jc, Jp, jacobian_structure(ci, pi, V, X.shape[0], k), k * V + 3 * X.shape[0])


def reprojection_blocks(camera_params: ArrayLike, points_3d: ArrayLike, camera_indices: ArrayLike,
                        point_indices: ArrayLike, K: ArrayLike) -> tuple:
    """The per-observation blocks of :func:`reprojection_jacobian`: ``∂u/∂(ω, t)`` and ``∂u/∂X``.

    The reference of notebook 04's exercise ``projection_jacobian`` (same arguments, same return).

    Parameters
    ----------
    camera_params, points_3d, camera_indices, point_indices, K
        As in :func:`reprojection_residuals` (no observed pixels needed).

    Returns
    -------
    Jc : (n_obs, 2, k) ndarray
        The camera block of each observation (columns ``ω1 ω2 ω3 t1 t2 t3 [f k1 k2]``).
    Jp : (n_obs, 2, 3) ndarray
        The point block of each observation.

    Examples
    --------
    >>> cp = np.zeros((1, 6)); cp[0, 5] = 5
    >>> Jc, Jp = reprojection_blocks(cp, np.zeros((1, 3)), [0], [0], np.eye(3))
    >>> Jc.shape, Jp.shape, Jp[0].tolist()
    ((1, 2, 6), (1, 2, 3), [[0.2, 0.0, 0.0], [0.0, 0.2, 0.0]])
    """
    cp, X, ci, pi, _, Ks = check_problem(camera_params, points_3d, camera_indices, point_indices, None, K,
                                          need_2d=False)
    _, Jc, Jp = project_observations(cp, X, ci, pi, Ks, jac=True)
    return Jc, Jp


def jacobian_sparsity(n_cameras: int, n_points: int, camera_indices: ArrayLike, point_indices: ArrayLike,
                      camera_block: int = 6):
    """Sparsity mask of the bundle-adjustment Jacobian (the ``jac_sparsity`` of ``least_squares``).

    Parameters
    ----------
    n_cameras, n_points : int
    camera_indices, point_indices : (n_obs,) int array_like
    camera_block : int
        Parameters per camera, ``k`` (6 for ``[ω, t]``, 9 for the BAL model).

    Returns
    -------
    A : (2 · n_obs, k · n_cameras + 3 · n_points) scipy.sparse.csr_matrix of int8
        1 where :func:`reprojection_jacobian` can be non-zero, with the same row and column order.

    >>> A = jacobian_sparsity(2, 3, [0, 1, 1], [0, 1, 2])
    >>> A.shape, A.nnz, A[0].toarray().ravel().tolist()
    ((6, 21), 54, [1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 1, 1, 1, 0, 0, 0, 0, 0, 0])
    """
    k = as_count(camera_block, "camera_block", 1)
    n_cameras, n_points = as_count(n_cameras, "n_cameras", 1), as_count(n_points, "n_points", 1)
    ci = as_indices(camera_indices, "camera_indices", None, int(n_cameras), "camera")
    pi = as_indices(point_indices, "point_indices", ci.shape[0], int(n_points), "point")
    cols = jacobian_structure(ci, pi, int(n_cameras), int(n_points), k)
    n_rows = 2 * ci.shape[0]
    indptr = np.arange(n_rows + 1, dtype=np.int64) * (k + 3)
    return sp.csr_matrix((np.ones(cols.size, np.int8), cols.ravel(), indptr),
                         shape=(n_rows, k * int(n_cameras) + 3 * int(n_points)))

