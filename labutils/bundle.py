"""Bundle adjustment: reprojection residuals, their analytic Jacobian and its sparsity, two solvers.

The problem (H&Z Sec. 18.1; Triggs et al., "Bundle Adjustment — A Modern Synthesis", 2000) is

    minimise  0.5 · Σ_i Σ_{a=x,y} f_scale² ρ(r_ia² / f_scale²),   r_i = π(camera c_i, X_{p_i}) - x_i

over the camera parameters and the 3D points, where ``ρ`` is the identity (``loss='linear'``, plain
least squares) or a robust loss (``'huber'``, ``'cauchy'``, ``'soft_l1'``, ``'arctan'``, as in
:func:`scipy.optimize.least_squares`, applied to each pixel coordinate separately).

Parametrisation and column order (used by every function here)
--------------------------------------------------------------
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

The gauge
---------
Reprojection errors do not change when the whole reconstruction (cameras and points) is moved by a
similarity (rotation, translation, scale: 7 degrees of freedom). The cost therefore has a 7-dimensional
valley of equal minima, ``JᵀJ`` is singular, and "the" solution is only defined once that freedom
is fixed. ``gauge='first-camera-and-scale'`` gives the result with the pose of the first camera at its
initial value (6 dof) and the distance between the first two camera centres at its initial value
(1 dof). See :func:`bundle_adjust`.

Solvers
-------
- ``'lm-schur'``: our Levenberg–Marquardt (Madsen, Nielsen & Tingleff 2004, Alg. 3.16, with
  Marquardt's diagonal scaling and Nielsen's damping update) on the normal equations, eliminating
  the 3×3 point blocks by the Schur complement (Triggs et al. Sec. 6.1; H&Z Sec. A6.3) and solving
  the reduced camera system by dense Cholesky. Robust losses by iteratively reweighted least squares,
  then the loss's second-order curvature near the optimum (see ``loss`` in :func:`bundle_adjust`).
- ``'scipy'``: :func:`scipy.optimize.least_squares` (trust-region reflective, ``x_scale='jac'``)
  with our analytic sparse Jacobian (``scipy_jac='analytic'``, default), or finite differences
  grouped by the sparsity mask (``'sparsity'``), or dense finite differences (``'dense'``; small
  problems only). Measured on the dinosaur (36 cameras, 4,983 points, soft_l1 loss, 2 cores):
  LM-Schur 13 iterations in 0.27 s; scipy with the mask 17 iterations in 3.2 s (7e-5 above), or
  with tighter LSMR tolerances 15 iterations in 14.6 s (the same cost).

Both solvers run with OpenBLAS on one thread (:func:`single_threaded_blas`).

Command line: ``python -m labutils.bundle PROBLEM.txt --solver {lm-schur,scipy} --out SOLVED.txt
[--fix-intrinsics] [--json]`` solves a BAL file (see :mod:`labutils.bal`).
"""
import contextlib
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from scipy.optimize import least_squares

from ._validation import as_points

LOSSES = ("linear", "huber", "soft_l1", "cauchy", "arctan")
GAUGES = ("first-camera-and-scale", None)
_SECOND_ORDER_AFTER = 1e-3      # robust loss: relative cost decrease below which LM leaves plain IRLS
_CURVATURE_FLOOR = 0.01         # ... and the floor of the second-order curvature, times rho'


# ---------------------------------------------------------------------------------------------
# BLAS threads
# ---------------------------------------------------------------------------------------------
_BLAS_NAMES = [("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
               ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
               ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
               ("openblas_get_num_threads", "openblas_set_num_threads")]


def _openblas_controls():
    """(get, set) thread-count functions of every OpenBLAS loaded in this process (Linux; else empty)."""
    import ctypes

    try:
        with open("/proc/self/maps") as f:
            paths = sorted({line.split()[-1] for line in f if "openblas" in line.lower() and ".so" in line})
    except OSError:
        return []
    controls = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get, set_ in _BLAS_NAMES:
            if hasattr(lib, get) and hasattr(lib, set_):
                controls.append((getattr(lib, get), getattr(lib, set_)))
                break
    return controls


@contextlib.contextmanager
def single_threaded_blas():
    """Run a block with every loaded OpenBLAS (numpy's and scipy's copies) on one thread, then restore.

    Bundle adjustment at these sizes makes many small BLAS calls (vector norms in LSMR, a 200×200
    Cholesky): threads only add synchronisation, and numpy's and scipy's two OpenBLAS thread pools
    spinning against each other on a 2-core machine made scipy's solve of the dinosaur 97 s instead of
    3.5 s, and LM-Schur 2.1 s instead of 0.3 s (measured). Both solvers run inside this. A no-op where
    OpenBLAS is not found (other BLAS, other systems); ``OPENBLAS_NUM_THREADS=1`` does the same globally.
    """
    controls = _openblas_controls()
    old = [get() for get, _ in controls]
    for _, set_ in controls:
        set_(1)
    try:
        yield
    finally:
        for (_, set_), n in zip(controls, old):
            set_(n)


# ---------------------------------------------------------------------------------------------
# rotations, vectorised over cameras
# ---------------------------------------------------------------------------------------------
def _skew_stack(v):
    """``(n, 3) -> (n, 3, 3)`` cross-product matrices."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1),
                     np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], axis=1)


def _aa_coefficients(theta):
    """``sin θ/θ``, ``(1 - cos θ)/θ²``, ``(θ - sin θ)/θ³``, accurate near θ = 0."""
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    t2 = theta ** 2
    a = np.where(small, 1 - t2 / 6, np.sin(th) / th)
    b = np.where(small, 0.5 - t2 / 24, (1 - np.cos(th)) / th ** 2)
    c = np.where(small, 1 / 6 - t2 / 120, (th - np.sin(th)) / th ** 3)
    return a, b, c


def rotations_from_angle_axis(w):
    """Rotation matrices from angle-axis vectors (Rodrigues), vectorised: ``(V, 3) -> (V, 3, 3)``.

    >>> rotations_from_angle_axis(np.zeros((2, 3))).shape
    (2, 3, 3)
    """
    w = np.asarray(w, float).reshape(-1, 3)
    a, b, _ = _aa_coefficients(np.linalg.norm(w, axis=1))
    Wx = _skew_stack(w)
    return np.eye(3) + a[:, None, None] * Wx + b[:, None, None] * (Wx @ Wx)


def left_jacobian_so3(w):
    """Left Jacobian of SO(3), ``J_l(ω) = I + (1 - cos θ)/θ² [ω]× + (θ - sin θ)/θ³ [ω]×²``, ``(V, 3, 3)``.

    It maps a change of the angle-axis vector to the rotation change applied on the left:
    ``exp([ω + δ]×) ≈ exp([J_l(ω) δ]×) exp([ω]×)``, hence ``∂(R(ω) X)/∂ω = -[R X]× J_l(ω)``.

    >>> np.allclose(left_jacobian_so3(np.zeros((1, 3)))[0], np.eye(3))
    True
    """
    w = np.asarray(w, float).reshape(-1, 3)
    _, b, c = _aa_coefficients(np.linalg.norm(w, axis=1))
    Wx = _skew_stack(w)
    return np.eye(3) + b[:, None, None] * Wx + c[:, None, None] * (Wx @ Wx)


def _angle_axis_from_rotations(R):
    from .geometry import angle_axis_from_rotation

    return np.stack([angle_axis_from_rotation(Ri) for Ri in R]) if len(R) else np.zeros((0, 3))


def camera_params_from_Rt(R, t):
    """Pack poses into ``camera_params``: ``(V, 3, 3), (V, 3) -> (V, 6)`` = ``[ω (angle-axis), t]``.

    >>> from labutils.geometry import rotation_from_angle_axis
    >>> R = np.stack([np.eye(3), rotation_from_angle_axis([0.1, -0.2, 0.3])]); t = np.ones((2, 3))
    >>> cp = camera_params_from_Rt(R, t); cp.shape
    (2, 6)
    >>> R2, t2 = Rt_from_camera_params(cp); bool(np.allclose(R2, R) and np.allclose(t2, t))
    True
    """
    R = np.asarray(R, float)
    t = np.asarray(t, float)
    if R.ndim == 2:
        R = R[None]
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R must have shape (V, 3, 3); got {R.shape}")
    t = t.reshape(-1, 3) if t.size == 3 * len(R) else t
    if t.shape != (len(R), 3):
        raise ValueError(f"t must have shape (V, 3) = ({len(R)}, 3); got {np.shape(t)}")
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        raise ValueError("R and t have non-finite entries (NaN or inf)")
    err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2)) if len(R) else np.zeros(0)
    bad = np.flatnonzero((err > 1e-6) | (np.linalg.det(R) < 0)) if len(R) else []
    if len(bad):
        raise ValueError(f"R[{int(bad[0])}] is not a rotation matrix (orthonormal, det +1)")
    return np.hstack([_angle_axis_from_rotations(R), t])


def Rt_from_camera_params(camera_params):
    """Unpack ``camera_params (V, k >= 6)`` into ``R (V, 3, 3)`` and ``t (V, 3)`` (see :func:`camera_params_from_Rt`)."""
    cp = np.asarray(camera_params, float)
    if cp.ndim != 2 or cp.shape[1] < 6:
        raise ValueError(f"camera_params must have shape (V, 6) or (V, 9); got {cp.shape}")
    return rotations_from_angle_axis(cp[:, :3]), cp[:, 3:6].copy()


# ---------------------------------------------------------------------------------------------
# input checks
# ---------------------------------------------------------------------------------------------
def _as_indices(a, name, n_obs, upper, what):
    a = np.asarray(a)
    if a.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of integers; got shape {a.shape}")
    if n_obs is not None and a.shape[0] != n_obs:
        raise ValueError(f"{name} has {a.shape[0]} entries but there are {n_obs} observations")
    if a.size and a.dtype.kind not in "iu":
        af = a.astype(float)
        if not np.all(np.isfinite(af)) or np.any(af != np.round(af)):
            raise ValueError(f"{name} must hold integers (indices of {what}s)")
        a = af
    a = a.astype(np.int64)
    bad = np.flatnonzero((a < 0) | (a >= upper))
    if bad.size:
        raise ValueError(f"{name}[{int(bad[0])}] = {int(a[bad[0]])} indexes a missing {what}: "
                         f"there are {upper} {what}s (valid indices 0..{upper - 1}); "
                         f"{bad.size} observation(s) are out of range")
    return a


def _check_K(K, n_cameras, k):
    """Return the (V, 3, 3) stack of calibrations (normalised so K[2] = [0, 0, 1]) or None for BAL."""
    if k == 9:
        if K is not None:
            raise ValueError("camera_params has 9 columns (the BAL model with f, k1, k2): pass K=None")
        return None
    if k != 6:
        raise ValueError(f"camera_params must have 6 columns (angle-axis, t) or 9 (BAL: + f, k1, k2); got {k}")
    if K is None:
        raise ValueError("the pinhole model (6 camera parameters) needs the calibration K, (3, 3) or (V, 3, 3)")
    try:
        K = np.asarray(K, float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"K must be a numeric (3, 3) or (V, 3, 3) array: {exc}") from None
    if K.shape == (3, 3):
        K = np.broadcast_to(K, (n_cameras, 3, 3))
    if K.shape != (n_cameras, 3, 3):
        raise ValueError(f"K must have shape (3, 3) or (V, 3, 3) = ({n_cameras}, 3, 3); got {K.shape}")
    if not np.all(np.isfinite(K)):
        raise ValueError("K has non-finite entries (NaN or inf)")
    if np.any(np.abs(K[:, 2, :2]) > 1e-12 * np.abs(K).max(axis=(1, 2))[:, None]) or np.any(K[:, 2, 2] == 0):
        raise ValueError("K must be a calibration matrix with last row [0, 0, K33 != 0]")
    return K / K[:, 2:3, 2:3]


def _check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K, need_2d=True):
    try:
        cp = np.asarray(camera_params, float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"camera_params must be a numeric (V, 6) or (V, 9) array: {exc}") from None
    if cp.ndim != 2 or cp.shape[1] not in (6, 9) or cp.shape[0] < 1:
        raise ValueError(f"camera_params must have shape (V, 6) or (V, 9) with V >= 1; got {cp.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(cp), axis=1))
    if bad.size:
        raise ValueError(f"camera_params has non-finite values (NaN or inf) for camera(s) {bad[:5].tolist()}")
    X = as_points(points_3d, "points_3d", dim=3)
    V, M = cp.shape[0], X.shape[0]
    ci = _as_indices(camera_indices, "camera_indices", None, V, "camera")
    pi = _as_indices(point_indices, "point_indices", ci.shape[0], M, "point")
    x = as_points(points_2d, "points_2d", dim=2, like=ci) if need_2d else None
    Ks = _check_K(K, V, cp.shape[1])
    return cp, X, ci, pi, x, Ks


# ---------------------------------------------------------------------------------------------
# model: projection and its Jacobian, vectorised over observations
# ---------------------------------------------------------------------------------------------
def _project(cp, X, ci, pi, Ks, jac=False):
    """Predicted pixels ``(n, 2)`` and, if ``jac``, the blocks ``Jc (n, 2, k)`` and ``Jp (n, 2, 3)``.

    ``Ks`` is None (BAL model) or ``(V, 3, 3)`` calibrations with last row ``[0, 0, 1]``.
    """
    n, k = ci.shape[0], cp.shape[1]
    Ro = rotations_from_angle_axis(cp[:, :3])[ci]                 # (n, 3, 3)
    RX = (Ro @ X[pi][:, :, None])[:, :, 0]                        # R X
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
    # ∂u/∂x_cam (n, 2, 3) through the normalised point xn = x_cam[:2] / z
    dn = np.zeros((n, 2, 3))
    dn[:, 0, 0] = dn[:, 1, 1] = iz
    if Ks is not None:
        dn[:, :, 2] = -xn * iz[:, None]
        du_dP = A @ dn
    else:                                                         # p = -xn
        dn[:, :, 2] = p * iz[:, None]
        dd_dp = (2 * (k1 + 2 * k2 * r2))[:, None] * p             # ∂d/∂p, (n, 2)
        du_dp = (f * d)[:, None, None] * np.eye(2) + f[:, None, None] * p[:, :, None] * dd_dp[:, None, :]
        du_dP = -(du_dp @ dn)
    # ∂x_cam/∂ω = -[R X]× J_l(ω): row g of ∂u/∂x_cam times -[a]× is (a × g)ᵀ
    a = RX[:, None, :]
    g0, g1, g2 = du_dP[:, :, 0], du_dP[:, :, 1], du_dP[:, :, 2]
    G = np.stack([a[..., 1] * g2 - a[..., 2] * g1, a[..., 2] * g0 - a[..., 0] * g2,
                  a[..., 0] * g1 - a[..., 1] * g0], axis=-1)      # (n, 2, 3)
    Jc = np.empty((n, 2, k))
    Jc[:, :, 0:3] = G @ left_jacobian_so3(cp[:, :3])[ci]
    Jc[:, :, 3:6] = du_dP                                         # ∂x_cam/∂t = I
    if Ks is None:
        Jc[:, :, 6] = d[:, None] * p
        Jc[:, :, 7] = (f * r2)[:, None] * p
        Jc[:, :, 8] = (f * r2 ** 2)[:, None] * p
    Jp = du_dP @ Ro                                               # ∂x_cam/∂X = R
    return u, Jc, Jp


def reprojection_residuals(camera_params, points_3d, camera_indices, point_indices, points_2d, K):
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
    cp, X, ci, pi, x, Ks = _check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K)
    return (_project(cp, X, ci, pi, Ks) - x).ravel()


def _jacobian_structure(ci, pi, V, M, k):
    """Column indices ``(n, 2, k + 3)`` of the non-zeros of each Jacobian row (camera block, then point block)."""
    cols = np.empty((ci.shape[0], 2, k + 3), np.int64)
    cols[:, :, :k] = (k * ci)[:, None, None] + np.arange(k)
    cols[:, :, k:] = (k * V + 3 * pi)[:, None, None] + np.arange(3)
    return cols


def _assemble(Jc, Jp, cols, n_cols, keep=None, colmap=None):
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


def reprojection_jacobian(camera_params, points_3d, camera_indices, point_indices, K):
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
    cp, X, ci, pi, _, Ks = _check_problem(camera_params, points_3d, camera_indices, point_indices, None, K,
                                          need_2d=False)
    _, Jc, Jp = _project(cp, X, ci, pi, Ks, jac=True)
    V, k = cp.shape
    return _assemble(Jc, Jp, _jacobian_structure(ci, pi, V, X.shape[0], k), k * V + 3 * X.shape[0])


def jacobian_sparsity(n_cameras, n_points, camera_indices, point_indices, camera_block=6):
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
    if int(camera_block) != camera_block or camera_block < 1:
        raise ValueError(f"camera_block must be a positive integer; got {camera_block}")
    k = int(camera_block)
    ci = _as_indices(camera_indices, "camera_indices", None, int(n_cameras), "camera")
    pi = _as_indices(point_indices, "point_indices", ci.shape[0], int(n_points), "point")
    cols = _jacobian_structure(ci, pi, int(n_cameras), int(n_points), k)
    n_rows = 2 * ci.shape[0]
    indptr = np.arange(n_rows + 1, dtype=np.int64) * (k + 3)
    return sp.csr_matrix((np.ones(cols.size, np.int8), cols.ravel(), indptr),
                         shape=(n_rows, k * int(n_cameras) + 3 * int(n_points)))


# ---------------------------------------------------------------------------------------------
# robust losses (scipy's conventions: rho(z) with z = r² / f_scale², applied per residual)
# ---------------------------------------------------------------------------------------------
def _rho(z, loss):
    """``ρ(z)``, ``ρ'(z)`` and ``ρ''(z)`` for ``z = (r / f_scale)²`` (scipy's definitions)."""
    if loss == "linear":
        return z, np.ones_like(z), np.zeros_like(z)
    if loss == "huber":
        big = z > 1
        sz = np.sqrt(np.where(big, z, 1.0))
        return np.where(big, 2 * sz - 1, z), np.where(big, 1 / sz, 1.0), np.where(big, -0.5 / sz ** 3, 0.0)
    if loss == "soft_l1":
        s = np.sqrt(1 + z)
        return 2 * (s - 1), 1 / s, -0.5 / s ** 3
    if loss == "cauchy":
        return np.log1p(z), 1 / (1 + z), -1 / (1 + z) ** 2
    if loss == "arctan":
        return np.arctan(z), 1 / (1 + z ** 2), -2 * z / (1 + z ** 2) ** 2
    raise ValueError(f"loss must be one of {LOSSES}; got {loss!r}")


def robust_cost(r, loss="linear", f_scale=1.0):
    """The objective ``0.5 Σ f_scale² ρ(r² / f_scale²)`` over all residual components (px²).

    >>> robust_cost(np.array([3.0, 4.0]))
    12.5
    >>> robust_cost(np.array([3.0, 0.5]), "huber", 1.0)   # 0.5 (2·3 - 1) + 0.5 · 0.25
    2.625
    """
    r = np.asarray(r, float).ravel()
    return float(0.5 * f_scale ** 2 * _rho((r / f_scale) ** 2, loss)[0].sum())


# ---------------------------------------------------------------------------------------------
# the result and the gauge
# ---------------------------------------------------------------------------------------------
@dataclass
class BundleResult:
    """What :func:`bundle_adjust` returns.

    Attributes
    ----------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
    X : (M, 3) ndarray
        The refined cameras (``x_cam = R @ X + t``) and points, in the gauge described by ``gauge``.
    camera_params : (V, k) ndarray
        The same cameras packed as ``[ω, t(, f, k1, k2)]``.
    cost_initial, cost_final : float
        ``0.5 · Σ r²`` in px² (plain squared error, whatever the loss).
    loss_cost_initial, loss_cost_final : float
        The objective actually minimised, ``0.5 · Σ f_scale² ρ(r²/f_scale²)`` (equal to the above for
        ``loss='linear'``).
    n_iter : int
        Iterations (Jacobian evaluations).
    n_eval : int
        Residual evaluations.
    seconds : float
        Wall time of the solve (set-up and checks included).
    success : bool
        True if a convergence test was met (not the iteration limit).
    message : str
    residuals : (n_obs, 2) ndarray
        Predicted minus observed pixels at the solution.
    solver : str
    free : (k · V + 3 · M,) bool ndarray
        Which columns of :func:`reprojection_jacobian` are free parameters in the gauge of the result
        (False: the anchor camera's pose, one translation coordinate of the scale camera, and whatever
        ``fixed_cameras``, ``fixed_points`` or fixed intrinsics held). ``J[:, free]`` has full rank at a
        regular solution and ``σ² (J[:, free]ᵀ J[:, free])⁻¹`` is a gauge-fixed covariance; quantities
        that do not depend on the gauge (relative poses, ratios of lengths) get the same covariance in
        every gauge.
    gauge : dict
        ``anchor`` (camera whose pose is held), ``scale_camera`` and ``baseline`` (the distance from the
        anchor's centre kept fixed), or empty when no gauge was imposed.
    """

    R: np.ndarray
    t: np.ndarray
    X: np.ndarray
    camera_params: np.ndarray
    cost_initial: float
    cost_final: float
    loss_cost_initial: float
    loss_cost_final: float
    n_iter: int
    n_eval: int
    seconds: float
    success: bool
    message: str
    residuals: np.ndarray
    solver: str
    free: np.ndarray = field(repr=False)
    gauge: dict = field(default_factory=dict)

    @property
    def n_free(self):
        """Number of free parameters ``d`` (after the gauge)."""
        return int(self.free.sum())

    def summary(self):
        """A JSON-friendly dict of the scalar results."""
        return dict(solver=self.solver, cost_initial=self.cost_initial, cost_final=self.cost_final,
                    loss_cost_initial=self.loss_cost_initial, loss_cost_final=self.loss_cost_final,
                    iterations=self.n_iter, evaluations=self.n_eval, seconds=self.seconds,
                    success=bool(self.success), message=self.message,
                    n_observations=int(self.residuals.shape[0]), n_free_parameters=self.n_free)


def _centres(cp):
    R = rotations_from_angle_axis(cp[:, :3])
    return -np.einsum("vji,vj->vi", R, cp[:, 3:6]), R


def _gauge_plan(cp, fixed_cameras, fixed_points, gauge):
    """Freeze the user's fixed cameras; choose the anchor and scale cameras of the gauge.

    Returns ``free_cam (V, k)`` (False for the held pose parameters) and the gauge ``info`` dict
    (empty when no gauge is imposed).
    """
    V, k = cp.shape
    free_cam = np.ones((V, k), bool)
    fc = np.unique(np.asarray(fixed_cameras if fixed_cameras is not None else [], dtype=np.int64).ravel())
    if fc.size and (fc.min() < 0 or fc.max() >= V):
        raise ValueError(f"fixed_cameras must index existing cameras 0..{V - 1}; got {fc.tolist()}")
    free_cam[fc, :6] = False
    if gauge is not None and gauge not in GAUGES:
        raise ValueError(f"gauge must be 'first-camera-and-scale' or None; got {gauge!r}")
    if gauge is None or fc.size >= 2 or (fixed_points is not None and fixed_points.sum() >= 3):
        return free_cam, {}                                     # nothing asked, or the fixed things hold it
    anchor = int(fc[0]) if fc.size else 0
    C, R = _centres(cp)
    dist = np.linalg.norm(C - C[anchor], axis=1)
    others = np.flatnonzero((np.arange(V) != anchor) & (dist > 1e-9 * max(dist.max(), 1e-300)))
    if not others.size:
        raise ValueError("gauge='first-camera-and-scale' needs a second camera with a different centre "
                         "(all camera centres coincide, or there is only one camera)")
    b = int(others[0])
    return free_cam, dict(anchor=anchor, scale_camera=b, baseline=float(dist[b]), R_anchor=R[anchor],
                          C_anchor=C[anchor])


def _apply_gauge(cp, X, free_cam, info):
    """Move the solution by the similarity that restores the gauge; return it and the gauge's columns.

    The similarity ``X' = s Q X + c`` puts the anchor camera back at its starting pose (``Q``, ``c``) and
    makes the distance from it to the scale camera its starting length (``s``); it changes no residual.
    The columns returned as held (for ``BundleResult.free``) are the anchor's six pose parameters and the
    coordinate ``j`` of the scale camera's translation that the scale moves most (the largest coordinate
    of ``-R_b (C_b - C_a)``): removing them from ``J`` removes the 7-dimensional null space.
    """
    free_cam = free_cam.copy()
    if not info:
        return cp, X, free_cam
    a, b = info["anchor"], info["scale_camera"]
    C, R = _centres(cp)
    Q = info["R_anchor"].T @ R[a]                                # R_a Qᵀ = R_anchor
    s = info["baseline"] / np.linalg.norm(C[b] - C[a])
    c = info["C_anchor"] - s * Q @ C[a]
    R_new = R @ Q.T
    C_new = s * C @ Q.T + c
    cp = cp.copy()
    cp[:, :3] = _angle_axis_from_rotations(R_new)
    cp[:, 3:6] = -np.einsum("vij,vj->vi", R_new, C_new)
    free_cam[a, :6] = False
    j = int(np.argmax(np.abs(R_new[b] @ (C_new[b] - C_new[a]))))
    free_cam[b, 3 + j] = False
    return cp, s * X @ Q.T + c, free_cam


# ---------------------------------------------------------------------------------------------
# solvers
# ---------------------------------------------------------------------------------------------
def _inv_sym3(A):
    """Inverse of a stack of symmetric 3×3 matrices, in closed form (adjugate / determinant)."""
    a, b, c = A[:, 0, 0], A[:, 0, 1], A[:, 0, 2]
    d, e, f = A[:, 1, 1], A[:, 1, 2], A[:, 2, 2]
    c00 = d * f - e * e
    c01 = c * e - b * f
    c02 = b * e - c * d
    c11 = a * f - c * c
    c12 = b * c - a * e
    c22 = a * d - b * b
    det = a * c00 + b * c01 + c * c02
    inv = np.stack([np.stack([c00, c01, c02], -1), np.stack([c01, c11, c12], -1),
                    np.stack([c02, c12, c22], -1)], axis=1)
    return inv / det[:, None, None]


class _SchurStructure:
    """Index bookkeeping for the reduced camera system, computed once per problem."""

    CHUNK = 8192

    def __init__(self, ci, pi, V, M):
        n = ci.shape[0]
        obs = np.arange(n)
        self.A_cam = sp.csr_matrix((np.ones(n), (ci, obs)), shape=(V, n))      # sums observations per camera
        self.A_pt = sp.csr_matrix((np.ones(n), (pi, obs)), shape=(M, n))       # ... per point
        # pairs of observations of the same point, o1 <= o2 (the reduced system is symmetric)
        order = np.argsort(pi, kind="stable")
        counts = np.bincount(pi, minlength=M)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        pos = np.empty(n, np.int64)
        pos[order] = np.arange(n)                                 # rank of each observation in its point's list
        rank = pos - starts[pi]
        n_partners = counts[pi] - rank                            # partners at or after itself
        o1 = np.repeat(obs, n_partners)
        first = np.repeat(pos, n_partners)
        o2 = order[first + (np.arange(o1.size) - np.repeat(np.cumsum(n_partners) - n_partners, n_partners))]
        off = o1 != o2                                            # the diagonal pairs are the observations
        o1, o2 = o1[off], o2[off]
        blk = ci[o1] * V + ci[o2]
        # chunks of pairs small enough to stay in cache; per chunk an indicator matrix that sums
        # each pair's k×k block into its (camera, camera) block of the reduced system
        self.chunks = []
        for s in range(0, o1.size, self.CHUNK):
            sl = slice(s, s + self.CHUNK)
            m = o1[sl].size
            A = sp.csr_matrix((np.ones(m), (blk[sl], np.arange(m))), shape=(V * V, m))
            self.chunks.append((o1[sl], o2[sl], A))
        self.A_diag = sp.csr_matrix((np.ones(n), (ci * (V + 1), obs)), shape=(V * V, n))
        self.n_pairs = o1.size
        self.V = V


def _lm_schur(cp0, X0, ci, pi, x, Ks, free_cam, free_pt, loss, f_scale, max_iter, tol, verbose):
    """Levenberg–Marquardt with the Schur complement; see :func:`bundle_adjust`. Returns a dict."""
    V, k = cp0.shape
    M = X0.shape[0]
    st = _SchurStructure(ci, pi, V, M)
    mask_c = free_cam[ci].astype(float)[:, None, :]                 # zero the frozen columns
    mask_p = free_pt[pi].astype(float)[:, None, None]
    frozen_c, frozen_p = ~free_cam, ~free_pt

    def cost_of(cp, X):
        r = _project(cp, X, ci, pi, Ks) - x
        return 0.5 * f_scale ** 2 * _rho((r / f_scale) ** 2, loss)[0].sum(), r

    cp, X = cp0.copy(), X0.copy()
    F, _ = cost_of(cp, X)
    mu, nu = None, 2.0
    n_iter, n_eval, status = 0, 1, "maximum number of iterations reached"
    success = False
    need_jac = True
    second_order = False
    x_norm = np.sqrt((cp ** 2).sum() + (X ** 2).sum())
    while n_iter < max_iter:
        if need_jac:
            u, Jc, Jp = _project(cp, X, ci, pi, Ks, jac=True)
            r = u - x
            n_iter += 1
            Jc, Jp = Jc * mask_c, Jp * mask_p
            if loss != "linear":
                # Robust loss: the gradient of 0.5 f² ρ(r²/f²) is ρ' r J. Far from the optimum we weight the
                # rows by sqrt(ρ') (IRLS: curvature ρ' JᵀJ, a convex model whatever the residuals). IRLS
                # overestimates the curvature of residuals beyond the scale, so its steps there are too short
                # and it converges only linearly; once the cost decrease slows (below 1e-3 relative) we switch
                # to the exact second-order curvature of the loss, ρ' + 2 z ρ'' (Triggs et al. Sec. 4.3; what
                # scipy uses from the start), floored at 0.01 ρ' to keep the model convex.
                z = (r / f_scale) ** 2
                _, d1, d2 = _rho(z, loss)
                hw = np.sqrt(np.maximum(d1 + 2 * z * d2, _CURVATURE_FLOOR * d1) if second_order else d1)
                r = r * d1 / hw
                Jc, Jp = Jc * hw[:, :, None], Jp * hw[:, :, None]
            JcT = np.swapaxes(Jc, 1, 2)
            U = (st.A_cam @ (JcT @ Jc).reshape(-1, k * k)).reshape(V, k, k)          # camera blocks
            Vp = (st.A_pt @ (np.swapaxes(Jp, 1, 2) @ Jp).reshape(-1, 9)).reshape(M, 3, 3)   # point blocks
            W = JcT @ Jp                                                # (n, k, 3) camera-point blocks
            gc = st.A_cam @ np.einsum("nai,na->ni", Jc, r)          # (V, k)
            gp = st.A_pt @ np.einsum("nai,na->ni", Jp, r)           # (M, 3)
            # frozen parameters: identity rows, zero gradient (their step is exactly 0)
            ic = np.nonzero(frozen_c)
            U[ic[0], ic[1], ic[1]] = 1.0
            Vp[frozen_p] = np.eye(3)
            Dc = np.clip(np.diagonal(U, axis1=1, axis2=2), 1e-6, 1e32)      # Marquardt scaling
            Dp = np.clip(np.diagonal(Vp, axis1=1, axis2=2), 1e-6, 1e32)
            g_inf = max(np.abs(gc).max(initial=0.0), np.abs(gp).max(initial=0.0))
            if mu is None:
                mu = 1e-4
            if g_inf <= 1e-14 * max(1.0, F):
                status, success = "gradient is zero to machine precision", True
                break
            need_jac = False
        # damped blocks, point inverses, reduced camera system
        Ua = U.copy()
        Ua[:, np.arange(k), np.arange(k)] += mu * Dc
        Va = Vp.copy()
        Va[:, np.arange(3), np.arange(3)] += mu * Dp
        Vinv = _inv_sym3(Va)
        Y = W @ Vinv[pi]                                            # W V⁻¹ per observation, (n, k, 3)
        S = -_reduced_camera_blocks(st, Y, W)
        S += _block_diag_dense(Ua)
        rhs = -(gc - st.A_cam @ np.einsum("nij,nj->ni", Y, gp[pi])).ravel()
        try:
            dc = scipy.linalg.cho_solve(scipy.linalg.cho_factor(S, lower=True, check_finite=False), rhs,
                                        check_finite=False).reshape(V, k)
        except np.linalg.LinAlgError:
            mu *= nu
            nu *= 2
            continue
        dc[frozen_c] = 0.0
        dp = np.einsum("mij,mj->mi", Vinv, -gp - st.A_pt @ np.einsum("nij,ni->nj", W, dc[ci]))
        dp[frozen_p] = 0.0
        h_norm = np.sqrt((dc ** 2).sum() + (dp ** 2).sum())
        xtol = 1e-2 * tol                                          # Ceres: 1e-8 with function tolerance 1e-6
        if h_norm <= xtol * (x_norm + xtol):
            status, success = "step size below xtol", True
            break
        pred = 0.5 * (mu * ((Dc * dc ** 2).sum() + (Dp * dp ** 2).sum()) - (gc * dc).sum() - (gp * dp).sum())
        cp_new, X_new = cp + dc, X + dp
        F_new, _ = cost_of(cp_new, X_new)
        n_eval += 1
        rho = (F - F_new) / pred if pred > 0 else -1.0
        if verbose:
            print(f"  lm-schur it {n_iter:3d}  cost {F:.6e} -> {F_new:.6e}  mu {mu:.2e}  gain {rho:+.3f}")
        if rho > 0 and np.isfinite(F_new):
            dF = F - F_new
            cp, X, F = cp_new, X_new, F_new
            x_norm = np.sqrt((cp ** 2).sum() + (X ** 2).sum())
            mu *= max(1 / 3, 1 - (2 * rho - 1) ** 3)
            nu = 2.0
            need_jac = True
            if dF <= _SECOND_ORDER_AFTER * F_new:
                second_order = True
            if dF <= tol * F_new or F_new == 0.0:
                status, success = "relative cost reduction below ftol", True
                break
        else:
            mu *= nu
            nu *= 2
            if mu > 1e32:
                status, success = "damping exceeded 1e32: no further reduction possible", True
                break
    return dict(cp=cp, X=X, n_iter=n_iter, n_eval=n_eval, success=success, message=status)


def _reduced_camera_blocks(st, Y, W):
    """``Σ_p W_p V_p⁻¹ W_pᵀ`` as a dense ``(V k, V k)`` matrix, from per-observation ``Y = W V⁻¹`` and ``W``.

    Block (c1, c2) sums ``Y_o1 W_o2ᵀ`` over the pairs of observations (o1 by c1, o2 by c2) of the same
    point: the diagonal pairs (o1 = o2) once, the others (o1 < o2) once and mirrored by symmetry.
    """
    n, k, _ = W.shape
    V = st.V
    Y2 = Y.reshape(n, 3 * k)
    Wt2 = np.ascontiguousarray(np.swapaxes(W, 1, 2)).reshape(n, 3 * k)
    G = np.zeros((V * V, k * k))
    for o1, o2, A in st.chunks:
        T = np.take(Y2, o1, axis=0).reshape(-1, k, 3) @ np.take(Wt2, o2, axis=0).reshape(-1, 3, k)
        G += A @ T.reshape(-1, k * k)
    Gd = st.A_diag @ (Y @ np.swapaxes(W, 1, 2)).reshape(n, k * k)

    def dense(B):
        return B.reshape(V, V, k, k).transpose(0, 2, 1, 3).reshape(V * k, V * k)

    G = dense(G)
    return G + G.T + dense(Gd)


def _block_diag_dense(blocks):
    V, k, _ = blocks.shape
    out = np.zeros((V, k, V, k))
    out[np.arange(V), :, np.arange(V), :] = blocks
    return out.reshape(V * k, V * k)


def _loss_callable(loss, second_order):
    """``loss`` as a callable for ``least_squares``, with the curvature model LM-Schur uses.

    ``least_squares`` scales each residual's Jacobian row by ``sqrt(ρ' + 2zρ'')`` (clamped at machine
    epsilon). With ``second_order=False`` we report ``ρ'' = 0``: IRLS, whose curvature ``ρ'`` stays positive
    whatever the residual. scipy's own choice, the exact curvature from the start, stalls from a far start
    where most residuals are beyond the scale (on the dinosaur with a Cauchy loss it ended 80 times above
    LM-Schur's cost after 300 iterations). With ``second_order=True``: the exact curvature floored at
    ``0.01 ρ'``, as in LM-Schur's second phase.
    """
    def rho(z):
        out = np.stack(_rho(z, loss))
        if second_order:
            floor = _CURVATURE_FLOOR * out[1]
            low = out[1] + 2 * z * out[2] < floor
            out[2] = np.where(low, (floor - out[1]) / (2 * np.maximum(z, 1e-300)), out[2])
        else:
            out[2] = 0.0
        return out

    rho.__name__ = f"{loss}_{'second_order' if second_order else 'irls'}"
    return rho


def _scipy(cp0, X0, ci, pi, x, Ks, free_cam, free_pt, loss, f_scale, max_iter, tol, verbose, scipy_jac,
           scipy_options):
    V, k = cp0.shape
    M = X0.shape[0]
    free = np.concatenate([free_cam.ravel(), np.repeat(free_pt, 3)])
    full0 = np.concatenate([cp0.ravel(), X0.ravel()])
    colmap = np.cumsum(free) - 1
    cols = _jacobian_structure(ci, pi, V, M, k)
    keep = free[cols.ravel()]
    n_free = int(free.sum())

    def unpack(z):
        full = full0.copy()
        full[free] = z
        return full[:V * k].reshape(V, k), full[V * k:].reshape(M, 3)

    def fun(z):
        cp, X = unpack(z)
        return (_project(cp, X, ci, pi, Ks) - x).ravel()

    def jac(z):
        cp, X = unpack(z)
        _, Jc, Jp = _project(cp, X, ci, pi, Ks, jac=True)
        return _assemble(Jc, Jp, cols, n_free, keep, colmap)

    kw = dict(x_scale="jac", f_scale=f_scale, ftol=tol, xtol=1e-2 * tol, gtol=1e-2 * tol, method="trf",
              verbose=2 if verbose else 0)
    if scipy_jac == "analytic":
        kw.update(jac=jac, tr_solver="lsmr")
    elif scipy_jac == "sparsity":
        mask = jacobian_sparsity(V, M, ci, pi, k)[:, free]
        kw.update(jac="2-point", jac_sparsity=mask, tr_solver="lsmr")
    elif scipy_jac == "dense":
        kw.update(jac="2-point", tr_solver="exact")
    else:
        raise ValueError(f"scipy_jac must be 'analytic', 'sparsity' or 'dense'; got {scipy_jac!r}")
    kw.update(scipy_options or {})
    z, n_iter, n_eval = full0[free], 0, 0
    # a robust loss in two phases, as LM-Schur: IRLS until the relative decrease is below 1e-3, then the
    # second-order curvature (unless the caller chose scipy's loss in scipy_options)
    phases = [("linear", tol)] if loss == "linear" else [(_loss_callable(loss, False), _SECOND_ORDER_AFTER),
                                                         (_loss_callable(loss, True), tol)]
    if "loss" in (scipy_options or {}):
        phases = [(scipy_options["loss"], tol)]
    for lossfn, ftol in phases:
        opts = dict(kw, loss=lossfn, ftol=max(ftol, tol), max_nfev=max(max_iter - n_eval, 1))
        res = least_squares(fun, z, **opts)
        z, n_iter, n_eval = res.x, n_iter + int(res.njev or res.nfev), n_eval + int(res.nfev)
        if n_eval >= max_iter:
            break
    cp, X = unpack(z)
    return dict(cp=cp, X=X, n_iter=n_iter, n_eval=n_eval, success=res.status > 0, message=res.message)


def solve(camera_params, points_3d, camera_indices, point_indices, points_2d, K=None, *, solver="lm-schur",
          loss="linear", f_scale=1.0, gauge="first-camera-and-scale", fixed_cameras=None, fixed_points=None,
          fix_intrinsics=False, max_iter=100, tol=1e-6, verbose=False, scipy_jac="analytic", scipy_options=None):
    """Bundle adjustment on packed parameters (the engine behind :func:`bundle_adjust` and the BAL CLI).

    Parameters
    ----------
    camera_params : (V, 6) or (V, 9) array_like
        Starting cameras, ``[ω, t]`` (pinhole, with ``K``) or ``[ω, t, f, k1, k2]`` (BAL, ``K=None``).
    points_3d, camera_indices, point_indices, points_2d, K
        As in :func:`reprojection_residuals`.
    fix_intrinsics : bool
        BAL model only: hold ``f, k1, k2`` of every camera (the camera block then has 6 free parameters).
    Others
        As in :func:`bundle_adjust`.

    Returns
    -------
    BundleResult
    """
    t0 = time.perf_counter()
    cp, X, ci, pi, x, Ks = _check_problem(camera_params, points_3d, camera_indices, point_indices, points_2d, K)
    V, k = cp.shape
    M = X.shape[0]
    if solver not in ("lm-schur", "scipy"):
        raise ValueError(f"solver must be 'lm-schur' or 'scipy'; got {solver!r}")
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {LOSSES}; got {loss!r}")
    if not (np.isfinite(f_scale) and f_scale > 0):
        raise ValueError(f"f_scale must be a positive number (pixels); got {f_scale}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter must be a positive integer; got {max_iter}")
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be positive; got {tol}")
    free_pt = np.ones(M, bool)
    if fixed_points is not None:
        fp = np.asarray(fixed_points, dtype=np.int64).ravel()
        if fp.size and (fp.min() < 0 or fp.max() >= M):
            raise ValueError(f"fixed_points must index existing points 0..{M - 1}")
        free_pt[fp] = False
    free_cam, info = _gauge_plan(cp, fixed_cameras, None if fixed_points is None else ~free_pt, gauge)
    if fix_intrinsics:
        if k != 9:
            raise ValueError("fix_intrinsics applies to the BAL model (9 camera parameters) only")
        free_cam[:, 6:] = False
    n_cam_obs = np.bincount(ci, minlength=V)
    no_obs = np.flatnonzero((n_cam_obs == 0) & free_cam.any(1))
    if no_obs.size:
        raise ValueError(f"camera(s) {no_obs[:10].tolist()} have no observations: their parameters are "
                         "undetermined (drop them, or hold them with fixed_cameras)")
    n_pt_obs = np.bincount(pi, minlength=M)
    no_obs = np.flatnonzero((n_pt_obs == 0) & free_pt)
    if no_obs.size:
        raise ValueError(f"point(s) {no_obs[:10].tolist()} have no observations: drop them before adjusting")
    n_free = int(free_cam.sum() + 3 * free_pt.sum())
    if info:                                                     # the gauge will hold 7 (or, anchor fixed, 1)
        n_free -= 1 if not free_cam[info["anchor"], :6].any() else 7
    if 2 * ci.shape[0] < n_free:
        raise ValueError(f"fewer residuals ({2 * ci.shape[0]} from {ci.shape[0]} observations) than free "
                         f"parameters ({n_free}): the problem is underdetermined")
    r0 = _project(cp, X, ci, pi, Ks) - x
    if not np.all(np.isfinite(r0)):
        bad = np.flatnonzero(~np.all(np.isfinite(r0), axis=1))
        raise ValueError(f"the starting point projects to non-finite pixels for observation(s) {bad[:5].tolist()} "
                         "(a point at a camera's centre?)")
    args = (cp, X, ci, pi, x, Ks, free_cam, free_pt, loss, float(f_scale), int(max_iter), float(tol), verbose)
    with single_threaded_blas():
        out = _lm_schur(*args) if solver == "lm-schur" else _scipy(*args, scipy_jac, scipy_options)
    cp_f, X_f, free_cam = _apply_gauge(out["cp"], out["X"], free_cam, info)
    info = {key: info[key] for key in ("anchor", "scale_camera", "baseline")} if info else {}
    r = _project(cp_f, X_f, ci, pi, Ks) - x
    R_f, t_f = Rt_from_camera_params(cp_f)
    free = np.concatenate([free_cam.ravel(), np.repeat(free_pt, 3)])
    return BundleResult(R=R_f, t=t_f, X=X_f, camera_params=cp_f, cost_initial=robust_cost(r0),
                        cost_final=robust_cost(r), loss_cost_initial=robust_cost(r0, loss, f_scale),
                        loss_cost_final=robust_cost(r, loss, f_scale), n_iter=out["n_iter"],
                        n_eval=out["n_eval"], seconds=time.perf_counter() - t0, success=bool(out["success"]),
                        message=str(out["message"]), residuals=r, solver=solver, free=free, gauge=info)


def bundle_adjust(R, t, X, camera_indices, point_indices, points_2d, K, *, solver="lm-schur", loss="linear",
                  f_scale=1.0, gauge="first-camera-and-scale", fixed_cameras=None, fixed_points=None,
                  max_iter=100, tol=1e-6, verbose=False, scipy_jac="analytic", scipy_options=None):
    """Refine calibrated cameras and 3D points by minimising the reprojection error (H&Z Sec. 18.1, A6.3).

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        Starting poses, ``x_cam = R @ X + t``.
    X : (M, 3) array_like
        Starting points.
    camera_indices, point_indices : (n_obs,) int array_like
    points_2d : (n_obs, 2) array_like
        Observation ``i`` is point ``point_indices[i]`` seen at pixel ``points_2d[i]`` by camera
        ``camera_indices[i]`` (e.g. from :func:`labutils.data.observations`).
    K : (3, 3) or (V, 3, 3) array_like
        Known calibration, shared or per camera (held fixed).
    solver : {'lm-schur', 'scipy'}
        Our Levenberg–Marquardt with the Schur complement, or :func:`scipy.optimize.least_squares`
        (``x_scale='jac'``, our analytic sparse Jacobian; ``scipy_jac='sparsity'`` uses finite
        differences with :func:`jacobian_sparsity`, ``'dense'`` dense finite differences).
    loss : {'linear', 'huber', 'cauchy', 'soft_l1', 'arctan'}
        Robust loss on each pixel coordinate, with inlier scale ``f_scale`` pixels (scipy's definition).
        LM-Schur minimises the same objective, by iteratively reweighted least squares (weights ``ρ'``)
        while far from the optimum, then with the exact second-order curvature of the loss
        ``ρ' + 2zρ''`` (floored at ``0.01 ρ'``) once the cost decrease slows below 1e-3 relative: IRLS
        alone converges linearly near the optimum (measured on the dinosaur with ``soft_l1``: 46
        iterations instead of 12), the exact curvature alone stalls from a far start. scipy gets
        the same two phases (two calls of ``least_squares`` with the loss as a callable), unless
        ``scipy_options`` names a ``loss`` of its own.
    f_scale : float
    gauge : {'first-camera-and-scale', None}
        How the 7-dof similarity ambiguity is fixed. The default holds the pose of the first camera at
        its starting value (6 dof) and the distance between the centres of the first two cameras
        (1 dof): without this, ``JᵀJ`` has a 7-dimensional null space, the optimum is a valley rather
        than a point, and covariances or comparisons between runs are meaningless. Both solvers iterate
        on all parameters (the damping keeps the steps finite along the valley, and this converges much
        faster than freezing parameters: on the dinosaur, 8 instead of 58 LM iterations, because a
        frozen perturbed first camera forces the whole scene through a slow, nonlinear rigid motion); the
        solution is then moved by the similarity that restores the gauge exactly (it changes no
        residual). With ``fixed_cameras`` the first fixed camera is the anchor, and with two or more
        fixed cameras, or three or more fixed points, nothing more is imposed. ``None`` imposes nothing.
    fixed_cameras : sequence of int, optional
        Cameras whose pose is held (e.g. the already registered cameras of an incremental SfM).
    fixed_points : sequence of int, optional
        Points held fixed (e.g. all of them for a PnP pose refinement).
    max_iter : int
        Iteration limit (LM: Jacobian evaluations; scipy: ``max_nfev``).
    tol : float
        Stop when an accepted step lowers the cost by less than ``tol`` times the cost, or the step is
        shorter than ``0.01 tol · ‖x‖`` (scipy: ``ftol = tol``, ``xtol = gtol = 0.01 tol``). The default 1e-6
        is Ceres's ``function_tolerance`` (and 1e-8 its ``parameter_tolerance``); use 1e-10 or less to
        converge to machine precision (noise-free data).
    scipy_jac : {'analytic', 'sparsity', 'dense'}
        For ``solver='scipy'``: the Jacobian it uses (see ``solver``).
    scipy_options : dict, optional
        Extra keywords for :func:`scipy.optimize.least_squares`, e.g. ``dict(tr_options=dict(atol=1e-10,
        btol=1e-10))``: tighter LSMR tolerances make each step dearer but far fewer steps are needed on
        bundle-adjustment problems (measured on the dinosaur: 86 instead of > 1000 iterations).
    verbose : bool

    Returns
    -------
    BundleResult
        See :class:`BundleResult`; ``cost_*`` are ``0.5 · Σ r²`` in px².

    Raises
    ------
    ValueError
        Wrong shapes, non-finite values, indices of missing cameras or points, a free camera or a point
        without observations, fewer residuals than free parameters, or an unknown option.

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> from labutils.data import observations
    >>> s = make_scene(60, 4, noise_px=0.0, rng=np.random.default_rng(0))
    >>> ci, pi, x = observations(s.x_true)
    >>> res = bundle_adjust(s.R, s.t, s.X + 0.01, ci, pi, x, s.K, tol=1e-12)
    >>> res.X.shape, res.cost_final < 1e-12, res.n_free == 4 * 6 - 7 + 3 * 60
    ((60, 3), True, True)
    """
    cp = camera_params_from_Rt(R, t)
    return solve(cp, X, camera_indices, point_indices, points_2d, K, solver=solver, loss=loss, f_scale=f_scale,
                 gauge=gauge, fixed_cameras=fixed_cameras, fixed_points=fixed_points, max_iter=max_iter,
                 tol=tol, verbose=verbose, scipy_jac=scipy_jac, scipy_options=scipy_options)


# ---------------------------------------------------------------------------------------------
# command line: solve a BAL file
# ---------------------------------------------------------------------------------------------
def solve_bal(problem, *, solver="lm-schur", fix_intrinsics=False, **kwargs):
    """Bundle-adjust a :class:`labutils.bal.BALProblem`; returns ``(solved BALProblem, BundleResult)``.

    By default every BAL parameter is refined (pose, f, k1, k2 of each camera, and the points), as the
    BAL benchmark and Ceres's BAL example do; ``fix_intrinsics=True`` holds f, k1, k2.
    Other keywords go to :func:`solve` (``loss``, ``gauge``, ``max_iter``, ``tol``, ...).
    """
    from .bal import BALProblem

    res = solve(problem.camera_params, problem.points_3d, problem.camera_indices, problem.point_indices,
                problem.points_2d, None, solver=solver, fix_intrinsics=fix_intrinsics, **kwargs)
    solved = BALProblem(camera_params=res.camera_params, points_3d=res.X, camera_indices=problem.camera_indices,
                        point_indices=problem.point_indices, points_2d=problem.points_2d)
    return solved, res


def main(argv=None):
    """``python -m labutils.bundle PROBLEM.txt --solver {lm-schur,scipy} --out SOLVED.txt [--fix-intrinsics] [--json]``.

    Reads a BAL file, solves it, writes the solution in BAL format and prints a summary (JSON with
    ``--json``). A malformed file or a bad problem prints ``error: ...`` (naming the line) to stderr,
    writes nothing and exits with status 2.
    """
    import argparse
    import json
    import sys

    from .bal import BALFormatError, read_bal, write_bal

    ap = argparse.ArgumentParser(prog="python -m labutils.bundle",
                                 description="Bundle-adjust a BAL ('Bundle Adjustment in the Large') problem file.")
    ap.add_argument("problem", help="BAL problem file (.txt or .txt.bz2)")
    ap.add_argument("--solver", choices=("lm-schur", "scipy"), default="lm-schur")
    ap.add_argument("--out", required=True, help="where to write the solved problem (BAL format)")
    ap.add_argument("--fix-intrinsics", action="store_true", help="hold f, k1, k2 of every camera")
    ap.add_argument("--loss", choices=LOSSES, default="linear")
    ap.add_argument("--f-scale", type=float, default=1.0, help="inlier scale of the robust loss, pixels")
    ap.add_argument("--gauge", choices=("first-camera-and-scale", "none"), default="first-camera-and-scale")
    ap.add_argument("--max-iter", type=int, default=100)
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    args = ap.parse_args(argv)
    try:
        problem = read_bal(args.problem)
        solved, res = solve_bal(problem, solver=args.solver, fix_intrinsics=args.fix_intrinsics, loss=args.loss,
                                f_scale=args.f_scale, gauge=None if args.gauge == "none" else args.gauge,
                                max_iter=args.max_iter, tol=args.tol)
        write_bal(args.out, solved)
    except (BALFormatError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    summary = dict(problem=str(args.problem), out=str(args.out), n_cameras=problem.n_cameras,
                   n_points=problem.n_points, **res.summary())
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"{args.problem}: {problem.n_cameras} cameras, {problem.n_points} points, "
              f"{problem.n_observations} observations")
        print(f"{res.solver}: cost 0.5·Σr² {res.cost_initial:.6e} -> {res.cost_final:.6e} in {res.n_iter} "
              f"iterations, {res.seconds:.2f} s ({res.message}); wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
