"""How precise can bundle adjustment be? The predicted pose covariance (the Cramér–Rao bound) in
the gauge of a similarity alignment, and the helpers of the noise study (notebook 06).

The theory in five lines
------------------------
With Gaussian pixel noise of standard deviation σ on every coordinate, bundle adjustment is the
maximum-likelihood (ML) estimate and, to first order, its parameter error is
``δθ = -(JᵀJ)⁻ Jᵀ ε`` with covariance ``σ² (JᵀJ)⁻`` (H&Z Sec. 5.2.2–5.2.3: backward propagation
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
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ._validation import as_matrix, as_points
from .bundle import left_jacobian_so3
from .geometry import angle_axis_from_rotation, skew
from .metrics import pose_errors


# --------------------------------------------------------------------------------------------- checks
def _check_Rt(R, t):
    R = np.asarray(R, dtype=float)
    t = np.asarray(t, dtype=float)
    if R.ndim != 3 or R.shape[1:] != (3, 3):
        raise ValueError(f"R must have shape (V, 3, 3); got shape {R.shape}")
    if t.shape != (R.shape[0], 3):
        raise ValueError(f"t must have shape ({R.shape[0]}, 3) to match R; got shape {t.shape}")
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        raise ValueError("R and t must be finite (no NaN or inf)")
    if R.shape[0] < 3:
        raise ValueError(f"need at least 3 cameras to align centres by a similarity; got {R.shape[0]}")
    if np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() > 1e-6 or np.any(np.linalg.det(R) < 0):
        raise ValueError("R must hold rotation matrices (orthonormal, det +1)")
    return R, t


def _check_observations(camera_indices, point_indices, n_cameras, n_points):
    ci = np.asarray(camera_indices)
    pi = np.asarray(point_indices)
    if ci.ndim != 1 or ci.shape != pi.shape:
        raise ValueError(f"camera_indices and point_indices must be 1-D of equal length; got {ci.shape} and {pi.shape}")
    if ci.size == 0 or not (np.issubdtype(ci.dtype, np.integer) and np.issubdtype(pi.dtype, np.integer)):
        raise ValueError("camera_indices and point_indices must be non-empty integer arrays")
    if ci.min() < 0 or ci.max() >= n_cameras or pi.min() < 0 or pi.max() >= n_points:
        raise ValueError(f"an index is out of range (cameras 0..{n_cameras - 1}, points 0..{n_points - 1})")
    return ci.astype(np.intp), pi.astype(np.intp)


# ------------------------------------------------------------------------------------- rotations
def _angle_axis_stack(R):
    return np.stack([angle_axis_from_rotation(r) for r in R])


# ------------------------------------------------------------------------------------- the gauge
def gauge_basis(R, t, X):
    """The 7 infinitesimal similarities of a reconstruction, in bundle-adjustment parameters.

    The parameters are those of :mod:`labutils.bundle`: per camera the angle-axis vector ``ω`` and
    ``t`` (6 numbers), then the points (3 numbers each). A similarity ``X' = (1 + λ) exp([q]×) X + u``
    moves them by ``δX = q × X + λ X + u``, ``δω = -J_l(ω)⁻¹ R q``, ``δt = λ t - R u`` and leaves every
    projection unchanged, so the reprojection Jacobian maps each column to zero (Triggs et al. Sec. 9).

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    X : (M, 3) array_like

    Returns
    -------
    N : (6 V + 3 M, 7) ndarray
        Columns: rotation about x, y, z; translation along x, y, z; scale.

    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(20, 4, rng=np.random.default_rng(0))
    >>> gauge_basis(s.R, s.t, s.X).shape
    (84, 7)
    """
    R, t = _check_Rt(R, t)
    X = as_points(X, "X", dim=3)
    V, M = len(R), len(X)
    Jl = left_jacobian_so3(_angle_axis_stack(R))
    N = np.zeros((6 * V + 3 * M, 7))
    cam = N[:6 * V].reshape(V, 6, 7)
    pts = N[6 * V:].reshape(M, 3, 7)
    cam[:, :3, :3] = -np.linalg.solve(Jl, R)               # δω for the rotation q
    cam[:, 3:, 3:6] = -R                                   # δt for the translation u
    cam[:, 3:, 6] = t                                      # δt for the scale λ
    pts[:, :, :3] = -np.stack([skew(x) for x in X])        # q × X = -[X]× q
    pts[:, :, 3:6] = np.eye(3)
    pts[:, :, 6] = X
    return N


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
    Jl = left_jacobian_so3(_angle_axis_stack(R))
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
    C = -np.einsum("vji,vj->vi", R, t)
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
    from .bundle import camera_params_from_Rt, reprojection_jacobian

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
    cov = np.asarray(cov, float)
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
        Which camera sees which point (as in :func:`labutils.data.observations`).
    K : (3, 3) array_like
    sigma : float
        Standard deviation of the pixel noise on each coordinate.
    jacobian : sparse matrix, optional
        The reprojection Jacobian (default: :func:`labutils.bundle.reprojection_jacobian` at the truth).
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
    K = as_matrix(K, "K", (3, 3))
    ci, pi = _check_observations(camera_indices, point_indices, len(R), len(X))
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"sigma must be a finite non-negative number; got {sigma}")
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
    C = -np.einsum("vji,vj->vi", R, t)
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
    K = as_matrix(K, "K", (3, 3))
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
    >>> from labutils.synthetic import make_scene
    >>> from labutils.data import observations
    >>> s = make_scene(60, 6, layout="turntable", noise_px=0, rng=np.random.default_rng(0))
    >>> p = predict_pose_errors(s.R, s.t, s.X, *observations(s.x_true)[:2], s.K, sigma=1.0)
    >>> p.cov.shape, p.rot_rms_deg.shape
    ((36, 36), (6,))
    """
    cov = aligned_pose_covariance(R, t, X, camera_indices, point_indices, K, sigma, **kwargs)
    R, t = np.asarray(R, float), np.asarray(t, float)
    V = len(R)
    C = -np.einsum("vji,vj->vi", R, t)
    size = float(np.sqrt(((C - C.mean(0)) ** 2).sum(1).mean()))
    var = np.diagonal(cov).reshape(V, 6)
    return PosePrediction(cov=cov, sigma=float(sigma), scene_size=size,
                          rot_rms_deg=np.degrees(np.sqrt(var[:, :3].sum(1))),
                          centre_rms_rel=np.sqrt(var[:, 3:].sum(1)) / size)


# ------------------------------------------------------------------------------- study helpers
def noisy_observations(x_true, sigma, rng, outlier_ratio=0.0, image_size=None):
    """Add Gaussian pixel noise (and optionally outliers) to noise-free projections.

    Parameters
    ----------
    x_true : (V, M, 2) array_like
        Noise-free pixels, NaN where unseen.
    sigma : float
        Standard deviation per coordinate (pixels).
    rng : numpy.random.Generator
    outlier_ratio : float
        Fraction (0 ≤ · < 1) of the visible observations replaced by uniform random pixels.
    image_size : (width, height), optional
        Required when ``outlier_ratio > 0``.

    Returns
    -------
    x_meas : (V, M, 2) ndarray
    outliers : (V, M) bool ndarray

    >>> x = np.zeros((2, 3, 2)); x[0, 0] = np.nan
    >>> xm, out = noisy_observations(x, 1.0, np.random.default_rng(0))
    >>> xm.shape, bool(np.isnan(xm[0, 0, 0])), int(out.sum())
    ((2, 3, 2), True, 0)
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError("rng must be a numpy.random.Generator, e.g. np.random.default_rng(0)")
    x_true = np.asarray(x_true, dtype=float)
    if x_true.ndim != 3 or x_true.shape[-1] != 2:
        raise ValueError(f"x_true must have shape (V, M, 2); got shape {x_true.shape}")
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"sigma must be a finite non-negative number; got {sigma}")
    if not 0 <= outlier_ratio < 1:
        raise ValueError(f"outlier_ratio must be in [0, 1); got {outlier_ratio}")
    seen = np.all(np.isfinite(x_true), axis=-1)
    x = x_true + rng.normal(scale=sigma, size=x_true.shape) if sigma > 0 else x_true.copy()
    outliers = np.zeros(seen.shape, bool)
    if outlier_ratio > 0:
        if image_size is None:
            raise ValueError("image_size is needed to draw outliers")
        vi, pi = np.nonzero(seen)
        pick = rng.random(vi.size) < outlier_ratio
        outliers[vi[pick], pi[pick]] = True
        x[vi[pick], pi[pick]] = rng.uniform([0, 0], image_size, size=(pick.sum(), 2))
    return x, outliers


def ba_from_truth(scene, x_meas, *, loss="linear", f_scale=1.0, reject_px=None, final_loss="linear", max_iter=100,
                  tol=1e-10, R0=None, t0=None, X0=None):
    """Bundle adjustment of ``x_meas`` started from the true cameras and points (the ML estimate).

    A stand-in for the full pipeline when only the ML estimate's behaviour matters: with noise of
    a few pixels the optimum found from the truth is the one a good initialisation would reach.

    Parameters
    ----------
    scene : labutils.data.Scene
        Supplies ``K`` and the starting point (the truth) unless ``R0, t0, X0`` are given.
    x_meas : (V, M, 2) array_like
        Observations, NaN where unseen.
    loss, f_scale : passed to :func:`labutils.bundle.bundle_adjust` (``'huber'``, ``'cauchy'``... are robust).
    reject_px : float, optional
        The outlier-removal step: after a first adjustment drop the observations whose
        reprojection error exceeds ``reject_px`` pixels and adjust again with ``final_loss`` (default
        plain least squares: the ML estimate on the kept observations); a point left with fewer than
        two observations is dropped (NaN in ``X``).
    max_iter, tol :
        Passed to :func:`labutils.bundle.bundle_adjust`; the tight default ``tol`` matters: an
        adjustment started from the truth and stopped early is biased towards the truth.
    R0, t0, X0 : optional
        Another starting point than the truth.

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
    X : (M, 3) ndarray
    info : dict
        ``'seconds'``, ``'n_iter'``, ``'cost_final'``, ``'kept'`` ((n_obs,) bool), ``'n_obs'``.
    """
    from .bundle import bundle_adjust
    from .data import observations

    R0 = scene.R if R0 is None else R0
    t0 = scene.t if t0 is None else t0
    X0 = scene.X if X0 is None else X0
    ci, pi, x2d = observations(x_meas)
    tic = time.perf_counter()
    res = bundle_adjust(R0, t0, X0, ci, pi, x2d, scene.K, loss=loss, f_scale=f_scale, max_iter=max_iter, tol=tol)
    n_iter = res.n_iter
    kept = np.ones(ci.size, bool)
    info_X = res.X
    if reject_px is not None:
        err = np.linalg.norm(np.asarray(res.residuals).reshape(-1, 2), axis=1)
        kept = err <= reject_px
        # a point left with fewer than 2 observations is dropped (its X becomes NaN)
        n_left = np.bincount(pi[kept], minlength=len(X0))
        kept &= n_left[pi] >= 2
        pts = np.flatnonzero(n_left >= 2)
        remap = np.full(len(X0), -1)
        remap[pts] = np.arange(pts.size)
        res2 = bundle_adjust(res.R, res.t, res.X[pts], ci[kept], remap[pi[kept]], x2d[kept], scene.K,
                             loss=final_loss, f_scale=f_scale, max_iter=max_iter, tol=tol)
        X = np.full((len(X0), 3), np.nan)
        X[pts] = res2.X
        res = res2
        n_iter += res.n_iter
        info_X = X
    info = dict(seconds=time.perf_counter() - tic, n_iter=n_iter, cost_final=float(res.cost_final),
                kept=kept, n_obs=int(ci.size))
    return res.R, res.t, info_X, info


def reconstruct_without_ba(tracks, K, order, rng, *, threshold_px=10.0, min_angle_deg=1.0, refine=True):
    """Incremental reconstruction *without* bundle adjustment: the "before BA" of the noise study.

    The same steps as :func:`labutils.sfm.incremental_sfm` minus every joint adjustment: the relative
    pose of the first two views of ``order`` (:func:`labutils.sfm.two_view_reconstruction`), then each
    further view in ``order`` by P3P-RANSAC on the points triangulated so far
    (:func:`labutils.pnp.pnp_ransac`, with ``refine`` its own pose only), and the tracks it completes
    triangulated (:func:`labutils.sfm.triangulate_tracks`). Errors of early views propagate to later
    ones: that is the drift bundle adjustment removes.

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        Pixels, NaN where unseen.
    K : (3, 3) array_like
    order : sequence of int
        The views in the order to add them, e.g. ``Reconstruction.order`` of an SfM run.
    rng : numpy.random.Generator
    threshold_px, min_angle_deg : float
        As in :func:`labutils.sfm.incremental_sfm`.
    refine : bool
        Refine each new pose on its inliers (still no joint adjustment).

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        NaN for views not registered.
    X : (T, 3) ndarray
        NaN for tracks not triangulated.
    """
    from .pnp import pnp_ransac
    from .sfm import triangulate_tracks, two_view_reconstruction

    tracks = np.asarray(tracks, float)
    if tracks.ndim != 3 or tracks.shape[-1] != 2:
        raise ValueError(f"tracks must have shape (V, T, 2); got {tracks.shape}")
    V, T = tracks.shape[:2]
    order = [int(v) for v in order]
    if len(order) < 2 or len(set(order)) != len(order) or min(order) < 0 or max(order) >= V:
        raise ValueError(f"order must list at least two different views in 0..{V - 1}")
    Ks = np.broadcast_to(as_matrix(K, "K", (3, 3)), (V, 3, 3))
    seen = np.all(np.isfinite(tracks), axis=-1)
    R, t, X = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan), np.full((T, 3), np.nan)
    i, j = order[:2]
    idx = np.flatnonzero(seen[i] & seen[j])
    R[j], t[j], X[idx], _ = two_view_reconstruction(tracks[i, idx], tracks[j, idx], Ks[i], Ks[j], rng,
                                                    threshold_px=threshold_px, min_angle_deg=min_angle_deg)
    R[i], t[i] = np.eye(3), np.zeros(3)
    for v in order[2:]:
        idx = np.flatnonzero(seen[v] & np.isfinite(X[:, 0]))
        if idx.size < 6:
            continue
        try:
            R[v], t[v], _ = pnp_ransac(X[idx], tracks[v, idx], Ks[v], threshold=threshold_px, rng=rng, refine=refine)
        except ValueError:
            continue
        reg = np.flatnonzero(np.isfinite(t[:, 0]))
        new = np.flatnonzero(~np.isfinite(X[:, 0]) & seen[v] & (seen[reg].sum(0) >= 2))
        if new.size:
            X[new] = triangulate_tracks(tracks[:, new], Ks, R, t, reg, seen[:, new], max_error_px=threshold_px,
                                        min_angle_deg=min_angle_deg)[0]
    return R, t, X


def refine_reconstruction(rec, tracks, K, *, tol=1e-10, max_iter=50):
    """One last plain bundle adjustment of a reconstruction on its inlier observations, to convergence.

    :func:`labutils.sfm.incremental_sfm` stops its final adjustment at a relative cost change of
    1e-6 (for speed); that leaves errors of about 1e-6 degrees on noise-free data. Running on to
    ``tol`` takes a few more iterations.

    Parameters
    ----------
    rec : labutils.sfm.Reconstruction
        Uses ``R, t, X, registered, inliers``.
    tracks : (V, T, 2) array_like
        The observations it was built from.
    K : (3, 3) array_like

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        NaN for the views that were not registered.
    """
    from .bundle import bundle_adjust

    cams = np.flatnonzero(rec.registered)
    pts = np.flatnonzero(rec.inliers[cams].any(0))
    ci, pi = np.nonzero(rec.inliers[np.ix_(cams, pts)])
    x = np.asarray(tracks, float)[cams[ci], pts[pi]]
    # gauge=None: the errors are measured after alignment, and (at the time of writing) the LM-Schur
    # solver's default gauge moves an exact solution by ~1e-6 degrees
    res = bundle_adjust(rec.R[cams], rec.t[cams], rec.X[pts], ci, pi, x, K, tol=tol, max_iter=max_iter, gauge=None)
    R, t = np.full(np.shape(rec.R), np.nan), np.full(np.shape(rec.t), np.nan)
    R[cams], t[cams] = res.R, res.t
    return R, t


def rms_errors(rot_deg, centre_rel, axis=None):
    """RMS of per-camera errors (NaN-aware), e.g. over cameras and trials: ``(rot, centre)``."""
    return (np.sqrt(np.nanmean(np.square(rot_deg), axis=axis)),
            np.sqrt(np.nanmean(np.square(centre_rel), axis=axis)))


def loglog_slope(sigmas, errors):
    """Least-squares slope of ``log(errors)`` against ``log(sigmas)`` (1 for errors ∝ σ).

    >>> round(loglog_slope([0.5, 1, 2], [0.1, 0.2, 0.4]), 12)
    1.0
    """
    s, e = np.asarray(sigmas, float), np.asarray(errors, float)
    if s.shape != e.shape or s.size < 2 or np.any(s <= 0) or np.any(e <= 0):
        raise ValueError("need at least two positive sigmas and positive errors of the same shape")
    return float(np.polyfit(np.log(s), np.log(e), 1)[0])


class Progress:
    """A progress counter that works everywhere: an ipywidgets bar in a live notebook, and a
    line of text (printed at every ``every``-th step and at the end) in any case, so that headless
    runs (nbval, CI) still show where they are."""

    def __init__(self, total, label="", every=None):
        self.total, self.label, self.n = int(total), label, 0
        self.every = every or max(1, self.total // 5)
        self.bar = None
        try:
            import ipywidgets
            from IPython import get_ipython
            from IPython.display import display

            if get_ipython() is not None:
                self.bar = ipywidgets.IntProgress(value=0, min=0, max=self.total, description=label)
                display(self.bar)
        except ImportError:
            pass
        self.tic = time.perf_counter()

    def step(self):
        self.n += 1
        if self.bar is not None:
            self.bar.value = self.n
        if self.n % self.every == 0 or self.n == self.total:
            print(f"{self.label} {self.n}/{self.total} ({time.perf_counter() - self.tic:.1f} s)", flush=True)


@dataclass
class NoiseStudy:
    """Pose errors of one pipeline over noise levels and trials (see :func:`run_noise_study`).

    Attributes
    ----------
    sigmas : list of float
    rot_deg, centre_rel : dict float -> (T, V) ndarray
        Per trial and camera, after similarity alignment of the registered cameras' centres; NaN for
        a camera the pipeline did not register, and for every camera of a failed trial.
    estimates : dict float -> list of (R, t)
        The raw estimates (the pipeline's own gauge; NaN for a failed trial), for single-trial plots.
    seconds : dict float -> (T,) ndarray
        Wall time of each pipeline call.
    failures : dict float -> list of str
        Why trials failed (the pipeline raised ``ValueError``, or registered fewer than 3 views).
    """

    sigmas: list
    rot_deg: dict
    centre_rel: dict
    estimates: dict
    seconds: dict
    failures: dict

    def flag_wrong_basins(self, pred, factor=10.0):
        """Count as failed the trials whose RMS rotation error exceeds ``factor`` times the predicted
        RMS (σ > 0 only); return how many.

        For the ML estimate a trial's ``Σ|φ_i|²`` is a Gaussian quadratic form; exceeding ``factor² = 100``
        times its mean is at most as likely as a χ²₁ exceeding 100 (all weight on one mode, the worst
        case): about 1e-23. Such a trial did not reach the ML optimum: the pipeline converged in a wrong
        basin (or its linearisation no longer holds).
        Its errors become NaN and the reason is added to ``failures``.
        """
        n = 0
        for s in self.sigmas:
            if s <= 0:
                continue
            d = self.rot_deg[s]
            seen = np.isfinite(d)
            r = np.sqrt(np.sum(np.where(seen, d, 0.0) ** 2, axis=1) / np.maximum(seen.sum(1), 1))
            bad = seen.any(1) & (r > factor * pred.rot_rms_deg_all * s)
            for k in np.flatnonzero(bad):
                self.failures[s].append(f"trial {k}: RMS rotation error {r[k]:.3g} deg, over {factor:g}x the bound "
                                        "(a wrong basin)")
            self.rot_deg[s][bad] = np.nan
            self.centre_rel[s][bad] = np.nan
            n += int(bad.sum())
        return n

    def n_ok(self, sigma):
        """Trials at ``sigma`` that produced at least 3 registered views."""
        return int(np.sum(np.any(np.isfinite(self.rot_deg[sigma]), axis=1)))

    def rms(self, which="rot"):
        """RMS error over cameras and successful trials, one per sigma: ``(S,)`` (NaN if none)."""
        d = self.rot_deg if which == "rot" else self.centre_rel
        return np.array([np.sqrt(np.nanmean(d[s] ** 2)) if np.isfinite(d[s]).any() else np.nan for s in self.sigmas])

    def trial_rms(self, which="rot"):
        """RMS error over the cameras of each trial: ``(S, T)`` array (NaN for a failed trial; with
        ``common_noise`` row ``k`` of every level is the same noise pattern)."""
        d = self.rot_deg if which == "rot" else self.centre_rel
        out = []
        for s in self.sigmas:
            seen = np.isfinite(d[s])
            sq = np.sum(np.where(seen, d[s], 0.0) ** 2, axis=1)
            out.append(np.where(seen.any(1), np.sqrt(sq / np.maximum(seen.sum(1), 1)), np.nan))
        return np.array(out)

    def table(self, pred=None):
        """A printable table: per sigma the successful / total trials, mean ± sd and RMS of both
        errors and, given a :class:`PosePrediction` for σ = 1, the predicted RMS and the ratio
        empirical / predicted."""
        head = f"{'sigma':>6} {'ok/trials':>9} | {'rot mean ± sd (deg)':>22} {'RMS':>9}"
        head += f" {'pred':>9} {'ratio':>6}" if pred else ""
        head += f" | {'centre mean ± sd (rel)':>24} {'RMS':>9}" + (f" {'pred':>9} {'ratio':>6}" if pred else "")
        lines = [head]
        for s, r_rms, c_rms in zip(self.sigmas, self.rms("rot"), self.rms("centre")):
            r, c = self.rot_deg[s], self.centre_rel[s]
            ok = f"{self.n_ok(s)}/{len(r)}"
            if not np.isfinite(r).any():
                lines.append(f"{s:6.2f} {ok:>9} | (every trial failed: {self.failures[s][0][:60]})")
                continue
            row = f"{s:6.2f} {ok:>9} | {np.nanmean(r):10.3g} ± {np.nanstd(r):9.3g} {r_rms:9.3g}"
            if pred:
                row += f" {pred.rot_rms_deg_all * s:9.3g} {r_rms / (pred.rot_rms_deg_all * s) if s > 0 else np.nan:6.3f}"
            row += f" | {np.nanmean(c):11.3g} ± {np.nanstd(c):10.3g} {c_rms:9.3g}"
            if pred:
                row += f" {pred.centre_rms_rel_all * s:9.3g} {c_rms / (pred.centre_rms_rel_all * s) if s > 0 else np.nan:6.3f}"
            lines.append(row)
        return "\n".join(lines)


def run_noise_study(scene, pipelines, sigmas, n_trials, rng, label="trials", keep_estimates=True, common_noise=False):
    """Run pipelines on noisy copies of ``scene.x_true`` and measure their aligned pose errors.

    Every trial draws one noise sample and gives the same observations to every pipeline, so
    pipelines can be compared trial by trial.

    Parameters
    ----------
    scene : labutils.data.Scene
        Ground truth: ``R, t`` and the noise-free projections ``x_true`` (NaN where unseen).
    pipelines : callable or dict str -> callable
        ``reconstruct(scene, x_meas, sigma, rng) -> (R, t)``, NaN poses for unregistered views: the
        pipeline under study (the incremental SfM, or BA from the truth). It is told the noise level,
        as a real pipeline is told its thresholds. A ``ValueError`` it raises counts as a failed trial.
    sigmas : sequence of float
        Pixel noise levels.
    n_trials : int or dict float -> int
        Trials per level.
    rng : numpy.random.Generator
        Draws the noise and is passed on to the pipelines.
    common_noise : bool
        Common random numbers: trial ``k`` of every level uses the same standard-normal draw ``ε_k``,
        scaled by σ (``x = x_true + σ ε_k``). The errors of an estimator that is linear in the noise
        then scale exactly with σ, so their log–log slope measures the nonlinearity alone, free of
        Monte Carlo scatter. (Levels are then not independent of each other.)

    Returns
    -------
    NoiseStudy, or dict str -> NoiseStudy when ``pipelines`` is a dict.
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError("rng must be a numpy.random.Generator, e.g. np.random.default_rng(0)")
    single = callable(pipelines)
    pipes = {"pipeline": pipelines} if single else dict(pipelines)
    if not pipes or not all(callable(f) for f in pipes.values()):
        raise ValueError("pipelines must be a callable or a non-empty dict of callables")
    sigmas = [float(s) for s in sigmas]
    counts = {s: int(n_trials[s] if isinstance(n_trials, dict) else n_trials) for s in sigmas}
    if min(counts.values()) < 1:
        raise ValueError(f"need at least one trial per noise level; got {counts}")
    progress = Progress(sum(counts.values()), label)
    V = scene.n_views
    base = rng.normal(size=(max(counts.values()),) + np.shape(scene.x_true)) if common_noise else None
    out = {name: NoiseStudy(sigmas=sigmas, rot_deg={}, centre_rel={}, estimates={}, seconds={}, failures={})
           for name in pipes}
    for s in sigmas:
        for st in out.values():
            st.rot_deg[s], st.centre_rel[s] = np.full((counts[s], V), np.nan), np.full((counts[s], V), np.nan)
            st.estimates[s], st.seconds[s], st.failures[s] = [], np.zeros(counts[s]), []
        for k in range(counts[s]):
            if common_noise:
                x_meas = scene.x_true + s * base[k]
            else:
                x_meas, _ = noisy_observations(scene.x_true, s, rng)
            for name, reconstruct in pipes.items():
                st = out[name]
                tic = time.perf_counter()
                why = None
                try:
                    R, t = reconstruct(scene, x_meas, s, rng)
                    R, t = np.asarray(R, float), np.asarray(t, float)
                except ValueError as exc:
                    R, t = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan)
                    why = f"trial {k}: {str(exc).splitlines()[0]}"
                st.seconds[s][k] = time.perf_counter() - tic
                ok = np.all(np.isfinite(R), axis=(1, 2)) & np.all(np.isfinite(t), axis=1)
                if ok.sum() >= 3:
                    st.rot_deg[s][k, ok], st.centre_rel[s][k, ok] = pose_errors(R[ok], t[ok], scene.R[ok], scene.t[ok])
                elif why is None:
                    why = f"trial {k}: only {ok.sum()} views registered"
                if why is not None:
                    st.failures[s].append(why)
                if keep_estimates:
                    st.estimates[s].append((R, t))
            progress.step()
    return out["pipeline"] if single else out
