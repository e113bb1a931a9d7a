"""The camera of a photo set without a chessboard: one shared focal length from the pairwise fundamental matrices,
then one shared focal length and radial distortion refined with the cameras and points.

- :func:`focal_from_fundamentals` — self-calibration by the essential-matrix constraint (Mendonça & Cipolla, CVPR
  1999; H&Z Sec. 19.3): for the right ``K``, every ``E = Kᵀ F K`` has two equal singular values. With the principal
  point at the image centre and square pixels only ``f`` is unknown; it minimises the median over the pairs of
  ``(σ1 - σ2) / (σ1 + σ2)``, searched on a logarithmic grid, then refined.
- :func:`refine_shared_intrinsics` — bundle adjustment with ``f``, ``k1``, ``k2`` shared by all views (the radial
  model of :func:`labutils.calibrate.lens.distort`, principal point fixed), maximum likelihood on the inliers with
  a Gaussian prior on ``log f`` and on ``k1, k2`` that keeps weak geometry from running away (a prior's pull is
  ``(value - centre) / σ_prior`` against residuals in units of the pixel noise, which is estimated from the data).
  Its covariance (Schur complement of the points, pseudo-inverse for the gauge; ``f`` and ``k`` are gauge
  invariant) gives the standard deviations.
"""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.optimize import least_squares, minimize_scalar
from scipy.spatial.transform import Rotation

from ..core.geometry import left_jacobian_so3, skew
from ..core.validation import as_array, as_calibration, as_count, as_positive, as_rotations, as_tracks

__all__ = ["SharedIntrinsics", "focal_from_fundamentals", "refine_shared_intrinsics"]

RAYLEIGH_MEDIAN = float(np.sqrt(2 * np.log(2)))     # median of |r| for 2-D N(0, σ² I) residuals is 1.1774 σ


def _asymmetry(F, f, c):
    K = np.array([[f, 0.0, c[0]], [0.0, f, c[1]], [0.0, 0.0, 1.0]])
    s = np.linalg.svd(K.T[None] @ F @ K[None], compute_uv=False)
    return (s[:, 0] - s[:, 1]) / (s[:, 0] + s[:, 1])


def focal_from_fundamentals(Fs: ArrayLike, principal_point: ArrayLike, size: float, *, span: tuple = (0.25, 5.0),
                            n_grid: int = 120) -> tuple:
    """Self-calibrated focal length from the fundamental matrices of many pairs (module docstring).

    Parameters
    ----------
    Fs : (P, 3, 3) array_like
        Fundamental matrices, ``x2ᵀ F x1 = 0``, of pairs of views of one camera (P >= 1).
    principal_point : (2,) array_like
        In pixels (the image centre).
    size : float
        The image's longer side in pixels: the search runs over ``f`` in ``span`` times it.
    span : (float, float)
    n_grid : int

    Returns
    -------
    f : float
    curve : (n_grid, 2) ndarray
        ``(f, median asymmetry)`` on the grid, for a plot.
    sharpness : float
        The curve's minimum over its median: near 0 a clear minimum, near 1 a flat curve (f is not determined by
        these pairs: e.g. pure translation, or optical axes all meeting in one point).

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> from labutils.twoview import fundamental_from_pose
    >>> from labutils.core import relative_pose
    >>> s = make_scene(50, 4, rng=np.random.default_rng(1))
    >>> Fs = [fundamental_from_pose(s.K, s.K, *relative_pose(s.R[0], s.t[0], s.R[k], s.t[k])) for k in (1, 2, 3)]
    >>> f, _, _ = focal_from_fundamentals(Fs, s.K[:2, 2], max(s.image_size))
    >>> bool(abs(f / s.K[0, 0] - 1) < 1e-6)
    True
    """
    F = as_array(Fs, "Fs", "(P, 3, 3)")
    if F.ndim != 3 or F.shape[1:] != (3, 3) or len(F) == 0:
        raise ValueError(f"Fs must have shape (P, 3, 3) with P >= 1; got shape {F.shape}")
    if not np.all(np.isfinite(F)) or np.any(np.linalg.norm(F, axis=(1, 2)) == 0):
        raise ValueError("Fs has NaN, inf or all-zero matrices")
    c = as_array(principal_point, "principal_point", "(2,)")
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise ValueError(f"principal_point must be 2 finite numbers; got {principal_point!r}")
    size = as_positive(size, "size")
    lo, hi = (as_positive(v, "span") for v in span) if len(span) == 2 else (None, None)
    if lo is None or not lo < hi:
        raise ValueError(f"span must be two factors (low, high) with low < high; got {span!r}")
    n_grid = as_count(n_grid, "n_grid", 3)
    F = F / np.linalg.norm(F, axis=(1, 2))[:, None, None]
    grid = np.geomspace(lo * size, hi * size, n_grid)
    cost = np.array([np.median(_asymmetry(F, f, c)) for f in grid])
    k = int(np.argmin(cost))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, n_grid - 1)]
    best = minimize_scalar(lambda lf: np.median(_asymmetry(F, np.exp(lf), c)), bounds=(np.log(lo), np.log(hi)),
                           method="bounded", options=dict(xatol=1e-9))
    f = float(np.exp(best.x)) if best.fun <= cost[k] else float(grid[k])
    return f, np.column_stack([grid, cost]), float(min(best.fun, cost[k]) / max(np.median(cost), 1e-300))


@dataclass
class SharedIntrinsics:
    """What :func:`refine_shared_intrinsics` returns.

    Attributes
    ----------
    K : (3, 3) ndarray
    dist : (2,) ndarray
        ``(k1, k2)``.
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
    X : (T, 3) ndarray
        NaN rows stay NaN.
    f_sd, k_sd, c_sd : float, (2,) ndarray, (2,) ndarray
        Standard deviations (pixels; unitless; pixels), from the covariance at the optimum (0 for what was held).
    sigma_px : float
        The pixel noise, estimated robustly (the median residual length over 1.1774, Rayleigh's) at the optimum;
        the residuals are weighted by it, so that the priors pull with their stated strength.
    rms_px : (float, float)
        RMS reprojection error before and after.
    n_obs : int
    success : bool
    """

    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    X: np.ndarray
    f_sd: float
    k_sd: np.ndarray
    c_sd: np.ndarray
    sigma_px: float
    rms_px: tuple
    n_obs: int
    success: bool


NI = 5          # shared parameters: log f, k1, k2, cx, cy


class _Problem:
    def __init__(self, x, ci, pi, R0, V, M):
        self.x, self.ci, self.pi, self.R0, self.V, self.M = x, ci, pi, R0, V, M

    def unpack(self, p):
        V, M = self.V, self.M
        w = p[NI:NI + 3 * V].reshape(V, 3)
        t = p[NI + 3 * V:NI + 6 * V].reshape(V, 3)
        X = p[NI + 6 * V:].reshape(M, 3)
        R = self.R0 @ Rotation.from_rotvec(w).as_matrix()       # R = R0 exp([w]x): no singularity near the start
        return np.exp(p[0]), p[1], p[2], p[3:5], R, t, X

    def project(self, p):
        f, k1, k2, c, R, t, X = self.unpack(p)
        Xc = np.einsum("nij,nj->ni", R[self.ci], X[self.pi]) + t[self.ci]
        xn = Xc[:, :2] / Xc[:, 2:3]
        r2 = np.sum(xn ** 2, axis=1, keepdims=True)
        return f * xn * (1 + k1 * r2 + k2 * r2 ** 2) + c

    def jacobian(self, p, free):
        """The residuals' Jacobian (in pixels); rotations by ``R0 exp([w]x)``:
        ``∂(R0 exp([w]x) X)/∂w = -R0 [exp([w]x) X]x J_l(w)`` (:func:`labutils.core.geometry.left_jacobian_so3`).
        ``free`` (NI,) bool: the columns of shared parameters held fixed are zero."""
        V, M, ci, pi = self.V, self.M, self.ci, self.pi
        f, k1, k2 = np.exp(p[0]), p[1], p[2]
        w = p[NI:NI + 3 * V].reshape(V, 3)
        E = Rotation.from_rotvec(w).as_matrix()
        R = self.R0 @ E
        t = p[NI + 3 * V:NI + 6 * V].reshape(V, 3)
        X = p[NI + 6 * V:].reshape(M, 3)
        Y = np.einsum("nij,nj->ni", E[ci], X[pi])                       # exp([w]x) X
        Xc = np.einsum("nij,nj->ni", self.R0[ci], Y) + t[ci]
        z = Xc[:, 2]
        xn = Xc[:, :2] / z[:, None]
        r2 = np.sum(xn ** 2, axis=1)
        g = 1 + k1 * r2 + k2 * r2 ** 2
        d_xn = f * (g[:, None, None] * np.eye(2) + 2 * (k1 + 2 * k2 * r2)[:, None, None]
                    * xn[:, :, None] * xn[:, None, :])                # ∂u/∂xn (2, 2)
        d_Xc = np.zeros((len(ci), 2, 3))
        d_Xc[:, 0, 0] = d_Xc[:, 1, 1] = 1 / z
        d_Xc[:, :, 2] = -xn / z[:, None]
        A = d_xn @ d_Xc                                                # ∂u/∂Xc (2, 3)
        d_w = -A @ self.R0[ci] @ skew(Y) @ left_jacobian_so3(w)[ci]
        d_X = A @ R[ci]
        d_c = np.broadcast_to(np.eye(2), (len(ci), 2, 2))
        d_in = np.concatenate([np.stack([f * g[:, None] * xn, f * xn * r2[:, None], f * xn * (r2 ** 2)[:, None]],
                                        axis=2), d_c], axis=2) * free
        vals = np.concatenate([d_in, d_w, A, d_X], axis=2)              # (n, 2, NI + 9)
        cols = np.concatenate([np.tile(np.arange(NI), (len(ci), 1)), NI + 3 * ci[:, None] + np.arange(3),
                               NI + 3 * V + 3 * ci[:, None] + np.arange(3),
                               NI + 6 * V + 3 * pi[:, None] + np.arange(3)], axis=1)
        rows = np.repeat(np.arange(2 * len(ci)), cols.shape[1])
        return sp.csr_matrix((vals.reshape(-1), (rows, np.repeat(cols, 2, axis=0).reshape(-1))),
                             shape=(2 * len(ci), NI + 6 * V + 3 * M))


def refine_shared_intrinsics(tracks: ArrayLike, R: ArrayLike, t: ArrayLike, X: ArrayLike, inliers: ArrayLike,
                             K0: ArrayLike, *, dist0: ArrayLike = (0.0, 0.0), f_prior: tuple = None,
                             k_sigma: float = 0.5, c_sigma: float | None = None, max_nfev: int = 200,
                             max_points: int | None = 400, refine_distortion: bool = True) -> SharedIntrinsics:
    """Bundle adjustment with one focal length, radial distortion ``(k1, k2)`` and optionally the principal point,
    shared by all views.

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        Pixels, NaN where unseen.
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
        Starting poses, ``x_cam = R @ X + t``; NaN for views left out.
    X : (T, 3) array_like
        Starting points; NaN for tracks left out.
    inliers : (V, T) bool array_like
        The observations used (registered view, triangulated point).
    K0 : (3, 3) array_like
        Starting calibration: square pixels, no skew.
    dist0 : (2,) array_like
        Starting ``(k1, k2)``.
    f_prior : (float, float), optional
        ``(f_centre, σ_log)``: a Gaussian prior on ``log f``; by default ``(K0's f, 0.5)`` (weak: ±65 %).
    k_sigma : float
        σ of the Gaussian priors on ``k1`` and ``k2`` (centred on 0).
    max_nfev : int
    max_points : int or None
        Use at most this many points, the most observed (three shared numbers need far fewer than a photo set
        gives; the rest follow in a bundle adjustment with the camera fixed). ``X`` of the points left out is NaN.
    refine_distortion : bool
        False: ``k1 = k2 = 0`` held fixed (a pinhole camera, f refined alone).
    c_sigma : float, optional
        With it the principal point is refined too, with a Gaussian prior of this σ (pixels) around K0's; by
        default it stays where K0 puts it.

    Returns
    -------
    SharedIntrinsics

    Raises
    ------
    ValueError
        Bad shapes, a K0 that is not a calibration or has skew or unequal focal lengths, rotations that are not,
        fewer than two views or 10 observations.
    """
    x = as_tracks(tracks)
    V, T = x.shape[:2]
    R, t, X = as_array(R, "R", "(V, 3, 3)"), as_array(t, "t", "(V, 3)"), as_array(X, "X", "(T, 3)")
    if R.shape != (V, 3, 3) or t.shape != (V, 3) or X.shape != (T, 3):
        raise ValueError(f"R, t, X must have shapes ({V}, 3, 3), ({V}, 3), ({T}, 3); got {R.shape}, {t.shape}, "
                         f"{X.shape}")
    inl = np.asarray(inliers)
    if inl.dtype != bool or inl.shape != (V, T):
        raise ValueError(f"inliers must be a ({V}, {T}) bool array; got {inl.dtype} {inl.shape}")
    K0 = as_calibration(K0, "K0")
    if abs(K0[0, 1]) > 1e-9 * K0[0, 0] or abs(K0[0, 0] / K0[1, 1] - 1) > 1e-9:
        raise ValueError("K0 must have square pixels and no skew (one focal length to refine)")
    views = np.flatnonzero(np.isfinite(R).all(axis=(1, 2)) & np.isfinite(t).all(axis=1) & inl.any(axis=1))
    pts = np.flatnonzero(np.isfinite(X).all(axis=1) & inl.any(axis=0))
    if max_points is not None:
        max_points = as_count(max_points, "max_points", 3)
    if max_points is not None and len(pts) > max_points:      # the best-observed points: five intrinsics need few
        seen = inl[np.ix_(views, pts)].sum(axis=0)
        pts = np.sort(pts[np.argsort(-seen, kind="stable")[:max_points]])
    if len(views) < 2:
        raise ValueError(f"at least two views with poses and observations are needed; got {len(views)}")
    as_rotations(R[views], "R")
    sub = inl[np.ix_(views, pts)] & np.isfinite(x[np.ix_(views, pts)]).all(axis=2)
    ci, pj = np.nonzero(sub)
    if len(ci) < 10:
        raise ValueError(f"{len(ci)} observations; at least 10 are needed")
    obs = x[views[ci], pts[pj]]
    f0 = float(K0[0, 0])
    if f_prior is not None and (isinstance(f_prior, str) or np.ndim(f_prior) != 1 or len(f_prior) != 2):
        raise ValueError(f"f_prior must be (f_centre, sigma_log); got {f_prior!r}")
    f_centre, f_sigma = (f0, 0.5) if f_prior is None else (as_positive(f_prior[0], "f_prior[0]"),
                                                          as_positive(f_prior[1], "f_prior[1]"))
    max_nfev = as_count(max_nfev, "max_nfev")
    if not isinstance(refine_distortion, bool | np.bool_):
        raise ValueError(f"refine_distortion must be True or False; got {refine_distortion!r}")
    k_sigma = as_positive(k_sigma, "k_sigma")
    c_centre = K0[:2, 2].copy()
    c_sigma = 0.0 if c_sigma is None else as_positive(c_sigma, "c_sigma", allow_zero=True)
    k0 = np.asarray(dist0, float)
    if k0.shape != (2,) or not np.all(np.isfinite(k0)):
        raise ValueError(f"dist0 must be 2 finite numbers (k1, k2); got {dist0!r}")
    free = np.array([True, refine_distortion, refine_distortion, c_sigma > 0, c_sigma > 0])
    centre = np.r_[np.log(f_centre), 0.0, 0.0, c_centre]
    sigmas = np.r_[f_sigma, k_sigma, k_sigma, c_sigma, c_sigma]
    prob = _Problem(obs, ci, pj, R[views], len(views), len(pts))
    p0 = np.concatenate([[np.log(f0)], k0 if refine_distortion else (0.0, 0.0), c_centre, np.zeros(3 * len(views)),
                         t[views].ravel(), X[pts].ravel()])
    fixed_values = p0[:NI].copy()
    r_start = np.linalg.norm(prob.project(p0) - obs, axis=1)
    sigma = max(float(np.median(r_start)) / RAYLEIGH_MEDIAN, 1e-6)      # refined below, from the fit
    prior_rows = np.flatnonzero(free)
    n_par = len(p0)
    prior_jac = sp.csr_matrix((1 / sigmas[prior_rows], (np.arange(len(prior_rows)), prior_rows)),
                              shape=(len(prior_rows), n_par))

    def held(p):
        q = p.copy()
        q[:NI] = np.where(free, p[:NI], fixed_values)
        return q

    def residuals(p):
        q = held(p)
        r = ((prob.project(q) - obs) / sigma).ravel()
        return np.concatenate([r, (q[prior_rows] - centre[prior_rows]) / sigmas[prior_rows]])

    def jacobian(p):
        return sp.vstack([prob.jacobian(held(p), free) / sigma, prior_jac]).tocsr()

    p, settled = p0, False
    for _ in range(4):         # σ from the residuals at the current optimum, until it settles (within 2 %)
        res = least_squares(residuals, p, jac=jacobian, method="trf", x_scale="jac", max_nfev=max_nfev,
                            ftol=1e-10, xtol=1e-10, tr_solver="lsmr")
        p = held(res.x)
        new = max(float(np.median(np.linalg.norm(prob.project(p) - obs, axis=1))) / RAYLEIGH_MEDIAN, 1e-6)
        settled, sigma = abs(new / sigma - 1) < 0.02, new
        if settled:
            break
    if not settled:
        res = least_squares(residuals, p, jac=jacobian, method="trf", x_scale="jac", max_nfev=max_nfev,
                            ftol=1e-10, xtol=1e-10, tr_solver="lsmr")
        p = held(res.x)
    f, k1, k2, c, Rv, tv, Xv = prob.unpack(p)
    r_end = np.linalg.norm(prob.project(p) - obs, axis=1)
    cov = _intrinsics_covariance(res.jac, NI, 6 * len(views), len(pts))
    R_out, t_out, X_out = np.full_like(R, np.nan), np.full_like(t, np.nan), np.full_like(X, np.nan)
    R_out[views], t_out[views], X_out[pts] = Rv, tv, Xv
    K = K0.copy()
    K[0, 0] = K[1, 1] = f
    K[:2, 2] = c
    sd = np.sqrt(np.clip(np.diag(cov), 0, None)) * free
    return SharedIntrinsics(K, np.array([k1, k2]), R_out, t_out, X_out, float(f * sd[0]), sd[1:3], sd[3:5], sigma,
                            (float(np.sqrt(np.mean(r_start ** 2))), float(np.sqrt(np.mean(r_end ** 2)))),
                            int(len(ci)), bool(res.success))


def _intrinsics_covariance(J, n_intr, n_cam, n_pts):
    """Covariance of the first ``n_intr`` parameters: points eliminated (Schur), cameras and intrinsics by pinv."""
    J = sp.csc_matrix(J)
    A, B = J[:, :n_intr + n_cam], J[:, n_intr + n_cam:]
    U = (A.T @ A).toarray()
    W = (A.T @ B).toarray() if n_pts else np.zeros((U.shape[0], 0))
    if n_pts:
        Bc = B.tocoo()                                 # each residual row touches one point's three columns
        vals, pt = np.zeros((J.shape[0], 3)), np.full(J.shape[0], -1)
        vals[Bc.row, Bc.col % 3], pt[Bc.row] = Bc.data, Bc.col // 3
        keep = pt >= 0
        Vb = np.zeros((n_pts, 3, 3))
        np.add.at(Vb, pt[keep], vals[keep, :, None] * vals[keep, None, :])
        Vinv = np.linalg.pinv(Vb)
        Wb = W.reshape(-1, n_pts, 3)
        U = U - np.einsum("anj,njk,bnk->ab", Wb, Vinv, Wb)
    return np.linalg.pinv(U, hermitian=True)[:n_intr, :n_intr]
