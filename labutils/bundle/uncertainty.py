"""How precise can bundle adjustment be? The predicted pose covariance (the Cramér–Rao bound) in
the gauge of a similarity alignment (notebook 06; the experiments that test it are :mod:`labutils.sfm.noise_study`).

The theory in five lines
------------------------
With Gaussian pixel noise of standard deviation σ on every coordinate, bundle adjustment is the
maximum-likelihood (ML) estimate and, to first order, its parameter error is
``δθ = (JᵀJ)⁻ Jᵀ ε`` (for residuals ``r = u(θ) - x`` and measurements ``x = x_true + ε``) with covariance
``σ² (JᵀJ)⁻`` (H&Z Sec. 5.2.2–5.2.3: backward propagation
of covariance, over-parametrisation; J is the reprojection Jacobian at the truth). A reconstruction
is only defined up to a similarity, so ``JᵀJ`` has a 7-dimensional null space (3 rotations, 3 translations,
1 scale: the *gauge*, Triggs et al. 2000, Sec. 9) and "the" covariance depends on how the gauge is
fixed. What is measured is gauge-free: the errors *after* the estimated camera centres have been
aligned to the true ones by the least-squares similarity (Umeyama). Linearising that alignment gives
a linear map ``A`` from parameter errors to aligned errors with ``A N = 0`` on the gauge directions
``N`` (an S-transformation), so ``Σ_e = σ² A (JᵀJ)⁻ Aᵀ`` is the same for every generalised inverse:
that is the bound the empirical errors are compared with.

Error vector per camera ``i``: ``e_i = (φ_i, c_i)``, where ``R_aligned R_trueᵀ = exp([φ_i]×)``
(radians; the rotation error in degrees is ``|φ_i|``) and ``c_i = C_aligned - C_true`` (world units).

References: Hartley & Zisserman (H&Z) Sec. 5.2; B. Triggs, P. McLauchlan, R. Hartley, A. Fitzgibbon,
"Bundle adjustment — a modern synthesis", 2000, Sec. 9 (gauge freedom); S. Umeyama, PAMI 1991;
W. Baarda, "S-transformations and criterion matrices", 1973.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..core.geometry import angle_axis_from_rotation, camera_center, left_jacobian_so3, skew
from ..core.validation import (
    as_array,
    as_calibration,
    as_count,
    as_points,
    as_positive,
    as_rotations,
    as_translations,
)
from .gauge import gauge_basis
from .reprojection import as_indices, camera_params_from_Rt, reprojection_jacobian


# --------------------------------------------------------------------------------------------- checks
def _check_Rt(R, t):
    R = as_rotations(R, "R")
    t = as_translations(t, "t", n=len(R), like_name="R")
    if R.shape[0] < 3:
        raise ValueError(f"need at least 3 cameras to align centres by a similarity; got {R.shape[0]}")
    return R, t


def _check_observations(camera_indices, point_indices, n_cameras, n_points):
    ci = as_indices(camera_indices, "camera_indices", None, n_cameras, "camera", upper_name="R")
    pi = as_indices(point_indices, "point_indices", ci.shape[0], n_points, "point", upper_name="X")
    if ci.size == 0:
        raise ValueError("camera_indices and point_indices are empty: no observations")
    return ci.astype(np.intp), pi.astype(np.intp)


# ------------------------------------------------------------------------------------- the gauge
def camera_perturbation_map(R, t):
    """Per-camera linear map from parameter errors ``(δω, δt)`` to pose errors ``(a, c)``.

    ``a`` is the rotation error in the world-to-camera rotation, ``R̂ = exp([a]×) R``, and ``c`` the
    centre error; from ``C = -Rᵀ t``: ``a = J_l(ω) δω`` and ``c = -Rᵀ [t]× a - Rᵀ δt``.

    Returns
    -------
    D : (V, 6, 6) ndarray

    >>> camera_perturbation_map(np.stack([np.eye(3)] * 3), np.zeros((3, 3))).shape
    (3, 6, 6)
    """
    R, t = _check_Rt(R, t)
    Jl = left_jacobian_so3(angle_axis_from_rotation(R))
    Rt = np.swapaxes(R, 1, 2)
    D = np.zeros((len(R), 6, 6))
    D[:, :3, :3] = Jl
    D[:, 3:, :3] = -Rt @ np.stack([skew(v) for v in t]) @ Jl
    D[:, 3:, 3:] = -Rt
    return D


def alignment_map(R, t):
    """The linearised similarity alignment of camera centres (Umeyama), as a matrix.

    If the estimate is off the truth by ``(a_i, c_i)`` per camera, the aligning similarity
    ``(1 + λ) exp([q]×) C + u`` is, to first order, the least-squares solution ``g = (q, λ, u)`` of
    ``c_i + B_i g ≈ 0`` with ``B_i = [-[C_i]×, C_i, I]``; so the aligned errors are
    ``c_al = (I - B (BᵀB)⁻¹ Bᵀ) c`` (a projection: the S-transformation) and ``φ_i = a_i - R_i q``
    (``R_aligned = R̂ exp(-[q]×)``).

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        The true poses (the linearisation point).

    Returns
    -------
    A : (6 V, 6 V) ndarray
        Maps ``(a_1, c_1, …, a_V, c_V)`` to ``(φ_1, c_al_1, …, φ_V, c_al_V)``.

    >>> alignment_map(np.stack([np.eye(3)] * 3), np.eye(3)).shape
    (18, 18)
    """
    R, t = _check_Rt(R, t)
    V = len(R)
    C = camera_center(R, t)
    B = np.zeros((V, 3, 7))
    B[:, :, :3] = -np.stack([skew(c) for c in C])
    B[:, :, 3] = C
    B[:, :, 4:] = np.eye(3)
    B = B.reshape(3 * V, 7)
    BtB = B.T @ B
    if np.linalg.cond(BtB) > 1e12:
        raise ValueError("the camera centres are collinear (or coincide): the similarity alignment is not determined")
    G = np.linalg.solve(BtB, B.T)                          # g = -G c
    A = np.zeros((V, 6, V, 6))
    A[np.arange(V), :3, np.arange(V), :3] = np.eye(3)      # φ = a ...
    A[:, :3, :, 3:] = np.einsum("vij,jwk->viwk", R, G[:3].reshape(3, V, 3))   # ... + R_i G_q c
    A[:, 3:, :, 3:] = (np.eye(3 * V) - B @ G).reshape(V, 3, V, 3)
    return A.reshape(6 * V, 6 * V)


def pose_error_map(R, t):
    """``alignment_map(R, t) @ blockdiag(camera_perturbation_map(R, t))``: from BA camera-parameter
    errors ``(δω_i, δt_i)`` to aligned pose errors ``(φ_i, c_i)``. Shape ``(6 V, 6 V)``.

    Every gauge direction is mapped to zero: ``pose_error_map(R, t) @ gauge_basis(R, t, X)[:6 V] ≈ 0``.
    """
    A = alignment_map(R, t)
    D = camera_perturbation_map(R, t)
    V = len(D)
    return np.einsum("rwk,wkl->rwl", A.reshape(6 * V, V, 6), D).reshape(6 * V, 6 * V)


# ------------------------------------------------------------------------------ information matrix
def _jacobian(R, t, X, camera_indices, point_indices, K):
    return sp.csr_matrix(reprojection_jacobian(camera_params_from_Rt(R, t), X, camera_indices, point_indices, K))


def camera_information(J, n_cameras, n_points):
    """Schur complement of the point block in ``JᵀJ``: the cameras' information matrix (H&Z A6.3.1).

    ``S = U - W V⁻¹ Wᵀ`` with ``JᵀJ = [[U, W], [Wᵀ, V]]``; ``V`` is block-diagonal (3×3 per point),
    so this costs one 3×3 inverse per point. The camera block of any generalised inverse of ``JᵀJ``
    is a generalised inverse of ``S``.

    Parameters
    ----------
    J : (2 n_obs, 6 V + 3 M) sparse matrix or ndarray
        The reprojection Jacobian, cameras first (6 per camera), then points (3 each).
    n_cameras, n_points : int

    Returns
    -------
    S : (6 V, 6 V) ndarray

    Raises
    ------
    ValueError
        If the shape does not match, or a point is not determined (seen by fewer than 2 views, or
        along a single ray).
    """
    n_cameras, n_points = as_count(n_cameras, "n_cameras"), as_count(n_points, "n_points")
    J = sp.csr_matrix(J)
    nc, npnt = 6 * n_cameras, 3 * n_points
    if J.shape[1] != nc + npnt:
        raise ValueError(f"J has {J.shape[1]} columns; expected 6 * {n_cameras} + 3 * {n_points} = {nc + npnt}")
    Jc, Jp = J[:, :nc], J[:, nc:]
    U = (Jc.T @ Jc).toarray()
    W = (Jc.T @ Jp).tocsr()
    Hp = (Jp.T @ Jp).tocoo()
    if np.any(Hp.row // 3 != Hp.col // 3):
        raise ValueError("the point block of JᵀJ is not 3×3 block-diagonal: is J ordered cameras first, then points?")
    blocks = np.zeros((n_points, 3, 3))
    np.add.at(blocks, (Hp.row // 3, Hp.row % 3, Hp.col % 3), Hp.data)
    scale = np.maximum(np.abs(blocks).max(axis=(1, 2)), 1e-300)
    cond = np.linalg.cond(blocks / scale[:, None, None])
    if np.any(~np.isfinite(cond) | (cond > 1e12)):
        bad = np.flatnonzero(~np.isfinite(cond) | (cond > 1e12))
        raise ValueError(f"points {bad[:5].tolist()}{' ...' if bad.size > 5 else ''} are not determined "
                         "(seen by fewer than 2 views, or from one direction only)")
    Vinv = sp.block_diag(list(np.linalg.inv(blocks)), format="csr")
    return U - (W @ Vinv @ W.T).toarray()


def _gauge_inverse(H, N):
    """A generalised inverse of the symmetric ``H`` whose null space is spanned by ``N``.

    Jacobi-scale ``H``, add the orthogonal projector on the (scaled) null space and invert; the
    result differs from the pseudo-inverse only along ``N``, which every gauge-invariant quantity
    ignores.
    """
    d = np.sqrt(np.maximum(np.diag(H), 1e-300))
    Hs = H / d[:, None] / d[None, :]
    Q, _ = np.linalg.qr(N * d[:, None])
    Haug = Hs + np.mean(np.diag(Hs)) * (Q @ Q.T)
    w = np.linalg.eigvalsh(Haug)
    if w[0] <= 1e-12 * w[-1]:
        raise ValueError(f"JᵀJ has more than the {N.shape[1]} similarity gauge freedoms (smallest scaled "
                         f"eigenvalue {w[0]:.2e} of {w[-1]:.2e}): some camera or point is not determined")
    Hinv = np.linalg.inv(Haug)
    return Hinv / d[:, None] / d[None, :]


# -------------------------------------------------------------------------------- the prediction
def effective_terms(cov):
    """How many independent χ²₁ terms one Monte Carlo trial of ``|e|²`` is worth, ``e ~ N(0, cov)``.

    ``|e|²`` has mean ``tr Σ`` and variance ``2 tr Σ²``, like a sum of ``n_eff = (tr Σ)² / tr Σ²``
    independent χ²₁ terms (1 ≤ n_eff ≤ the dimension; correlated errors make it small). The RMS of
    ``|e|`` over T trials then has a relative standard deviation of ``1 / sqrt(2 T n_eff)``.

    >>> effective_terms(np.eye(6)), effective_terms(np.diag([1.0, 0, 0]))
    (6.0, 1.0)
    """
    cov = as_array(cov, "cov", "(d, d)")
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1] or cov.size == 0 or not np.all(np.isfinite(cov)):
        raise ValueError(f"cov must be a finite square (d, d) matrix; got shape {cov.shape}")
    if not np.sum(cov * cov) > 0:
        raise ValueError("cov is zero: no terms to count")
    return float(np.trace(cov) ** 2 / np.sum(cov * cov))


@dataclass
class PosePrediction:
    """Predicted covariance of the aligned pose errors, and the RMS errors it implies.

    Attributes
    ----------
    cov : (6 V, 6 V) ndarray
        Covariance of ``(φ_1, c_1, …, φ_V, c_V)``: rotation errors in radians, centre errors in
        world units, after the similarity alignment of the centres.
    sigma : float
        The pixel noise it was computed for (it scales as σ²).
    scene_size : float
        RMS distance of the true centres from their mean (the unit of relative centre errors).
    rot_rms_deg : (V,) ndarray
        Predicted RMS rotation error per camera, degrees: ``sqrt(tr Σ_φi)``.
    centre_rms_rel : (V,) ndarray
        Predicted RMS centre error per camera over ``scene_size``.
    """

    cov: np.ndarray
    sigma: float
    scene_size: float
    rot_rms_deg: np.ndarray
    centre_rms_rel: np.ndarray

    @property
    def n_cameras(self):
        return len(self.rot_rms_deg)

    def _blocks(self, which):
        V = self.n_cameras
        sl = slice(0, 3) if which == "rot" else slice(3, 6)
        return self.cov.reshape(V, 6, V, 6)[:, sl, :, sl].reshape(3 * V, 3 * V)

    @property
    def rot_rms_deg_all(self):
        """RMS rotation error over all cameras (degrees)."""
        return float(np.sqrt(np.mean(self.rot_rms_deg ** 2)))

    @property
    def centre_rms_rel_all(self):
        """RMS relative centre error over all cameras."""
        return float(np.sqrt(np.mean(self.centre_rms_rel ** 2)))

    def n_effective(self, which="rot"):
        """Effective number of independent squared terms in one trial's sum of squared errors
        (:func:`effective_terms` of the rotation or centre blocks of ``cov``)."""
        return effective_terms(self._blocks(which))

    def mc_relative_sd(self, n_trials, which="rot"):
        """Relative standard deviation of a Monte Carlo RMS error over ``n_trials`` trials:
        ``1 / sqrt(2 n_trials n_eff)`` (half that of the mean square)."""
        return float(1.0 / np.sqrt(2.0 * n_trials * self.n_effective(which)))

    def trials_needed(self, rel_tol, z=3.0, which="rot"):
        """Fewest trials for which ``z`` Monte Carlo standard deviations of the RMS error stay
        within ``rel_tol``: ``ceil(z² / (2 n_eff rel_tol²))``."""
        return int(np.ceil(z ** 2 / (2.0 * self.n_effective(which) * rel_tol ** 2)))


def aligned_pose_covariance(R, t, X, camera_indices, point_indices, K, sigma=1.0, *, jacobian=None, method="schur"):
    """Predicted covariance of the pose errors after similarity alignment (the Cramér–Rao bound).

    ``Σ_e = σ² A (JᵀJ)⁻ Aᵀ`` with J the reprojection Jacobian at the truth (H&Z Sec. 5.2.3) and
    ``A`` = :func:`pose_error_map` (the linearised "BA parameters → Umeyama alignment → errors",
    zero on the 7 gauge directions, so any generalised inverse gives the same ``Σ_e``).

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    X : (M, 3) array_like
        The true cameras and points (the linearisation point), V >= 3, centres not collinear.
    camera_indices, point_indices : (n_obs,) int array_like
        Which camera sees which point (as in :func:`labutils.data.loaders.observations`).
    K : (3, 3) array_like
    sigma : float
        Standard deviation of the pixel noise on each coordinate.
    jacobian : sparse matrix, optional
        The reprojection Jacobian (default: :func:`labutils.bundle.adjust.reprojection_jacobian` at the truth).
    method : {'schur', 'dense'}
        ``'schur'``: eliminate the points (a 6V×6V system); ``'dense'``: invert the full
        ``(6V + 3M)²`` information matrix (a cross-check).

    Returns
    -------
    cov : (6 V, 6 V) ndarray
        Covariance of ``(φ_1, c_1, …, φ_V, c_V)``, radians and world units.
    """
    R, t = _check_Rt(R, t)
    X = as_points(X, "X", dim=3)
    K = as_calibration(K, "K")
    ci, pi = _check_observations(camera_indices, point_indices, len(R), len(X))
    sigma = as_positive(sigma, "sigma", allow_zero=True)
    V, M = len(R), len(X)
    J = _jacobian(R, t, X, ci, pi, K) if jacobian is None else sp.csr_matrix(jacobian)
    if J.shape != (2 * ci.size, 6 * V + 3 * M):
        raise ValueError(f"jacobian must have shape {(2 * ci.size, 6 * V + 3 * M)}; got {J.shape}")
    N = gauge_basis(R, t, X)
    E = pose_error_map(R, t)
    if method == "schur":
        S = camera_information(J, V, M)
        Sg = _gauge_inverse(S, N[:6 * V])
        cov = E @ Sg @ E.T
    elif method == "dense":
        H = (J.T @ J).toarray()
        Hg = _gauge_inverse(H, N)
        cov = E @ Hg[:6 * V, :6 * V] @ E.T
    else:
        raise ValueError(f"method must be 'schur' or 'dense'; got {method!r}")
    cov = sigma ** 2 * 0.5 * (cov + cov.T)
    return cov


def s_transformation(N, G):
    """The S-transformation onto a gauge: ``P = I - N (Gᵀ N)⁻¹ Gᵀ`` (Baarda 1973; Triggs et al. Sec. 9).

    A parameter error ``δ`` known up to the gauge directions ``N`` is moved along them until it
    satisfies the gauge's linearised constraints ``Gᵀ δ = 0``: ``P N = 0``, ``Gᵀ P = 0``, ``P² = P``.
    The covariance in that gauge is ``P Σ Pᵀ`` for any generalised inverse ``Σ`` of the information.

    Parameters
    ----------
    N : (n, k) ndarray
        Gauge directions (e.g. :func:`gauge_basis`, k = 7).
    G : (n, k) ndarray
        Constraint normals (e.g. :func:`first_camera_gauge`); ``Gᵀ N`` must be invertible.

    Returns
    -------
    P : (n, n) ndarray

    >>> N = np.array([[1.0], [1.0]]); G = np.array([[1.0], [0.0]])   # gauge: shift both; fix the first
    >>> s_transformation(N, G) @ np.array([2.0, 5.0])
    array([0., 3.])
    """
    N, G = np.asarray(N, float), np.asarray(G, float)
    if N.ndim != 2 or G.shape != N.shape:
        raise ValueError(f"N and G must both have shape (n, k); got {N.shape} and {G.shape}")
    GtN = G.T @ N
    if np.linalg.cond(GtN) > 1e12:
        raise ValueError("the constraints G do not fix the gauge (Gᵀ N is singular)")
    return np.eye(N.shape[0]) - N @ np.linalg.solve(GtN, G.T)


def first_camera_gauge(R, t, X, anchor=0, scale_camera=1):
    """Linearised constraints of the gauge :func:`labutils.bundle.bundle_adjust` uses by default.

    The pose of camera ``anchor`` is held (6 constraints: ``δω_a = 0``, ``δt_a = 0``) and the
    distance between the centres of ``anchor`` and ``scale_camera`` (1 constraint:
    ``uᵀ (δC_b - δC_a) = 0`` with ``u`` the unit baseline).

    Returns
    -------
    G : (6 V + 3 M, 7) ndarray
        Constraint normals for :func:`s_transformation`.
    """
    R, t = _check_Rt(R, t)
    X = as_points(X, "X", dim=3)
    V, M = len(R), len(X)
    if not (0 <= anchor < V and 0 <= scale_camera < V and anchor != scale_camera):
        raise ValueError(f"anchor and scale_camera must be two different cameras in 0..{V - 1}")
    C = camera_center(R, t)
    u = C[scale_camera] - C[anchor]
    if np.linalg.norm(u) < 1e-12 * max(np.abs(C).max(), 1e-300):
        raise ValueError("the anchor and scale cameras have the same centre: the scale is not fixed")
    u = u / np.linalg.norm(u)
    D = camera_perturbation_map(R, t)                      # rows 3: of D map (δω, δt) to δC
    G = np.zeros((6 * V + 3 * M, 7))
    G[6 * anchor:6 * anchor + 6, :6] = np.eye(6)
    G[6 * scale_camera:6 * scale_camera + 6, 6] = u @ D[scale_camera, 3:]
    G[6 * anchor:6 * anchor + 6, 6] = -u @ D[anchor, 3:]
    return G


def gauge_pose_covariance(R, t, X, camera_indices, point_indices, K, sigma=1.0, *, G=None, jacobian=None):
    """Predicted covariance of the pose errors ``(a_i, c_i)`` in a fixed gauge, without any alignment.

    This is what the errors of a bundle adjustment run in that gauge (default: the first camera and
    one baseline held, as :func:`labutils.bundle.bundle_adjust` does) look like when they are
    compared with the truth directly: zero at the anchor, growing away from it. It is *not* what is
    measured after a similarity alignment (:func:`aligned_pose_covariance`).

    Parameters
    ----------
    G : (6 V + 3 M, 7) ndarray, optional
        Gauge constraints (default: :func:`first_camera_gauge` with cameras 0 and 1).
    Other parameters as in :func:`aligned_pose_covariance`.

    Returns
    -------
    cov : (6 V, 6 V) ndarray
        Covariance of ``(a_1, c_1, …, a_V, c_V)`` (``R̂ = exp([a]×) R``, ``c = Ĉ - C``).
    """
    R, t = _check_Rt(R, t)
    X = as_points(X, "X", dim=3)
    K = as_calibration(K, "K")
    ci, pi = _check_observations(camera_indices, point_indices, len(R), len(X))
    V, M = len(R), len(X)
    J = _jacobian(R, t, X, ci, pi, K) if jacobian is None else sp.csr_matrix(jacobian)
    N = gauge_basis(R, t, X)
    G = first_camera_gauge(R, t, X) if G is None else np.asarray(G, float)
    Sg = _gauge_inverse(camera_information(J, V, M), N[:6 * V])
    # the S-transformation acts on cameras and points, but the constraints here involve cameras
    # only, so its camera block maps camera errors to camera errors
    if np.any(G[6 * V:]):
        raise ValueError("this function supports gauge constraints on camera parameters only")
    P = s_transformation(N, G)[:6 * V, :6 * V]
    D = camera_perturbation_map(R, t)
    Dblk = sp.block_diag(list(D)).toarray()
    cov = Dblk @ P @ Sg @ P.T @ Dblk.T
    return sigma ** 2 * 0.5 * (cov + cov.T)


def predict_pose_errors(R, t, X, camera_indices, point_indices, K, sigma=1.0, **kwargs):
    """Predicted RMS rotation (degrees) and relative centre errors after alignment.

    Same arguments as :func:`aligned_pose_covariance`.

    Returns
    -------
    PosePrediction

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.core.scene import observations
    >>> s = make_scene(60, 6, layout="turntable", noise_px=0, rng=np.random.default_rng(0))
    >>> p = predict_pose_errors(s.R, s.t, s.X, *observations(s.x_true)[:2], s.K, sigma=1.0)
    >>> p.cov.shape, p.rot_rms_deg.shape
    ((36, 36), (6,))
    """
    cov = aligned_pose_covariance(R, t, X, camera_indices, point_indices, K, sigma, **kwargs)
    R, t = np.asarray(R, float), np.asarray(t, float)
    V = len(R)
    C = camera_center(R, t)
    size = float(np.sqrt(((C - C.mean(0)) ** 2).sum(1).mean()))
    var = np.diagonal(cov).reshape(V, 6)
    return PosePrediction(cov=cov, sigma=float(sigma), scene_size=size,
                          rot_rms_deg=np.degrees(np.sqrt(var[:, :3].sum(1))),
                          centre_rms_rel=np.sqrt(var[:, 3:].sum(1)) / size)
