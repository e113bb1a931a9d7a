"""Two-view geometry: the fundamental matrix, the essential matrix and the relative pose.

Conventions (see the package docstring): ``x2_hᵀ F x1_h = 0``; camera 1 is ``[I | 0]`` and camera 2
``[R | t]``; ``E = [t]× R``; ``F = K2⁻ᵀ E K1⁻¹``. F and E are defined up to scale (and sign): every F
returned here has unit Frobenius norm and rank 2, and its largest entry (in absolute value) is positive.

The estimators, from H&Z Ch. 11 and 9.6:

- :func:`fundamental_8point` (Alg. 11.1) and :func:`fundamental_7point` (Sec. 11.1.2), linear;
- :func:`fundamental_ransac`: 7-point samples in :func:`labutils.ransac.ransac`, then the 8-point on the inliers;
- :func:`fundamental_gold_standard` (Alg. 11.3): the maximum-likelihood F by sparse Levenberg–Marquardt,
  started from the 8-point and from a global search over the epipole (:func:`epipole_search`);
- :func:`essential_from_fundamental`, :func:`decompose_essential` (Result 9.19), :func:`pose_from_essential`.

Degenerate input
----------------
The correspondences do not determine F when a homography maps all of them (``x2 ≃ H x1``): all 3D
points on one plane, or no baseline (a pure rotation). Then ``H⁻ᵀ [v]×`` fits every correspondence for
every v, the 8-point design matrix has rank 6, and the 8-point returns an arbitrary member of that
family. :func:`fundamental_8point` raises ``ValueError`` in two cases:

1. noise-free (to rounding) degeneracy: after Hartley's normalisation the design matrix has rank < 8,
   i.e. its 8th singular value is below ``rank_tol`` (1e-8) times the largest;
2. noisy degeneracy, when there are enough points to judge it (N >= 50): a homography explains the
   correspondences at least as well as F, by Torr's geometric robust information criterion
   (:func:`gric_model_selection`, which returns the numbers): ``GRIC = e / σ² + λ1 d N + λ2 k`` with
   ``e`` the sum of squared Sampson distances of the model, ``λ1 = log 4``, ``λ2 = log 4N``, and
   (d, k) = (3, 7) for F, (2, 8) for H; σ² is estimated from F, ``e_F / (N - 7)``. H wins when
   ``e_H - e_F < (N log 4 - log 4N) σ²``: F must remove about 1.39 σ² per correspondence more than the
   noise would. Both models are fitted by (near) maximum likelihood: H by the normalised DLT, F by
   minimising the Sampson error from the 8-point and from the best epipole of :func:`epipole_search`.
   The test used to compare H with the linear 8-point F at a fixed ratio (1.25 of the noise variance per
   degree of freedom); with the epipole inside the image (forward motion) the 8-point F leaves up to
   two to three times the noise variance, so that test refused 24-33 % of valid forward pairs (below).
   ``degeneracy=None`` turns the test off.

   Measured (300 scenes per cell; "forward": two views, N points in a cloud of ±1 at depth 4-10, forward
   step 0.5-1, rotation 1-5°, σ = 0.5 px; "plane", "rotation": ``make_scene(planar=True)`` and a pure
   rotation of 1-5°, σ = 1 px and 0.5 px, the ranges over these four), refused in %:

   ==============================  ========  ========  ========  ========  ========
   N                                  50        100       200       300       500
   ==============================  ========  ========  ========  ========  ========
   forward, GRIC                      0.0       0.0       0.0       0.7       0.0
   forward, old fixed ratio          25.0      24.0      32.0      29.7      33.3
   plane / rotation, GRIC           2.3-4.0   15-22     55-63     82-84     98-99
   plane / rotation, old ratio       70-76     87-92     98-99    99.7-100    100
   ==============================  ========  ========  ========  ========  ========

   (A second set of 300 forward pairs per N: 0.3, 0.0, 0.3, 0.0, 0.3 % refused.) With σ estimated from
   the data, noisy degeneracy is caught only with many points: on degenerate data F is not determined,
   and its best fit places the free epipole where it absorbs noise (it leaves 0.72, 0.80, 0.86, 0.88,
   0.91 σ² per degree of freedom at these N), so σ comes out low and H's residual looks large. Given
   the true σ (``gric_model_selection(..., sigma_px=σ)``) the same criterion refuses 60-67, 84-87,
   98-99, 99.7-100 and 100 % of those scenes, and 1.0, 0.0, 0.7, 0.0, 0.7 % of the forward pairs. Some
   forward pairs of that family are degenerate to within the noise (a cloud at depth 10 and a step of
   0.5: H leaves 6-12 % more than σ² per degree of freedom, the true F no less); nothing in the data
   tells them from a plane, and GRIC errs towards keeping them. Below N = 50 only the rank test
   applies: noisy degenerate data with few points give an F that means nothing.

A scene with a dominant plane plus a few off-plane points is *not* degenerate and is accepted; RANSAC
on such data may still lock onto the plane (DEGENSAC, Chum et al. 2005, is not implemented here).
"""
from dataclasses import dataclass

import numpy as np

from ._validation import as_matrix, as_points
from .geometry import rotation_from_angle_axis, skew
from .ransac import ransac
from .triangulation import _rank2_fundamental, fundamental_residual, triangulate, triangulate_optimal

__all__ = ["fundamental_8point", "fundamental_7point", "sampson_distance", "fundamental_ransac",
           "fundamental_gold_standard", "GoldStandardProblem", "epipole_search", "fundamental_residual",
           "homography_dlt", "essential_from_fundamental", "decompose_essential", "pose_from_essential",
           "fundamental_from_pose", "hartley_normalisation", "ModelSelection", "gric_model_selection"]


H_TEST_MIN_POINTS = 50        # the homography-vs-F degeneracy test needs this many correspondences

# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------

def hartley_normalisation(x):
    """Similarity ``T`` moving points to centroid 0 and mean distance √2 from it (H&Z Sec. 4.4.4).

    Parameters
    ----------
    x : (N, 2) array_like

    Returns
    -------
    T : (3, 3) ndarray
        ``x_n_h = x_h @ T.T``.

    Raises
    ------
    ValueError
        If all points coincide.

    Examples
    --------
    >>> T = hartley_normalisation([[0., 0.], [2., 0.]])
    >>> T @ [2., 0., 1.]
    array([1.41421356, 0.        , 1.        ])
    """
    x = np.asarray(x, float)
    c = x.mean(0)
    d = np.sqrt(((x - c) ** 2).sum(1)).mean()
    if not d > 1e-12 * max(1.0, np.abs(c).max()):
        raise ValueError("all points coincide: they cannot be normalised (degenerate configuration)")
    s = np.sqrt(2) / d
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])


def _apply(T, x):
    x_h = np.hstack([x, np.ones((len(x), 1))]) @ T.T
    return x_h[:, :2] / x_h[:, 2:]


def _design(x1, x2):
    """Rows ``kron(x2_h, x1_h)``: ``A @ F.ravel() = x2_hᵀ F x1_h`` (H&Z eq. 11.3)."""
    x1_h = np.hstack([x1, np.ones((len(x1), 1))])
    x2_h = np.hstack([x2, np.ones((len(x2), 1))])
    return (x2_h[:, :, None] * x1_h[:, None, :]).reshape(len(x1), 9)


def _canonical_sign(F):
    """Unit Frobenius norm, largest-magnitude entry positive (F is defined up to scale and sign)."""
    F = F / np.linalg.norm(F)
    return F * np.sign(F.flat[np.argmax(np.abs(F))])


def _null_space_svd(A):
    """Singular values and right singular vectors of A (rows >= 1, 9 columns) without the large U.

    ``full_matrices=True`` would build an N×N U (slow for many points); padding A with zero rows to
    9 keeps the 9×9 V, so its last row is the null vector also when N < 9. Zero rows add zero singular
    values at the end and change nothing else.
    """
    if A.shape[0] < A.shape[1]:
        A = np.vstack([A, np.zeros((A.shape[1] - A.shape[0], A.shape[1]))])
    _, s, Vt = np.linalg.svd(A, full_matrices=False)
    return s, Vt


def _enforce_rank2(F):
    U, s, Vt = np.linalg.svd(F)
    return (U[:, :2] * s[:2]) @ Vt[:2]


def _check_pair(x1, x2, min_n):
    x1 = as_points(x1, "x1", min_n=min_n)
    x2 = as_points(x2, "x2", min_n=min_n, like=x1)
    return x1, x2


# --------------------------------------------------------------------------------------------------
# linear estimates
# --------------------------------------------------------------------------------------------------

def sampson_distance(F, x1, x2):
    """Sampson distance of each correspondence to F, in pixels (not squared) (H&Z eq. 11.9).

    ``d = |x2_hᵀ F x1_h| / sqrt((F x1_h)_1² + (F x1_h)_2² + (Fᵀ x2_h)_1² + (Fᵀ x2_h)_2²)``: the first-order
    approximation of the distance, in the 4D space of ``(x1, x2)``, from the measured pair to the nearest
    pair that satisfies the constraint exactly. H&Z eq. 11.9 is its square.

    Parameters
    ----------
    F : (3, 3) array_like
    x1, x2 : (N, 2) array_like

    Returns
    -------
    d : (N,) ndarray
        Non-negative, in pixels.

    Examples
    --------
    >>> F = np.array([[0., 0, 0], [0, 0, -1], [0, 1, 0]])    # rows must agree: d = |y1 - y2| / sqrt(2)
    >>> sampson_distance(F, [[0., 0.]], [[5., 2.]])
    array([1.41421356])
    """
    F = as_matrix(F, "F", (3, 3))
    x1, x2 = _check_pair(x1, x2, 1)
    x1_h = np.hstack([x1, np.ones((len(x1), 1))])
    x2_h = np.hstack([x2, np.ones((len(x2), 1))])
    Fx1 = x1_h @ F.T
    Ftx2 = x2_h @ F
    num = np.abs(np.einsum("ni,ni->n", x2_h, Fx1))
    den = np.sqrt(Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / den, np.where(num > 0, np.inf, 0.0))


def homography_dlt(x1, x2):
    """Normalised DLT homography ``x2_h ≃ H x1_h`` (H&Z Alg. 4.2), and its Sampson errors in pixels.

    Used here to recognise degenerate two-view data (a plane, or no baseline).

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        N >= 4.

    Returns
    -------
    H : (3, 3) ndarray
        Unit Frobenius norm.
    d : (N,) ndarray
        Sampson distance of each correspondence to H (H&Z Sec. 4.2.6), in pixels, not squared.

    Examples
    --------
    >>> x1 = np.array([[0., 0], [1, 0], [0, 1], [1, 1], [2, 3]])
    >>> H, d = homography_dlt(x1, 2 * x1 + 1)
    >>> np.round(H / H[2, 2], 9) + 0.0, bool(d.max() < 1e-9)
    (array([[2., 0., 1.],
           [0., 2., 1.],
           [0., 0., 1.]]), True)
    """
    x1, x2 = _check_pair(x1, x2, 4)
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    y1, y2 = _apply(T1, x1), _apply(T2, x2)
    n = len(y1)
    y1_h = np.hstack([y1, np.ones((n, 1))])
    A = np.zeros((2 * n, 9))
    A[0::2, 3:6] = -y1_h
    A[0::2, 6:9] = y2[:, 1:2] * y1_h
    A[1::2, 0:3] = y1_h
    A[1::2, 6:9] = -y2[:, 0:1] * y1_h
    H = np.linalg.inv(T2) @ _null_space_svd(A)[1][-1].reshape(3, 3) @ T1
    H /= np.linalg.norm(H)
    # Sampson error of the two constraints r = (x2 h3·X1 - h1·X1, y2 h3·X1 - h2·X1)
    X1 = np.hstack([x1, np.ones((n, 1))])
    hx = X1 @ H.T
    r = np.column_stack([x2[:, 0] * hx[:, 2] - hx[:, 0], x2[:, 1] * hx[:, 2] - hx[:, 1]])
    J = np.zeros((n, 2, 4))
    J[:, 0, 0] = x2[:, 0] * H[2, 0] - H[0, 0]
    J[:, 0, 1] = x2[:, 0] * H[2, 1] - H[0, 1]
    J[:, 1, 0] = x2[:, 1] * H[2, 0] - H[1, 0]
    J[:, 1, 1] = x2[:, 1] * H[2, 1] - H[1, 1]
    J[:, 0, 2] = J[:, 1, 3] = hx[:, 2]
    JJt = J @ J.transpose(0, 2, 1)
    d2 = np.einsum("ni,nij,nj->n", r, np.linalg.pinv(JJt), r)
    return H, np.sqrt(np.maximum(d2, 0.0))


def _eight_point_normalised(y1, y2):
    """Rank-2 F from normalised points, and the singular values of the design matrix."""
    s, Vt = _null_space_svd(_design(y1, y2))
    return _enforce_rank2(Vt[-1].reshape(3, 3)), s


def _sampson_and_gradient(F, x1_h, x2_h):
    """Signed Sampson distances ``d`` (N,) of pixel correspondences to F, and ``∂d/∂F`` (N, 3, 3)."""
    a = x1_h @ F.T
    b = x2_h @ F
    num = np.einsum("ni,ni->n", x2_h, a)
    den = a[:, 0] ** 2 + a[:, 1] ** 2 + b[:, 0] ** 2 + b[:, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        d = num / np.sqrt(den)
        a[:, 2] = 0.0
        b[:, 2] = 0.0
        G = (x2_h[:, :, None] * x1_h[:, None, :] - (num / den)[:, None, None]
             * (a[:, :, None] * x1_h[:, None, :] + x2_h[:, :, None] * b[:, None, :])) / np.sqrt(den)[:, None, None]
    return d, G


_E_SKEW = np.stack([skew(e) for e in np.eye(3)])


def _sampson_fundamental(x1, x2, T1, T2, starts_n, max_iter=50, tol=1e-7):
    """Rank-2 F minimising the sum of squared Sampson distances (pixels), by Levenberg–Marquardt.

    A first-order stand-in for the gold standard (H&Z Sec. 11.4.3), with no point parameters, so it is
    fast. F is kept of rank 2 by the orthonormal representation (Bartoli & Sturm 2004): in normalised
    coordinates ``F_n = U diag(1, s, 0) Vᵀ`` with U, V rotations, updated as ``U exp([ω_U]×)``,
    ``V exp([ω_V]×)`` and ``s + δs`` (7 parameters); ``F = T2ᵀ F_n T1``. Each normalised start in
    ``starts_n`` is refined and the lowest cost wins. Returns ``(F, cost)``, F of unit norm.
    """
    n = len(x1)
    x1_h = np.hstack([x1, np.ones((n, 1))])
    x2_h = np.hstack([x2, np.ones((n, 1))])
    best = (np.inf, None)
    for Fn in starts_n:
        U, sv, Vt = np.linalg.svd(Fn)
        if not sv[0] > 0:
            continue
        U, V, s = U * np.sign(np.linalg.det(U)), Vt.T * np.sign(np.linalg.det(Vt)), sv[1] / sv[0]

        def pixels(U, s, V):
            return T2.T @ (U * [1.0, s, 0.0]) @ V.T @ T1

        d, G = _sampson_and_gradient(pixels(U, s, V), x1_h, x2_h)
        cost, lam = d @ d, 1e-3
        for _ in range(max_iter):
            if not np.isfinite(cost):
                break
            S = np.diag([1.0, s, 0.0])
            dFn = np.concatenate([U @ _E_SKEW @ S @ V.T, -(U @ S) @ _E_SKEW @ V.T,
                                  (U @ np.diag([0.0, 1.0, 0.0]) @ V.T)[None]])      # ∂F_n / ∂(ω_U, ω_V, s)
            J = np.einsum("nij,pij->np", G, T2.T @ dFn @ T1)             # (N, 7)
            A, g = J.T @ J, J.T @ d
            improved = False
            while lam < 1e10:
                step = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12 * np.trace(A)), -g)
                U2, V2 = U @ rotation_from_angle_axis(step[:3]), V @ rotation_from_angle_axis(step[3:6])
                d2, G2 = _sampson_and_gradient(pixels(U2, s + step[6], V2), x1_h, x2_h)
                cost2 = d2 @ d2
                if np.isfinite(cost2) and cost2 < cost:
                    small = cost - cost2 <= tol * cost
                    U, V, s, d, G, cost = U2, V2, s + step[6], d2, G2, cost2
                    lam, improved = max(lam / 10, 1e-12), True
                    break
                lam *= 10
            if not improved or small:
                break
        if cost < best[0]:
            F = pixels(U, s, V)
            best = (cost, F / np.linalg.norm(F))
    return best[1], best[0]


@dataclass
class ModelSelection:
    """What :func:`gric_model_selection` found: F or a homography, by Torr's GRIC.

    Attributes
    ----------
    n : int
        Correspondences.
    F : (3, 3) ndarray
        Rank-2 F of (near) maximum likelihood: least sum of squared Sampson distances, unit norm.
    H : (3, 3) ndarray
        The normalised-DLT homography (:func:`homography_dlt`).
    e_F, e_H : float
        Sums of squared Sampson distances (px²) of the correspondences to F and to H.
    sigma : float
        The noise level used, px: given, or estimated from F, ``sqrt(e_F / (n - 7))``.
    gric_F, gric_H : float
        ``GRIC = e / σ² + λ1 d n + λ2 k`` with ``λ1 = log 4``, ``λ2 = log 4n`` and (d, k) = (3, 7) for F,
        (2, 8) for H. The lower wins.
    """

    n: int
    F: np.ndarray
    H: np.ndarray
    e_F: float
    e_H: float
    sigma: float
    gric_F: float
    gric_H: float

    @property
    def degenerate(self):
        """True when the homography wins (``gric_H <= gric_F``): F is not determined by these data."""
        return bool(self.gric_H <= self.gric_F)

    def text(self):
        """One line with the numbers: noise variance per degree of freedom of each model, σ, both GRICs."""
        n = self.n
        return (f"GRIC {self.gric_H:.1f} for H vs {self.gric_F:.1f} for F (N = {n}, sigma = {self.sigma:.3g} px; "
                f"noise variance per degree of freedom {self.e_H / (2 * n - 8):.3g} px² for H vs "
                f"{self.e_F / (n - 7):.3g} px² for F)")


def gric_model_selection(x1, x2, sigma_px=None):
    """Homography or fundamental matrix? Torr's geometric robust information criterion (GRIC).

    Torr (1998, 2002): for a model of dimension d (the variety it defines in the 4D space of
    correspondences) with k parameters, ``GRIC = Σ ρ(e_i² / σ²) + λ1 d n + λ2 k`` with ``λ1 = log r``
    (r = 4, the data dimension) and ``λ2 = log(r n)``; the model with the lower GRIC is chosen. F has
    d = 3, k = 7; H has d = 2, k = 8. The ``λ1 d n`` term charges F for the extra coordinate each
    corrected correspondence keeps (a point of a 3D variety rather than a 2D one), so F wins only when
    it lowers the residual by more than ``log 4 ≈ 1.39`` σ² per correspondence beyond what H leaves.
    Here ``ρ`` is the identity: the correspondences are inliers (Torr caps ρ at ``2 (r - d)`` to resist
    outliers; on inliers the cap makes H win wrongly in forward motion, where the parallax is large far
    from the epipole and zero near it: it refused 2-6 % of the forward pairs of the module docstring).
    σ² is estimated from F, ``e_F / (n - 7)``, unless given.

    Both models are fitted by (near) maximum likelihood, which is the point: the linear 8-point F is far
    from the best F when the epipole lies inside the image (forward motion), leaving up to two to three
    times the noise variance, and a comparison with it refuses valid pairs. F minimises the sum of squared
    Sampson distances (H&Z Sec. 11.4.3; Levenberg–Marquardt over rank-2 F), started from the 8-point and
    from the best epipole of :func:`epipole_search` (the 8-point alone often starts in the wrong basin);
    on 300 forward pairs its Sampson cost was at most 2.4 % above the gold standard's (median: equal).
    H is the normalised DLT (close to its ML estimate).

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Corresponding pixels (inliers), N >= 9.
    sigma_px : float, optional
        The noise level (standard deviation of each pixel coordinate), if known. By default it is
        estimated from F, ``sqrt(e_F / (N - 7))``: unbiased when F is determined, but low on degenerate
        data, where F over-fits (module docstring), which makes H lose more often than it should.

    Returns
    -------
    ModelSelection
        ``.degenerate`` is True when H wins; ``.text()`` gives the numbers in one line.

    Raises
    ------
    ValueError
        Bad input (as :func:`fundamental_8point`), or N < 9.

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(60, 2, noise_px=0.5, rng=np.random.default_rng(0))
    >>> ms = gric_model_selection(*s.pair(0, 1)[:2])
    >>> ms.degenerate, bool(ms.gric_H > ms.gric_F), bool(0.3 < ms.sigma < 0.7)
    (False, True, True)
    >>> s = make_scene(200, 2, noise_px=0.5, planar=True, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1)
    >>> gric_model_selection(x1, x2).degenerate, gric_model_selection(x1, x2, sigma_px=0.5).degenerate
    (True, True)
    """
    x1, x2 = _check_pair(x1, x2, 9)
    if sigma_px is not None and not (np.isfinite(sigma_px) and sigma_px > 0):
        raise ValueError(f"sigma_px must be a positive number of pixels; got {sigma_px}")
    n = len(x1)
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    Fn8 = _eight_point_normalised(_apply(T1, x1), _apply(T2, x2))[0]
    starts = [Fn8 / np.linalg.norm(Fn8)]
    for F in epipole_search(x1, x2, n_dirs=200):
        Fn = np.linalg.inv(T2).T @ F @ np.linalg.inv(T1)
        starts.append(Fn / np.linalg.norm(Fn))
    F, e_F = _sampson_fundamental(x1, x2, T1, T2, starts)
    H, d_H = homography_dlt(x1, x2)
    e_H = float(d_H @ d_H)
    if F is None:                              # every start failed (not finite): the 8-point
        F = T2.T @ Fn8 @ T1
        e_F = float(np.sum(sampson_distance(F, x1, x2) ** 2))
    sigma2 = float(sigma_px) ** 2 if sigma_px is not None else max(e_F / (n - 7), 1e-300)
    l1, l2 = np.log(4.0), np.log(4.0 * n)
    gric_F = e_F / sigma2 + l1 * 3 * n + l2 * 7
    gric_H = e_H / sigma2 + l1 * 2 * n + l2 * 8
    return ModelSelection(n=n, F=_canonical_sign(F), H=H, e_F=float(e_F), e_H=e_H, sigma=float(np.sqrt(sigma2)),
                          gric_F=float(gric_F), gric_H=float(gric_H))


def fundamental_8point(x1, x2, rank_tol=1e-8, degeneracy="gric", h_ratio="deprecated"):
    """Normalised 8-point estimate of F (Hartley 1997; H&Z Alg. 11.1).

    Steps: normalise each image (centroid 0, mean distance √2); build ``A`` with rows ``kron(x2_h, x1_h)``;
    the right singular vector of the smallest singular value is ``F``; set its smallest singular
    value to 0 (rank 2); undo the normalisation, ``F = T2ᵀ F_n T1``.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Corresponding pixels in images 1 and 2, N >= 8.
    rank_tol : float
        Degenerate (noise-free) when the normalised design matrix's 8th singular value is below
        ``rank_tol`` times its largest.
    degeneracy : {'gric', None}
        For N >= 50: refuse the data when a homography explains them at least as well as F by Torr's
        GRIC (:func:`gric_model_selection`; module docstring). None turns this test off.
    h_ratio : None
        Deprecated: ``h_ratio=None`` is ``degeneracy=None`` (the fixed-ratio test it tuned is gone).

    Returns
    -------
    F : (3, 3) ndarray
        Rank 2, unit Frobenius norm (largest entry positive), with ``x2_hᵀ F x1_h = 0``.

    Raises
    ------
    ValueError
        If the shapes differ, N < 8, a coordinate is not finite, or the points are degenerate (all on
        one plane, or zero baseline: a homography maps x1 to x2).

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(20, 2, noise_px=0.0, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1, which="true")
    >>> F = fundamental_8point(x1, x2)
    >>> F.shape, bool(sampson_distance(F, x1, x2).max() < 1e-9)
    ((3, 3), True)
    """
    if h_ratio is None:
        degeneracy = None
    elif h_ratio != "deprecated":
        raise ValueError(f"h_ratio={h_ratio!r}: the fixed-ratio degeneracy test is gone; use degeneracy='gric' "
                         "(Torr's GRIC, the default) or degeneracy=None (no test)")
    if degeneracy not in ("gric", None):
        raise ValueError(f"degeneracy must be 'gric' or None; got {degeneracy!r}")
    x1, x2 = _check_pair(x1, x2, 8)
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    Fn, s = _eight_point_normalised(_apply(T1, x1), _apply(T2, x2))
    if s[7] < rank_tol * s[0]:
        raise ValueError(
            f"degenerate correspondences: the normalised 8-point design matrix has rank < 8 "
            f"(8th singular value {s[7] / s[0]:.1e} of the largest). A homography maps x1 to x2: all points "
            "on one plane, or zero baseline (pure rotation), or a critical configuration")
    F = _canonical_sign(T2.T @ Fn @ T1)
    if degeneracy is not None and len(x1) >= H_TEST_MIN_POINTS:
        _raise_if_degenerate(x1, x2)
    return F


def _raise_if_degenerate(x1, x2):
    """The noisy-degeneracy test of :func:`fundamental_8point` (module docstring)."""
    ms = gric_model_selection(x1, x2)
    if ms.degenerate:
        raise ValueError(
            f"degenerate correspondences: a homography explains them at least as well as F ({ms.text()}): "
            "all points on one plane, or zero baseline (pure rotation), or too little parallax to determine F")


def fundamental_7point(x1, x2):
    """The up to three F through exactly seven correspondences (H&Z Sec. 11.1.2).

    The 7×9 design matrix (normalised points) has a two-dimensional null space ``F = α F1 + (1 - α) F2``;
    ``det F = 0`` is a cubic in α with one or three real roots.

    Parameters
    ----------
    x1, x2 : (7, 2) array_like

    Returns
    -------
    list of (3, 3) ndarray
        Each rank 2 with unit norm; empty when the sample is degenerate (design matrix rank < 7).

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(7, 2, noise_px=0.0, rng=np.random.default_rng(1))
    >>> x1, x2, _ = s.pair(0, 1, which="true")
    >>> Fs = fundamental_7point(x1, x2)
    >>> len(Fs) in (1, 3), all(sampson_distance(F, x1, x2).max() < 1e-8 for F in Fs)
    (True, True)
    """
    x1 = as_points(x1, "x1")
    x2 = as_points(x2, "x2", like=x1)
    if x1.shape[0] != 7:
        raise ValueError(f"the 7-point solver needs exactly 7 correspondences; got {x1.shape[0]}")
    return _seven_point(x1, x2)


def _seven_point(x1, x2):
    try:
        T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    except ValueError:
        return []
    s, Vt = _null_space_svd(_design(_apply(T1, x1), _apply(T2, x2)))
    if s[6] < 1e-8 * s[0]:
        return []
    F1, F2 = Vt[-2].reshape(3, 3), Vt[-1].reshape(3, 3)
    # det(α F1 + (1 - α) F2) is a cubic in α: interpolate it at four values, then find the real roots
    alphas = np.array([-1.0, 0.0, 1.0, 2.0])
    dets = [np.linalg.det(a * F1 + (1 - a) * F2) for a in alphas]
    coef = np.linalg.solve(np.vander(alphas, 4), dets)
    roots = np.roots(coef) if np.any(np.abs(coef) > 0) else np.zeros(0)
    out = []
    for r in roots[np.abs(roots.imag) < 1e-9 * np.maximum(1.0, np.abs(roots.real))].real:
        F = T2.T @ _enforce_rank2(r * F1 + (1 - r) * F2) @ T1
        out.append(_canonical_sign(F))
    return out


def fundamental_ransac(x1, x2, threshold=1.0, rng=None, confidence=0.999, max_iter=10000, refits=5):
    """Robust F: adaptive RANSAC on minimal 7-point samples, then the 8-point on the inliers (H&Z Alg. 11.4).

    Why 7-point samples: a sample of 7 instead of 8 needs fewer trials for the same confidence
    (``log(1 - p) / log(1 - w^s)``: 588 against 1177 at 50 % inliers and p = 0.99), and each candidate
    is exactly of rank 2, so its Sampson distances are meaningful; the up-to-3 real roots are all scored.
    A sample with a rank-deficient design matrix (e.g. 7 points on one plane) gives no candidate.
    After the loop the 8-point is fitted to the inliers, the inliers recomputed with it, and this is
    repeated (at most ``refits`` times) until the inlier set stops changing.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Putative correspondences, N >= 8.
    threshold : float
        Inlier threshold on the Sampson distance, in pixels (about 2σ for noise σ: H&Z Sec. 4.7.1
        gives t² = 3.84 σ² for a codimension-1 model).
    rng : numpy.random.Generator
        Required.
    confidence : float
        Probability that at least one sample was all inliers when sampling stops.
    max_iter : int
        At most this many samples.
    refits : int
        Inlier re-estimation rounds after sampling.

    Returns
    -------
    F : (3, 3) ndarray
        Rank 2, unit norm.
    inliers : (N,) bool ndarray

    Raises
    ------
    ValueError
        Bad input as for :func:`fundamental_8point`, no ``rng``, no non-degenerate sample, or degenerate
        inliers (the final 8-point's checks).

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(60, 2, noise_px=0.5, outlier_ratio=0.2, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1)
    >>> F, inl = fundamental_ransac(x1, x2, threshold=1.5, rng=np.random.default_rng(0))
    >>> F.shape, inl.shape == (len(x1),)
    ((3, 3), True)
    """
    x1, x2 = _check_pair(x1, x2, 8)
    if not isinstance(rng, np.random.Generator):
        raise ValueError("rng must be a numpy.random.Generator, e.g. np.random.default_rng(0)")
    if not threshold > 0:
        raise ValueError(f"threshold must be a positive number of pixels; got {threshold}")
    F, inliers, _ = ransac(len(x1), 7, lambda idx: _seven_point(x1[idx], x2[idx]),
                           lambda F: sampson_distance(F, x1, x2), threshold, rng,
                           confidence=confidence, max_iter=max_iter)
    tested = None
    for _ in range(refits):
        if inliers.sum() < 8:
            break
        F_new = fundamental_8point(x1[inliers], x2[inliers], degeneracy=None)   # raises if exactly degenerate
        tested = inliers
        new = sampson_distance(F_new, x1, x2) < threshold
        if new.sum() < 8:
            break
        F, changed, inliers = F_new, np.any(new != inliers), new
        if not changed:
            break
    if tested is not None and tested.sum() >= H_TEST_MIN_POINTS:
        _raise_if_degenerate(x1[tested], x2[tested])             # once, on the inliers of the last refit
    return F, inliers


# --------------------------------------------------------------------------------------------------
# the gold standard (maximum likelihood)
# --------------------------------------------------------------------------------------------------

def epipole_search(x1, x2, n_dirs=400, n_best=1, min_angle_deg=8.0):
    """Global search for starting points of the gold standard: F with a given epipole, over a grid of epipoles.

    For a fixed right epipole e, the F with ``F e = 0`` that minimises the algebraic error is linear
    (H&Z Sec. 11.3: ``F = G Bᵀ`` with B an orthonormal basis of e⊥, and G the smallest eigenvector of a
    6×6 matrix). Its Sampson error is evaluated for ``n_dirs`` epipoles spread evenly over the projective
    plane (a Fibonacci hemisphere of directions in Hartley-normalised coordinates, so epipoles at
    infinity are included); the ``n_best`` lowest, at least ``min_angle_deg`` apart, are returned. When the
    epipole lies inside the image (forward motion) the 8-point often lands in the wrong basin of the ML
    cost; these starts do not.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        N >= 8.
    n_dirs : int
        Epipole directions tried.
    n_best : int
        Starts returned.
    min_angle_deg : float
        Smallest angle between the epipole directions of two returned starts.

    Returns
    -------
    list of (3, 3) ndarray
        Rank-2 F, unit norm, best (lowest total squared Sampson error) first.

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(30, 2, noise_px=0.0, layout="forward", rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1, which="true")
    >>> len(epipole_search(x1, x2, n_best=2)), epipole_search(x1, x2)[0].shape
    (2, (3, 3))
    """
    x1, x2 = _check_pair(x1, x2, 8)
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    A = _design(_apply(T1, x1), _apply(T2, x2))
    AtA = A.T @ A
    i = np.arange(n_dirs) + 0.5
    z = i / n_dirs
    phi = np.pi * (1 + np.sqrt(5)) * i
    E = np.column_stack([np.sqrt(1 - z ** 2) * np.cos(phi), np.sqrt(1 - z ** 2) * np.sin(phi), z])
    helper = np.where(np.abs(E[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    b1 = np.cross(E, helper)
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    B = np.stack([b1, np.cross(E, b1)], axis=2)                  # (m, 3, 2), orthonormal basis of e⊥
    C = np.zeros((n_dirs, 9, 6))                                 # vec(G Bᵀ) = C vec(G)
    for r in range(3):
        C[:, 3 * r:3 * r + 3, 2 * r:2 * r + 2] = B
    _, vecs = np.linalg.eigh(C.transpose(0, 2, 1) @ AtA @ C)
    Fn = (C @ vecs[:, :, :1]).reshape(n_dirs, 3, 3)
    Fp = T2.T @ Fn @ T1                                           # back to pixels
    x1_h, x2_h = np.hstack([x1, np.ones((len(x1), 1))]), np.hstack([x2, np.ones((len(x2), 1))])
    Fx1 = Fp @ x1_h.T                                             # (m, 3, N)
    Ftx2 = Fp.transpose(0, 2, 1) @ x2_h.T
    num = (x2_h.T[None] * Fx1).sum(1) ** 2
    den = Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2
    cost = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf).sum(1)
    chosen = []
    for m in np.argsort(cost):
        if all(abs(E[m] @ E[c]) < np.cos(np.radians(min_angle_deg)) for c in chosen):
            chosen.append(m)
        if len(chosen) == n_best:
            break
    return [_canonical_sign(Fp[m]) for m in chosen]


class GoldStandardProblem:
    """The maximum-likelihood F problem of H&Z Alg. 11.3, as residuals and a sparse Jacobian.

    Cameras ``P1 = [I | 0]`` and ``P2`` (12 free entries); point i is ``X_i = (u_i, v_i, 1, ρ_i)``: its
    (corrected) image in view 1 and a projective inverse depth, so ``P1 X_i = (u_i, v_i, 1)`` exactly and
    ``P2 X_i`` its image in view 2 (this covers every point not at infinity in image 1, including points
    on the plane at infinity of the projective frame, with 3 parameters each). Everything is computed
    in Hartley-normalised coordinates (one similarity per image) and the residuals are scaled back to
    pixels, so the cost is the reprojection error in pixels (H&Z eq. 11.6). The parameter vector is
    ``[P2.ravel() (12), u_0, v_0, ρ_0, u_1, ...]``; the residuals are ``[x1 residual (2), x2 residual (2)]``
    per point. Gauge freedom (5: the scale of P2 and ``P2 -> P2 + e' vᵀ`` with λ) is left to the damping.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Measured correspondences, pixels.
    F0 : (3, 3) array_like
        Initial F (rank 2). The initial points are its optimal correction (H&Z Alg. 12.1), so the
        initial cost is exactly ``4 N fundamental_residual(F0, x1, x2)²``.
    """

    def __init__(self, x1, x2, F0):
        x1, x2 = _check_pair(x1, x2, 8)
        F0 = _rank2_fundamental(F0, "F0")[0]
        self.x1, self.x2, self.n = x1, x2, len(x1)
        self.T1, self.T2 = hartley_normalisation(x1), hartley_normalisation(x2)
        self.s1, self.s2 = self.T1[0, 0], self.T2[0, 0]
        self.y1, self.y2 = _apply(self.T1, x1), _apply(self.T2, x2)
        Fn = np.linalg.inv(self.T2).T @ F0 @ np.linalg.inv(self.T1)
        Fn /= np.linalg.norm(Fn)
        e2 = np.linalg.svd(Fn)[0][:, 2]                      # left epipole: e2ᵀ F = 0
        P2 = np.hstack([skew(e2) @ Fn, e2[:, None]])         # H&Z Result 9.14
        x1_hat, x2_hat = triangulate_optimal(F0, x1, x2)
        u = _apply(self.T1, x1_hat)
        z2 = np.hstack([_apply(self.T2, x2_hat), np.ones((self.n, 1))])
        # rho from z2 ~ M u_h + rho e: least squares on z2 × (M u_h + rho e) = 0
        Mu = np.hstack([u, np.ones((self.n, 1))]) @ P2[:, :3].T
        a, b = np.cross(z2, P2[:, 3]), np.cross(z2, Mu)
        rho = -np.einsum("ni,ni->n", a, b) / np.maximum(np.einsum("ni,ni->n", a, a), 1e-300)
        self.p0 = np.concatenate([P2.ravel(), np.column_stack([u, rho]).ravel()])

    @property
    def n_params(self):
        return 12 + 3 * self.n

    def unpack(self, p):
        """``P2 (3, 4)`` and the point parameters ``(N, 3)`` (u, v, ρ) in normalised coordinates."""
        return p[:12].reshape(3, 4), p[12:].reshape(self.n, 3)

    def _project(self, p):
        P2, q = self.unpack(p)
        X = np.column_stack([q[:, 0], q[:, 1], np.ones(self.n), q[:, 2]])
        return P2, q, X, X @ P2.T

    def residuals(self, p):
        """``(4N,)`` residuals in pixels: per point ``(x1_hat - x1, x2_hat - x2)``."""
        _, q, _, y = self._project(p)
        r1 = (q[:, :2] - self.y1) / self.s1
        r2 = (y[:, :2] / y[:, 2:] - self.y2) / self.s2
        return np.hstack([r1, r2]).ravel()

    def _blocks(self, p):
        """Dense per-point Jacobian blocks: ``A (N, 2, 12)`` = ∂r2/∂P2, ``B (N, 4, 3)`` = ∂r/∂(u, v, ρ)."""
        P2, q, X, y = self._project(p)
        w = 1.0 / y[:, 2]
        D = np.zeros((self.n, 2, 3))                         # ∂π/∂y, π(y) = y[:2] / y[2]
        D[:, 0, 0] = D[:, 1, 1] = w
        D[:, :, 2] = -y[:, :2] * (w ** 2)[:, None]
        D /= self.s2
        A = (D[:, :, :, None] * X[:, None, None, :]).reshape(self.n, 2, 12)
        B = np.zeros((self.n, 4, 3))
        B[:, 0, 0] = B[:, 1, 1] = 1.0 / self.s1
        B[:, 2:, :] = D @ P2[:, [0, 1, 3]]
        return A, B

    def jacobian(self, p):
        """Analytic Jacobian as a ``scipy.sparse.csr_matrix`` of shape ``(4N, 12 + 3N)``."""
        import scipy.sparse

        A, B = self._blocks(p)
        rows, cols = self._pattern()
        full = np.zeros((self.n, 4, 15))
        full[:, 2:, :12] = A
        full[:, :, 12:] = B
        keep = self._mask15()
        return scipy.sparse.csr_matrix((full[:, keep].ravel(), (rows, cols)), shape=(4 * self.n, self.n_params))

    def _mask15(self):
        keep = np.zeros((4, 15), bool)
        keep[2:, :12] = True
        keep[:2, 12:14] = True
        keep[2:, 12:] = True
        return keep

    def _pattern(self):
        keep = self._mask15()
        r, c = np.nonzero(keep)
        i = np.arange(self.n)[:, None]
        rows = 4 * i + r[None]
        cols = np.where(c[None] < 12, c[None], 12 + 3 * i + (c[None] - 12))
        return rows.ravel(), cols.ravel()

    def sparsity(self):
        """Which Jacobian entries can be non-zero: a ``scipy.sparse`` 0/1 matrix (for ``jac_sparsity``)."""
        import scipy.sparse

        rows, cols = self._pattern()
        return scipy.sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(4 * self.n, self.n_params))

    def F(self, p):
        """The F of these parameters in pixels: ``F = T2ᵀ [e']× M T1`` with ``P2 = [M | e']`` (H&Z Result 9.9)."""
        P2 = p[:12].reshape(3, 4)
        return _canonical_sign(self.T2.T @ skew(P2[:, 3]) @ P2[:, :3] @ self.T1)

    def points(self, p):
        """Corrected pixels ``x1_hat, x2_hat`` (N, 2): the reprojections of the current points."""
        _, q, _, y = self._project(p)
        return (_apply(np.linalg.inv(self.T1), q[:, :2]),
                _apply(np.linalg.inv(self.T2), y[:, :2] / y[:, 2:]))

    def solve(self, p=None, max_iter=100, tol=1e-10):
        """Levenberg–Marquardt with the Schur complement on the 3×3 point blocks (H&Z Sec. A6.3-A6.4).

        The normal equations ``[U W; Wᵀ V] [δa; δb] = -[g_a; g_b]`` (a: the 12 camera entries, b: the points,
        V block diagonal) are reduced to the 12×12 system ``(U - W V⁻¹ Wᵀ) δa = -g_a + W V⁻¹ g_b``; each point
        step is then ``δb_i = -V_i⁻¹ (g_b_i + W_iᵀ δa)``. Marquardt damping ``(1 + λ)`` on the diagonals, plus
        a tiny ``λ`` absolute term, also fixes the gauge. A step is kept only if it lowers the cost, so the
        cost never rises above the initial one.

        Returns
        -------
        p : (12 + 3N,) ndarray
        info : dict
            ``cost`` (history of 0.5 Σ r², per accepted step), ``n_iter``, ``converged``.
        """
        p = self.p0.copy() if p is None else np.array(p, float)
        r = self.residuals(p)
        cost = 0.5 * r @ r
        history, lam, converged = [cost], 1e-3, False
        it = 0
        for it in range(1, max_iter + 1):
            A, B = self._blocks(p)
            rr = r.reshape(self.n, 4)
            A2 = A.reshape(-1, 12)
            U = A2.T @ A2
            V = B.transpose(0, 2, 1) @ B
            W = A.transpose(0, 2, 1) @ B[:, 2:, :]                  # (N, 12, 3)
            ga = A2.T @ rr[:, 2:].ravel()
            gb = (B.transpose(0, 2, 1) @ rr[:, :, None])[:, :, 0]
            improved = False
            while lam < 1e16:
                Ud = U + lam * (np.diag(np.diag(U)) + 1e-12 * np.trace(U) / 12 * np.eye(12))
                dV = np.einsum("nii->ni", V)
                Vd = V + lam * (dV[:, :, None] * np.eye(3) + 1e-12 * dV.sum(1)[:, None, None] / 3 * np.eye(3))
                Vinv = np.linalg.inv(Vd)
                WVinv = W @ Vinv
                S = Ud - WVinv.transpose(1, 0, 2).reshape(12, -1) @ W.transpose(1, 0, 2).reshape(12, -1).T
                rhs = -ga + WVinv.transpose(1, 0, 2).reshape(12, -1) @ gb.ravel()
                try:
                    da = np.linalg.solve(S, rhs)
                except np.linalg.LinAlgError:
                    lam *= 10
                    continue
                db = -(Vinv @ (gb + (W.transpose(0, 2, 1) @ da))[:, :, None])[:, :, 0]
                p_new = p + np.concatenate([da, db.ravel()])
                r_new = self.residuals(p_new)
                cost_new = 0.5 * r_new @ r_new
                if np.isfinite(cost_new) and cost_new < cost:
                    p_new[:12] /= np.linalg.norm(p_new[:12])          # a pure gauge move (P2 up to scale)
                    done = cost - cost_new <= tol * cost
                    p, r, cost = p_new, self.residuals(p_new), cost_new
                    history.append(cost)
                    lam = max(lam / 10, 1e-12)
                    improved = True
                    break
                lam *= 10
            if not improved or done:
                converged = True
                break
        return p, dict(cost=np.array(history), n_iter=it, converged=converged)


def fundamental_gold_standard(x1, x2, F0=None, return_points=False, n_starts=1, max_iter=100, tol=1e-10,
                              return_info=False):
    """Maximum-likelihood ("gold standard") F (H&Z Alg. 11.3).

    Minimises the reprojection error ``Σ |x1 - P1 X|² + |x2 - P2 X|²`` over the camera ``P2`` (12
    entries, with ``P1 = [I | 0]``) and the N points (:class:`GoldStandardProblem`), starting from ``F0``
    (the normalised 8-point if None): ``P2 = [[e']× F0 | e']`` and the points from the optimal correction.
    The solver is our own sparse Levenberg–Marquardt with an analytic Jacobian
    (:meth:`GoldStandardProblem.solve`): the Schur complement leaves a 12×12 system per iteration, so
    N = 200 takes about a millisecond per iteration. (``scipy.optimize.least_squares`` with
    ``jac=problem.jacobian`` or ``jac_sparsity=problem.sparsity()`` solves the same problem, slower.)

    One addition makes it reliable when the epipole is inside the image (forward motion): there the
    cost has several local minima, the 8-point often starts in the wrong one, and LM can also stall
    where a corrected point reaches the epipole of image 2 (its 3D point would have to pass through
    the centre of camera 1, ρ through infinity). So besides F0 we also start from the ``n_starts`` best F
    of a global search over the epipole (:func:`epipole_search`) and keep the lowest final cost: the
    result is never worse than the textbook run from F0.

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Corresponding pixels, N >= 8 (inliers only: the cost is not robust).
    F0 : (3, 3) array_like, optional
        Initial F of rank 2.
    return_points : bool
        Also return the corrected pixels (the reprojections of the ML points).
    n_starts : int
        Extra starts from :func:`epipole_search` (0: only F0, the textbook algorithm).
    max_iter : int
        Levenberg–Marquardt iterations at most, per run.
    tol : float
        Stop when an iteration lowers the cost by less than ``tol`` times the cost.
    return_info : bool
        Also return a dict: ``cost`` (history of 0.5 Σ r² of the winning run), ``n_iter``, ``converged``,
        ``start`` (0 for F0, then the epipole-search starts) and ``start_costs`` (final 0.5 Σ r² of each).

    Returns
    -------
    F : (3, 3) ndarray
        Rank 2, unit Frobenius norm.
    x1_hat, x2_hat : (N, 2) ndarray
        With ``return_points``.
    info : dict
        With ``return_info``.

    Raises
    ------
    ValueError
        Bad input as for :func:`fundamental_8point` (including degenerate data when F0 is None).

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> s = make_scene(30, 2, noise_px=1.0, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1)
    >>> F = fundamental_gold_standard(x1, x2)
    >>> F.shape, bool(fundamental_residual(F, x1, x2) <= fundamental_residual(fundamental_8point(x1, x2), x1, x2))
    ((3, 3), True)
    """
    x1, x2 = _check_pair(x1, x2, 8)
    F0 = fundamental_8point(x1, x2) if F0 is None else _rank2_fundamental(F0, "F0")[0]
    starts = [F0] + (epipole_search(x1, x2, n_best=n_starts) if n_starts > 0 else [])
    runs = []
    for F in starts:
        problem = GoldStandardProblem(x1, x2, F)
        p, info = problem.solve(max_iter=max_iter, tol=tol)
        runs.append((problem, p, info))
    costs = np.array([run[2]["cost"][-1] for run in runs])
    best = int(np.argmin(costs))
    problem, p, info = runs[best]
    info.update(start=best, start_costs=costs)
    out = (problem.F(p),)
    if return_points:
        out += problem.points(p)
    if return_info:
        out += (info,)
    return out if len(out) > 1 else out[0]


# --------------------------------------------------------------------------------------------------
# the essential matrix and the relative pose
# --------------------------------------------------------------------------------------------------

def _calibration(K, name):
    K = as_matrix(K, name, (3, 3))
    if abs(np.linalg.det(K)) <= 1e-12 * max(np.abs(K).max(), 1e-300) ** 3:
        raise ValueError(f"{name} is singular: not a calibration matrix")
    return K


def fundamental_from_pose(K1, K2, R, t):
    """``F = K2⁻ᵀ [t]× R K1⁻¹`` for camera 2 ``[R | t]`` relative to camera 1 ``[I | 0]`` (H&Z eq. 9.2).

    Returns F with unit norm and the package's sign convention.

    Examples
    --------
    >>> F = fundamental_from_pose(np.eye(3), np.eye(3), np.eye(3), [1., 0, 0])
    >>> (F * np.sqrt(2)).round(9) + 0.0
    array([[ 0.,  0.,  0.],
           [ 0.,  0.,  1.],
           [ 0., -1.,  0.]])
    """
    K1, K2 = _calibration(K1, "K1"), _calibration(K2, "K2")
    R = as_matrix(R, "R", (3, 3))
    t = as_matrix(np.asarray(t, float).reshape(-1), "t", (3,))
    return _canonical_sign(np.linalg.inv(K2).T @ skew(t) @ R @ np.linalg.inv(K1))


def essential_from_fundamental(F, K1, K2):
    """``E = K2ᵀ F K1``, projected onto the essential manifold (H&Z eq. 9.12, Sec. 9.6.1).

    The projection keeps the singular vectors and sets the singular values to ``(1, 1, 0)``: the
    closest essential matrix in Frobenius norm, up to scale.

    Parameters
    ----------
    F : (3, 3) array_like
    K1, K2 : (3, 3) array_like
        Calibrations of views 1 and 2.

    Returns
    -------
    E : (3, 3) ndarray
        Singular values exactly (1, 1, 0) (to rounding).

    Examples
    --------
    >>> K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]])
    >>> F = fundamental_from_pose(K, K, np.eye(3), [1., 0, 0])
    >>> np.linalg.svd(essential_from_fundamental(F, K, K))[1].round(9)
    array([1., 1., 0.])
    """
    F = as_matrix(F, "F", (3, 3))
    K1, K2 = _calibration(K1, "K1"), _calibration(K2, "K2")
    U, s, Vt = np.linalg.svd(K2.T @ F @ K1)
    if s[1] <= 1e-12 * s[0]:
        raise ValueError(f"K2ᵀ F K1 has rank < 2 (singular values {s}): F is not a fundamental matrix")
    return U @ np.diag([1.0, 1.0, 0.0]) @ Vt


def decompose_essential(E):
    """The four camera poses ``[R | t]`` compatible with E, camera 1 being ``[I | 0]`` (H&Z Result 9.19).

    With ``E = U diag(1, 1, 0) Vᵀ`` (U, V rotations) and ``W = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]``:
    ``R ∈ {U W Vᵀ, U Wᵀ Vᵀ}`` and ``t = ±u3``. Only one of the four puts the points in front of both
    cameras: see :func:`pose_from_essential`.

    Parameters
    ----------
    E : (3, 3) array_like
        Essential matrix (any scale; projected onto the manifold by the SVD).

    Returns
    -------
    list of 4 tuples (R, t)
        ``(U W Vᵀ, u3), (U W Vᵀ, -u3), (U Wᵀ Vᵀ, u3), (U Wᵀ Vᵀ, -u3)``; det R = +1, ``|t| = 1``.

    Raises
    ------
    ValueError
        If E is not finite, not 3×3, or has rank < 2.

    Examples
    --------
    >>> from labutils.geometry import rotation_from_angle_axis
    >>> R0, t0 = rotation_from_angle_axis([0.1, 0.2, 0.3]), np.array([0.6, 0.0, 0.8])
    >>> poses = decompose_essential(skew(t0) @ R0)
    >>> len(poses), any(np.allclose(R, R0) and np.allclose(t, t0) for R, t in poses)
    (4, True)
    """
    E = as_matrix(E, "E", (3, 3))
    U, s, Vt = np.linalg.svd(E)
    if s[0] == 0 or s[1] <= 1e-12 * s[0]:
        raise ValueError(f"E has rank < 2 (singular values {s}): not an essential matrix")
    if np.linalg.det(U) < 0:
        U = -U
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    Ra, Rb, u3 = U @ W @ Vt, U @ W.T @ Vt, U[:, 2]
    return [(Ra, u3.copy()), (Ra, -u3), (Rb, u3.copy()), (Rb, -u3)]


def _cheirality_counts(poses, y1, y2):
    """Points in front of both cameras for each pose; y1, y2 are normalised image points."""
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    counts = []
    for R, t in poses:
        X = triangulate(P1, np.hstack([R, t[:, None]]), y1, y2)
        ok = np.isfinite(X).all(1) & (X[:, 2] > 0) & (X @ R[2] + t[2] > 0)
        counts.append(int(ok.sum()))
    return counts


def pose_from_essential(E, x1, x2, K1, K2, return_counts=False):
    """Relative pose of camera 2 (camera 1 = ``[I | 0]``) from E, chosen by cheirality (H&Z Sec. 9.6.3).

    Each of the four poses of :func:`decompose_essential` is used to triangulate the correspondences
    (linear DLT on ``K⁻¹ x``); the pose that puts the most points in front of both cameras wins.

    Parameters
    ----------
    E : (3, 3) array_like
        Essential matrix, ``x2_nᵀ E x1_n = 0`` for normalised coordinates ``x_n = K⁻¹ x_h``.
    x1, x2 : (N, 2) array_like
        Corresponding pixels (inliers), N >= 1.
    K1, K2 : (3, 3) array_like
    return_counts : bool
        Also return the four counts of points in front (in the order of :func:`decompose_essential`).

    Returns
    -------
    R : (3, 3) ndarray
        det +1.
    t : (3,) ndarray
        ``|t| = 1``: the translation direction (the scale is not observable).

    Raises
    ------
    ValueError
        Bad input, or no pose puts more points in front than every other (e.g. no baseline).

    Examples
    --------
    >>> from labutils.synthetic import make_scene
    >>> from labutils.geometry import relative_pose
    >>> s = make_scene(20, 2, noise_px=0.0, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1, which="true")
    >>> E = essential_from_fundamental(fundamental_8point(x1, x2), s.K, s.K)
    >>> R, t = pose_from_essential(E, x1, x2, s.K, s.K)
    >>> R_true, t_true = relative_pose(s.R[0], s.t[0], s.R[1], s.t[1])
    >>> bool(np.allclose(R, R_true) and np.allclose(t, t_true / np.linalg.norm(t_true)))
    True
    """
    x1, x2 = _check_pair(x1, x2, 1)
    K1, K2 = _calibration(K1, "K1"), _calibration(K2, "K2")
    poses = decompose_essential(E)
    y1 = _apply(np.linalg.inv(K1), x1)
    y2 = _apply(np.linalg.inv(K2), x2)
    counts = _cheirality_counts(poses, y1, y2)
    order = np.argsort(counts)[::-1]
    if counts[order[0]] == 0 or counts[order[0]] == counts[order[1]]:
        raise ValueError(f"cheirality cannot decide between the four poses (points in front: {counts}); "
                         "no baseline, or the correspondences do not fit E")
    R, t = poses[order[0]]
    return (R, t, counts) if return_counts else (R, t)
