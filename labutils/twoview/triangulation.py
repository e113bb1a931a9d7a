"""Triangulation: linear (DLT) from two or more views (H&Z Sec. 12.2), the optimal two-view correction
(H&Z Sec. 12.5, Alg. 12.1) with the residual of an F built on it, and the robust triangulation of tracks with
outliers that structure from motion uses.
"""
import numpy as np
from numpy.typing import ArrayLike

from ..core.geometry import camera_center
from ..core.lm import nielsen
from ..core.validation import (
    as_array,
    as_calibration,
    as_camera_matrices,
    as_camera_matrix,
    as_fundamental,
    as_mask,
    as_points,
    as_positive,
    as_rotations,
    as_tracks,
    as_translations,
)


def _normalise_rows(A):
    return A / np.linalg.norm(A, axis=-1, keepdims=True)


def triangulate(P1: ArrayLike, P2: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> np.ndarray:
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
        Wrong shapes, non-finite values, mismatched lengths, or two cameras with the same centre (no baseline:
        the same camera, or a pure rotation).

    Examples
    --------
    >>> P1 = np.hstack([np.eye(3), np.zeros((3, 1))]); P2 = np.hstack([np.eye(3), [[-1.], [0], [0]]])
    >>> triangulate(P1, P2, [[0.2, 0.1]], [[0.0, 0.1]])
    array([[1. , 0.5, 5. ]])
    """
    P1, P2 = as_camera_matrix(P1, "P1"), as_camera_matrix(P2, "P2")
    x1 = as_points(x1, "x1")
    x2 = as_points(x2, "x2", like=(x1, "x1"))
    C = _centres_h(np.stack([P1, P2]))
    if _same_centre(C[0], C[1]):
        raise ValueError("P1 and P2 have the same centre (the same camera, or a pure rotation): no baseline, "
                         "the points cannot be triangulated")
    return triangulate_multiview(np.stack([P1, P2]), np.stack([x1, x2]))


def _centres_h(Ps):
    """Homogeneous centres ``(V, 4)`` of cameras ``(V, 3, 4)``: the null vectors ``P C = 0``, unit norm."""
    return np.linalg.svd(Ps)[2][:, -1]


def _same_centre(Ca, Cb, tol=1e-9):
    """Whether two homogeneous centres are the same point (up to scale and sign)."""
    return min(np.linalg.norm(Ca - Cb), np.linalg.norm(Ca + Cb)) < tol


def triangulate_multiview(Ps: ArrayLike, xs: ArrayLike) -> np.ndarray:
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
        NaN for points seen in fewer than two views, and for points whose observing cameras all share one
        centre (no baseline: the point's depth is not determined).

    Raises
    ------
    ValueError
        Wrong shapes, non-finite camera matrices, infinite pixels, or every camera at the same centre.

    Examples
    --------
    >>> Ps = np.stack([np.hstack([np.eye(3), [[-c], [0], [0]]]) for c in (0., 1., 2.)])
    >>> X = np.array([[1.0, 0.5, 5.0]]); xs = np.stack([(X[:, :2] - [c, 0]) / 5 for c in (0., 1., 2.)])
    >>> xs[2, 0] = np.nan
    >>> np.round(triangulate_multiview(Ps, xs), 9)
    array([[1. , 0.5, 5. ]])
    """
    Ps = as_camera_matrices(Ps, "Ps")
    xs = as_tracks(xs, "xs")
    if xs.shape[0] != Ps.shape[0]:
        raise ValueError(f"xs must have shape (V, N, 2) with V = {Ps.shape[0]} (one row of pixels per camera of Ps); "
                         f"got {xs.shape}")
    return _triangulate_multiview(Ps, xs)


def _triangulate_multiview(Ps, xs):
    """:func:`triangulate_multiview` on checked input (cameras that see nothing may be zero)."""
    seen = np.all(np.isfinite(xs), axis=-1)                      # (V, N)
    C = _centres_h(Ps)
    same = np.minimum(np.linalg.norm(C[:, None] - C[None], axis=-1),
                      np.linalg.norm(C[:, None] + C[None], axis=-1)) < 1e-9
    label = np.argmax(same, axis=1)                               # cameras with one centre share a label
    if len(C) >= 2 and np.all(label == label[0]):
        raise ValueError("every camera in Ps has the same centre (no baseline): nothing can be triangulated")
    X = np.full((xs.shape[1], 3), np.nan)
    n_seen = seen.sum(0)
    order = np.argsort(~seen, axis=0, kind="stable")              # each point's observing views first
    # group the points by how many views see them, so each SVD gets only real rows
    for L in np.unique(n_seen[n_seen >= 2]):
        cols = np.flatnonzero(n_seen == L)
        v = order[:L, cols]                                        # (L, m) view indices
        P, x = Ps[v], xs[v, cols]                                  # (L, m, 3, 4), (L, m, 2)
        # rows x P[2] - P[0] and y P[2] - P[1], scaled to unit norm: (L, m, 2, 4)
        A = _normalise_rows(x[..., None] * P[:, :, 2:3, :] - P[:, :, :2, :])
        A = A.transpose(1, 0, 2, 3).reshape(cols.size, 2 * L, 4)
        X_h = np.linalg.svd(A)[2][:, -1]
        with np.errstate(divide="ignore", invalid="ignore"):
            X[cols] = X_h[:, :3] / X_h[:, 3:]
        # a point seen only from one centre has no baseline: its depth is arbitrary
        lab = label[v]
        X[cols[lab.min(0) == lab.max(0)]] = np.nan
    return X


# --------------------------------------------------------------------------------------------------
# The optimal two-view correction (H&Z Sec. 12.5, Alg. 12.1)
# --------------------------------------------------------------------------------------------------

def _polymul(p, q):
    """Product of batched polynomials, coefficients highest degree first: (n, a) x (n, b) -> (n, a + b - 1)."""
    r = np.zeros((p.shape[0], p.shape[1] + q.shape[1] - 1))
    for i in range(p.shape[1]):
        r[:, i:i + q.shape[1]] += p[:, i:i + 1] * q
    return r


def _polyval(p, t):
    """Evaluate batched polynomials (n, k) at (n, m) points (Horner)."""
    v = np.zeros_like(t)
    for k in range(p.shape[1]):
        v = v * t + p[:, k:k + 1]
    return v


def _poly_roots(coef):
    """All complex roots of each row of ``coef`` (n, 7); rows with a negligible leading term use np.roots."""
    n, k = coef.shape
    roots = np.full((n, k - 1), np.nan, dtype=complex)
    scale = np.abs(coef).max(1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        monic = coef / coef[:, :1]
    full = np.all(np.isfinite(monic), axis=1)       # else the degree drops (f = 0, a = 0 or c = 0)
    if full.any():                                   # batched companion matrices (eigvals balances them)
        c = monic[full]
        comp = np.zeros((c.shape[0], k - 1, k - 1))
        comp[:, 0, :] = -c[:, 1:]
        comp[:, np.arange(1, k - 1), np.arange(k - 2)] = 1.0
        roots[full] = np.linalg.eigvals(comp)
    for i in np.flatnonzero(~full):                  # the degree drops: np.roots trims leading zeros
        c = np.where(np.abs(coef[i]) > 1e-14 * scale[i], coef[i], 0.0)
        r = np.roots(c) if np.any(c) else np.zeros(0)
        roots[i, :r.size] = r
    return roots


def triangulate_optimal(F: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> tuple:
    """Optimal (maximum-likelihood) correction of two-view correspondences (H&Z Sec. 12.5, Alg. 12.1).

    Finds, for each pair, the points ``x1_hat, x2_hat`` that satisfy ``x2_hatᵀ F x1_hat = 0`` exactly and
    minimise ``|x1 - x1_hat|² + |x2 - x2_hat|²`` (the geometric error under Gaussian pixel noise). The
    epipolar lines through the two points are parametrised by t; the squared distance is stationary at
    the roots of a degree-6 polynomial g(t) (H&Z eq. 12.7), evaluated at all real parts of its roots
    and at t = ∞, then the best is kept. Vectorised over the points: the roots come from batched
    companion matrices, polished by one Newton step on g.

    Triangulate the corrected points with :func:`triangulate` (any two cameras consistent with F):
    their rays meet exactly.

    Parameters
    ----------
    F : (3, 3) array_like
        Fundamental matrix of rank 2, ``x2_hᵀ F x1_h = 0`` (any scale).
    x1, x2 : (N, 2) array_like
        Measured corresponding pixels.

    Returns
    -------
    x1_hat, x2_hat : (N, 2) ndarray
        Corrected pixels.

    Raises
    ------
    ValueError
        Wrong shapes, NaN/inf, mismatched lengths, or F not of rank 2.

    Examples
    --------
    >>> F = np.array([[0., 0, 0], [0, 0, -1], [0, 1, 0]])      # pure x-translation: rows must agree
    >>> x1_hat, x2_hat = triangulate_optimal(F, [[0., 0.]], [[5., 2.]])
    >>> x1_hat.round(9), x2_hat.round(9)
    (array([[0., 1.]]), array([[5., 1.]]))
    """
    F, e1, e2 = as_fundamental(F)
    x1 = as_points(x1, "x1")
    x2 = as_points(x2, "x2", like=(x1, "x1"))
    n = x1.shape[0]
    # one common isotropic scale for both images keeps the polynomial well conditioned and the
    # minimiser unchanged (the cost is a sum of squared distances, scaled by the same factor)
    c1, c2 = x1.mean(0), x2.mean(0)
    spread = np.sqrt(((x1 - c1) ** 2).sum(1).mean() / 2 + ((x2 - c2) ** 2).sum(1).mean() / 2)
    s = 1.0 / spread if spread > 0 else 1.0
    S1 = np.array([[s, 0, -s * c1[0]], [0, s, -s * c1[1]], [0, 0, 1]])
    S2 = np.array([[s, 0, -s * c2[0]], [0, s, -s * c2[1]], [0, 0, 1]])
    y1, y2 = (x1 - c1) * s, (x2 - c2) * s
    Fs = np.linalg.inv(S2).T @ F @ np.linalg.inv(S1)
    e1, e2 = S1 @ e1, S2 @ e2                                 # F e1 = 0, e2ᵀ F = 0 in scaled coordinates
    # (i)-(v): translate each point to the origin (T), rotate its epipole onto the x axis (R)
    ep1 = np.column_stack([e1[0] - y1[:, 0] * e1[2], e1[1] - y1[:, 1] * e1[2], np.full(n, e1[2])])
    ep2 = np.column_stack([e2[0] - y2[:, 0] * e2[2], e2[1] - y2[:, 1] * e2[2], np.full(n, e2[2])])
    ep1 /= np.maximum(np.hypot(ep1[:, 0], ep1[:, 1]), 1e-300)[:, None]
    ep2 /= np.maximum(np.hypot(ep2[:, 0], ep2[:, 1]), 1e-300)[:, None]

    def frame(y, ep):                                   # M = R T (maps the point to 0, e to (1, 0, f))
        M = np.zeros((n, 3, 3))
        M[:, 0, 0], M[:, 0, 1], M[:, 1, 0], M[:, 1, 1] = ep[:, 0], ep[:, 1], -ep[:, 1], ep[:, 0]
        M[:, 2, 2] = 1.0
        M[:, :2, 2] = -np.einsum("nij,nj->ni", M[:, :2, :2], y)
        return M

    M1, M2 = frame(y1, ep1), frame(y2, ep2)
    M1inv, M2inv = np.linalg.inv(M1), np.linalg.inv(M2)
    Fl = np.einsum("nji,jk,nkl->nil", M2inv, Fs, M1inv)     # M2⁻ᵀ F M1⁻¹, the form of H&Z eq. 12.3
    Fl /= np.linalg.norm(Fl, axis=(1, 2), keepdims=True)
    f1, f2 = ep1[:, 2], ep2[:, 2]
    a, b, c, d = Fl[:, 1, 1], Fl[:, 1, 2], Fl[:, 2, 1], Fl[:, 2, 2]
    # (vii) g(t) = t ((a t + b)² + f2² (c t + d)²)² - (a d - b c) (1 + f1² t²)² (a t + b) (c t + d)
    at_b, ct_d = np.column_stack([a, b]), np.column_stack([c, d])
    q = _polymul(at_b, at_b) + f2[:, None] ** 2 * _polymul(ct_d, ct_d)
    g = np.zeros((n, 7))
    g[:, 1:6] = _polymul(q, q)                                 # t q²: degrees 5 .. 1
    w = np.column_stack([f1 ** 2, np.zeros(n), np.ones(n)])
    g -= (a * d - b * c)[:, None] * _polymul(_polymul(w, w), _polymul(at_b, ct_d))
    t = _poly_roots(g).real                                   # (n, 6), NaN where the degree dropped
    dg = g[:, :-1] * np.arange(6, 0, -1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t_newton = t - _polyval(g, t) / _polyval(dg, t)
        t = np.concatenate([t, np.where(np.isfinite(t_newton), t_newton, np.nan)], axis=1)

        def cost(t):
            return t ** 2 / (1 + (f1[:, None] * t) ** 2) + (c[:, None] * t + d[:, None]) ** 2 / (
                (a[:, None] * t + b[:, None]) ** 2 + (f2[:, None] * (c[:, None] * t + d[:, None])) ** 2)

        s_t = np.where(np.isfinite(t), cost(t), np.inf)
        s_inf = 1 / f1 ** 2 + c ** 2 / (a ** 2 + f2 ** 2 * c ** 2)   # t -> infinity
    best = np.argmin(s_t, axis=1)
    t_min = t[np.arange(n), best]
    at_inf = ~(s_t[np.arange(n), best] <= s_inf)
    t_min = np.where(at_inf, 0.0, t_min)
    # (ix) the two epipolar lines at t_min, and the points on them closest to the origin
    l1 = np.column_stack([t_min * f1, np.ones(n), -t_min])
    l2 = np.column_stack([-f2 * (c * t_min + d), a * t_min + b, c * t_min + d])
    l1[at_inf] = np.column_stack([f1, np.zeros(n), -np.ones(n)])[at_inf]
    l2[at_inf] = np.column_stack([-f2 * c, a, c])[at_inf]

    def foot(l):
        return np.column_stack([-l[:, 0] * l[:, 2], -l[:, 1] * l[:, 2], l[:, 0] ** 2 + l[:, 1] ** 2])

    # (x) back to pixels: x = S⁻¹ M⁻¹ x_local
    p1 = np.einsum("nij,nj->ni", M1inv, foot(l1))
    p2 = np.einsum("nij,nj->ni", M2inv, foot(l2))
    x1_hat = p1[:, :2] / p1[:, 2:] / s + c1
    x2_hat = p2[:, :2] / p2[:, 2:] / s + c2
    return x1_hat, x2_hat


def fundamental_residual(F: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> float:
    """RMS geometric residual of an F: the optimal correction's distance, over all 4N coordinates.

    ``sqrt(sum(|x1 - x1_hat|² + |x2 - x2_hat|²) / (4 N))`` with ``x1_hat, x2_hat`` from
    :func:`triangulate_optimal` — the quantity the gold-standard F minimises (H&Z eq. 11.6), so any F can be
    judged the same way. For the ML estimate from N noisy correspondences (σ per coordinate) it is
    expected to be ``σ sqrt((N - 7) / (4 N))`` (H&Z Result 5.2; :func:`labutils.core.ml_residual_bound`).

    Parameters
    ----------
    F : (3, 3) array_like
        Rank 2.
    x1, x2 : (N, 2) array_like

    Returns
    -------
    float
        In pixels.

    Examples
    --------
    >>> F = np.array([[0., 0, 0], [0, 0, -1], [0, 1, 0]])
    >>> float(fundamental_residual(F, [[0., 0.]], [[5., 2.]]))       # sqrt((1 + 1) / 4)
    0.7071067811865476
    """
    x1 = as_points(x1, "x1")
    x2 = as_points(x2, "x2", like=(x1, "x1"))
    x1_hat, x2_hat = triangulate_optimal(F, x1, x2)
    return float(np.sqrt((((x1 - x1_hat) ** 2).sum() + ((x2 - x2_hat) ** 2).sum()) / (4 * x1.shape[0])))


# --------------------------------------------------------------------------------------------------
# Robust triangulation of tracks (structure from motion)
# --------------------------------------------------------------------------------------------------

def ray_angles_deg(C: ArrayLike, X: ArrayLike, mask: ArrayLike) -> np.ndarray:
    """Triangulation angle of each point: the largest angle between two of its viewing rays (degrees).

    Parameters
    ----------
    C : (V, 3) array_like
        Camera centres.
    X : (T, 3) array_like
        Points.
    mask : (V, T) bool array_like
        Which views observe which point.

    Returns
    -------
    angle : (T,) ndarray
        NaN for points with fewer than two observations.

    >>> C = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]
    >>> np.round(ray_angles_deg(C, [[1, 0, 1], [1, 0, 1]], [[1, 1], [0, 1], [1, 0]]), 6)
    array([90., 45.])
    """
    C, X = as_array(C, "C", "(V, 3)"), as_array(X, "X", "(T, 3)")
    mask = as_mask(mask, "mask", C.shape[:1] + X.shape[:1], like="the rows of C and X")
    for name, a, used in (("C", C, mask.any(axis=1)), ("X", X, mask.any(axis=0))):
        if a.ndim != 2 or a.shape[1] != 3 or not np.all(np.isfinite(a[used])):
            raise ValueError(f"{name} must have shape (N, 3), finite in the rows mask uses; got shape {a.shape}")
    n = mask.sum(0)
    angle = np.full(X.shape[0], np.nan)
    order = np.argsort(~mask, axis=0, kind="stable")                      # observing views first
    for L in np.unique(n[n >= 2]):                                         # tracks grouped by length
        cols = np.flatnonzero(n == L)
        rays = X[cols][None] - C[order[:L, cols]]                          # (L, m, 3)
        rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
        cos = np.einsum("imk,jmk->mij", rays, rays).min(axis=(1, 2))
        angle[cols] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return angle


def _camera_matrices(K, R, t, views):
    return np.einsum("vij,vjk->vik", K[views], np.concatenate([R[views], t[views, :, None]], axis=2))


def _refine_points(Ps, xs, use, X, n_iter=3):
    """Each point moved to (near) its maximum-likelihood position in the views of ``use`` (H&Z Sec. 12.3, A6.2).

    ``n_iter`` Levenberg–Marquardt steps on each point's reprojection error, all points at once (3×3 normal
    equations per point, the package's damping rule :func:`labutils.core.lm.nielsen`); from the DLT, three reach
    the optimum to 1e-6 px on the dinosaur. The DLT minimises an algebraic error whose weights depend on the world
    frame: from cameras that differ only by a similarity it gives reprojection errors that differ by pixels, so
    decisions taken on them (inlier or not) would depend on the gauge. The reprojection error does not.

    Parameters
    ----------
    Ps : (V, 3, 4) ndarray
        Camera matrices, scaled so that the third coordinate of ``P X_h`` is the depth's sign.
    xs : (V, N, 2) ndarray
    use : (V, N) bool ndarray
        The observations each point is fitted to.
    X : (N, 3) ndarray
        Starting points (NaN rows, and points behind a camera of ``use``, are left as they are).

    Returns
    -------
    X : (N, 3) ndarray
        A step is kept only if it lowers the point's error and keeps it in front of its cameras.
    """
    X = np.array(X, float)
    cols = np.flatnonzero(np.all(np.isfinite(X), axis=1) & (use.sum(0) >= 2))
    if cols.size == 0:
        return X
    cam, j = np.nonzero(use[:, cols])
    N = cols.size
    P, x = Ps[cam], xs[cam, cols[j]]

    def evaluate(Xc):
        q = np.einsum("nij,nj->ni", P[:, :, :3], Xc[j]) + P[:, :, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = q[:, :2] / q[:, 2:]
        r = u - x
        cost = np.bincount(j, (r ** 2).sum(1), N)
        cost[(np.bincount(j, ~(q[:, 2] > 0), N) > 0) | ~np.isfinite(cost)] = np.inf
        return r, u, q, cost

    Xc = X[cols]
    r, u, q, cost = evaluate(Xc)
    lam, nu = np.full(N, 1e-3), np.full(N, 2.0)
    for _ in range(n_iter):
        J = (P[:, :2, :3] - u[:, :, None] * P[:, 2:3, :3]) / q[:, 2, None, None]          # (n, 2, 3)
        JtJ = np.stack([np.bincount(j, np.einsum("nk,nk->n", J[:, :, a], J[:, :, b]), N)
                        for a in range(3) for b in range(3)], axis=1).reshape(N, 3, 3)
        g = np.stack([np.bincount(j, np.einsum("nk,nk->n", J[:, :, a], r), N) for a in range(3)], axis=1)
        d = np.einsum("nii->ni", JtJ)
        A = JtJ + (lam[:, None] * d + 1e-12 * d.sum(1, keepdims=True))[:, :, None] * np.eye(3)
        ok = np.isfinite(cost) & np.all(np.isfinite(A), axis=(1, 2)) & (np.abs(np.linalg.det(A)) > 0)
        step = np.zeros((N, 3))
        step[ok] = np.linalg.solve(A[ok], -g[ok][:, :, None])[:, :, 0]
        cost_new = evaluate(Xc + step)[3]
        better = ok & (cost_new < cost)
        predicted = 0.5 * np.einsum("ni,ni->n", step, (lam[:, None] * d + 1e-12 * d.sum(1, keepdims=True)) * step
                                    - g)
        with np.errstate(divide="ignore", invalid="ignore"):
            gain = np.where(better & (predicted > 0), 0.5 * (cost - cost_new) / predicted, -1.0)
        Xc = np.where(better[:, None], Xc + step, Xc)
        lam, nu = nielsen(lam, nu, gain)           # the package's damping rule (labutils.core.lm)
        r, u, q, cost = evaluate(Xc)
    X[cols] = Xc
    return X


def triangulate_tracks(tracks: ArrayLike, K: ArrayLike, R: ArrayLike, t: ArrayLike, views: ArrayLike,
                       mask: ArrayLike, *, threshold_px: float, min_angle_deg: float) -> tuple:
    """Robust triangulation of tracks from registered views (H&Z Sec. 12.2; the idea of COLMAP's RANSAC
    triangulation, with every pair of views tried).

    For each track, every pair of its observations is triangulated (midpoint of the two rays) and scored
    by how many of the track's observations then reproject within ``threshold_px`` in front of the camera
    (the consensus). The observations on which all the largest consensus sets agree are triangulated by
    multi-view DLT and the consensus taken again (twice); a track whose largest consensus sets share fewer
    than two observations is ambiguous (which observation is the outlier cannot be told) and is rejected.
    Then, while some kept observation reprojects too far, the worst one is dropped and the track
    triangulated again. A point is accepted when at least two observations remain and its triangulation
    angle is at least ``min_angle_deg``. Trying all pairs makes the result depend on the cameras only, not
    on the order in which views were added; every DLT point is moved to its maximum-likelihood position
    (:func:`_refine_points`) before it is judged, so the result does not depend on the world frame either
    (the DLT's algebraic error does: on the dinosaur, track 3255 triangulated from the true cameras in the
    world frame reprojects at most 3.1 px from its observations, from the same cameras in the frame of
    view 17 4.8 px, beyond a 4 px threshold).

    Parameters
    ----------
    tracks : (V, N, 2) array_like
        Pixels, NaN where unseen (the columns are the tracks to triangulate).
    K, R : (V, 3, 3) array_like
    t : (V, 3) array_like
        Calibration and poses (used only for ``views``).
    views : (m,) int array_like
        The registered views to use.
    mask : (V, N) bool array_like
        Observations allowed (outside ``views`` they are ignored).
    threshold_px, min_angle_deg : float

    Returns
    -------
    X : (N, 3) ndarray
        NaN where the track was rejected.
    used : (V, N) bool ndarray
        The observations that support each accepted point (all False for a rejected one).

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(20, 3, noise_px=0.0, rng=np.random.default_rng(0))
    >>> x = s.x_true.copy(); x[2, 0] += 50                     # one gross outlier
    >>> X, used = triangulate_tracks(x, np.stack([s.K] * 3), s.R, s.t, [0, 1, 2], s.visible,
    ...                              threshold_px=1.0, min_angle_deg=1.0)
    >>> bool(np.allclose(X, s.X)), int(used.sum()), bool(used[2, 0])
    (True, 59, False)
    """
    tracks = as_tracks(tracks)
    V, N = tracks.shape[:2]
    K = as_calibration(K, "K", n_views=V, like_name="tracks")
    R, t = as_array(R, "R", f"({V}, 3, 3)"), as_array(t, "t", f"({V}, 3)")
    if R.shape != (V, 3, 3):
        raise ValueError(f"R must have shape ({V}, 3, 3) (NaN for views not used); got {R.shape}")
    if t.shape != (V, 3):
        raise ValueError(f"t must have shape ({V}, 3) (NaN for views not used); got {t.shape}"
                         + (" — t transposed? translations are rows" if t.shape == (3, V) else ""))
    views = np.asarray(views)
    if views.ndim != 1 or (views.size and (views.dtype.kind not in "iu" or views.min() < 0 or views.max() >= V)):
        raise ValueError(f"views must be a 1-D array of view indices in 0..{V - 1}; got {views!r}")
    if np.unique(views).size < 2:
        raise ValueError(f"views must list at least two different views to triangulate from; got {views.tolist()}")
    views = views.astype(int)
    R = R.copy()
    R[views] = as_rotations(R[views], "R[views]")
    as_translations(t[views], "t[views]")
    mask = as_mask(mask, "mask", (V, N), like="tracks")
    threshold_px = as_positive(threshold_px, "threshold_px", allow_inf=True)
    min_angle_deg = as_positive(min_angle_deg, "min_angle_deg", allow_zero=True)
    use = np.zeros((V, N), bool)
    use[views] = mask[views] & np.all(np.isfinite(tracks[views]), axis=-1)
    X = np.full((N, 3), np.nan)
    if N == 0:
        return X, np.zeros((V, N), bool)
    Ps = np.zeros((V, 3, 4))
    Ps[views] = _camera_matrices(K, R, t, views)           # K33 = 1: q_z has the sign of the depth
    xs = np.where(use[..., None], tracks, 0.0)

    def errors(Xq, cam, col):
        """Reprojection errors of points ``Xq`` (n, 3) in views ``cam`` against ``xs[cam, col]``; inf behind."""
        q = np.einsum("nij,nj->ni", Ps[cam], np.hstack([Xq, np.ones((len(Xq), 1))]))
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.linalg.norm(q[:, :2] / q[:, 2:] - xs[cam, col], axis=1)
        e[~(q[:, 2] > 0)] = np.inf
        return e

    # 1. every pair of observations of every track, and its consensus in the whole track
    cand = np.flatnonzero(use.sum(0) >= 2)
    if cand.size == 0:
        return X, np.zeros((V, N), bool)
    n_obs = use[:, cand].sum(0)
    L = int(n_obs.max())
    vid = np.argsort(~use[:, cand], axis=0, kind="stable")[:L]           # (L, n): observing views first
    a, b = np.triu_indices(L, 1)
    pa, col = np.nonzero(b[:, None] < n_obs[None])                         # all pairs of each track
    va, vb, trk = vid[a[pa], col], vid[b[pa], col], cand[col]
    # the midpoint of the two viewing rays (H&Z Sec. 12.1): cheap, and only used to find the consensus
    Kinv = np.zeros((V, 3, 3))
    Kinv[views] = np.linalg.inv(K[views])
    C = np.zeros((V, 3))
    C[views] = camera_center(R[views], t[views])
    Rt = np.swapaxes(np.where(use.any(1)[:, None, None], R, 0.0), 1, 2)
    xh = np.concatenate([xs, np.ones((V, N, 1))], axis=2)
    da = np.einsum("nij,nj->ni", Rt[va] @ Kinv[va], xh[va, trk])
    db = np.einsum("nij,nj->ni", Rt[vb] @ Kinv[vb], xh[vb, trk])
    w0 = C[va] - C[vb]
    aa, ab, bb = (da * da).sum(1), (da * db).sum(1), (db * db).sum(1)
    d, e = (da * w0).sum(1), (db * w0).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = aa * bb - ab ** 2
        sa, sb = (ab * e - bb * d) / den, (aa * e - ab * d) / den
        Xp = 0.5 * (C[va] + sa[:, None] * da + C[vb] + sb[:, None] * db)
    Xp[~(np.abs(den) > 1e-12 * aa * bb) | ~np.all(np.isfinite(Xp), axis=1)] = np.inf
    # each pair's point against every observation of its track
    n_po = n_obs[col]
    pair_of = np.repeat(np.arange(col.size), n_po)
    slot = np.arange(pair_of.size) - np.repeat(np.cumsum(n_po) - n_po, n_po)
    cam = vid[slot, col[pair_of]]
    e = errors(np.nan_to_num(Xp[pair_of], posinf=0.0), cam, trk[pair_of])
    e[~np.isfinite(Xp[pair_of, 0])] = np.inf
    inl = np.isfinite(e) & (e <= threshold_px)                            # inf: behind a camera
    count = np.bincount(pair_of, inl, col.size)
    most = np.zeros(N)
    np.maximum.at(most, trk, count)
    top = count == most[trk]                                               # the pairs with the largest consensus
    # the observations on which all the largest consensus sets agree (an ambiguous track keeps < 2)
    n_top = np.bincount(trk[top], minlength=N)
    votes = np.zeros((V, N), int)
    w = top[pair_of] & inl
    np.add.at(votes, (cam[w], trk[pair_of[w]]), 1)
    cons = (votes == n_top[None]) & (votes > 0)
    # 2. refit on the consensus set and take the consensus again
    for _ in range(2):
        todo = np.flatnonzero(cons.sum(0) >= 2)
        X[todo] = _refine_points(Ps, xs[:, todo], cons[:, todo],
                                 _triangulate_multiview(Ps, np.where(cons[:, todo, None], xs[:, todo], np.nan)))
        cam, pt = np.nonzero(use[:, todo])
        cons[:, todo] = False
        e = errors(np.nan_to_num(X[todo[pt]]), cam, todo[pt])
        cons[cam, todo[pt]] = np.isfinite(e) & (e <= threshold_px)
    use &= cons
    # 3. drop the worst observation while one reprojects too far
    todo = np.flatnonzero(use.sum(0) >= 2)
    while todo.size:
        X[todo] = _refine_points(Ps, xs[:, todo], use[:, todo],
                                 _triangulate_multiview(Ps, np.where(use[:, todo, None], xs[:, todo], np.nan)))
        cam, pt = np.nonzero(use[:, todo])
        err = np.full((V, todo.size), -1.0)
        err[cam, pt] = errors(np.nan_to_num(X[todo[pt]]), cam, todo[pt])
        worst = np.argmax(err, axis=0)
        e = err[worst, np.arange(todo.size)]
        bad = np.isinf(e) | (e > threshold_px)
        use[worst[bad], todo[bad]] = False
        todo = todo[bad & (use[:, todo].sum(0) >= 2)]
    ok = use.sum(0) >= 2
    angle = ray_angles_deg(C, np.where(ok[:, None], np.nan_to_num(X), 0.0), use & ok)
    ok &= angle >= min_angle_deg
    X[~ok] = np.nan
    use[:, ~ok] = False
    return X, use
