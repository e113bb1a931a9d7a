"""The fundamental matrix from correspondences: linear estimates, the Sampson distance, and RANSAC.

Conventions (see the package docstring): ``x2_hᵀ F x1_h = 0``; camera 1 is ``[I | 0]`` and camera 2
``[R | t]``; ``E = [t]× R``; ``F = K2⁻ᵀ E K1⁻¹``. F and E are defined up to scale (and sign): every F
returned here has unit Frobenius norm and rank 2, and its largest entry (in absolute value) is positive.

The estimators, from H&Z Ch. 11:

- :func:`fundamental_8point` (Alg. 11.1) and :func:`fundamental_7point` (Sec. 11.1.2), linear;
- :func:`fundamental_ransac`: 7-point samples in :func:`labutils.ransac.ransac`, then the 8-point on the inliers.

The maximum-likelihood F is :mod:`labutils.gold_standard`; E and the relative pose :mod:`labutils.essential`.

Degenerate input
----------------
The correspondences do not determine F when a homography maps all of them (``x2 ≃ H x1``): all 3D
points on one plane, or no baseline (a pure rotation). Then ``H⁻ᵀ [v]×`` fits every correspondence for
every v, the 8-point design matrix has rank 6, and the 8-point returns an arbitrary member of that
family. :func:`fundamental_8point` raises ``ValueError`` in two cases:

1. noise-free (to rounding) degeneracy: after Hartley's normalisation the design matrix has rank < 8,
   i.e. its 8th singular value is below ``rank_tol`` (1e-8) times the largest;
2. noisy degeneracy, when there are enough points to judge it (N >= 50): a homography explains the
   correspondences about as well as F does. We compare the noise variance each model leaves per
   degree of freedom: ``rho = (e_H / (2N - 8)) / (e_F / (N - 7))``, with ``e_H, e_F`` the sums of squared
   Sampson errors of the linear H (DLT, codimension 2, 8 parameters) and of the rank-2 8-point F
   (codimension 1, 7 parameters). With Gaussian noise and a planar scene (or no baseline) both
   estimate σ², so ``rho ≈ 1``; parallax makes e_H grow. The test needs no σ. We raise when
   ``rho < h_ratio = 1.25``, a compromise we measured (σ = 1 px, ``make_scene``, 200-1000 scenes
   each): planar or pure-rotation data are caught 70-75 % of the time at N = 50, ~90 % at N = 100 and
   98-100 % at N >= 200, while real 3D scenes are rarely rejected: at most ~1 % of forward-motion
   scenes (at any N; those whose parallax is close to the noise, where F is barely determined),
   0.3 % of random 50-point subsets of a turntable pair, none for the general layout. Below N = 50 the
   spread of ``rho`` under pure noise is too wide to tell, and only the rank test applies: noisy
   degenerate data with few points give an F that means nothing. ``h_ratio=None`` turns the test off.

A scene with a dominant plane plus a few off-plane points is *not* degenerate and is accepted; RANSAC
on such data may still lock onto the plane (DEGENSAC, Chum et al. 2005, is not implemented here).
"""
import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_count, as_matrix, as_points, as_positive, as_rng
from .ransac import ransac

H_TEST_MIN_POINTS = 50        # the homography-vs-F degeneracy test needs this many correspondences

# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------

def hartley_normalisation(x: ArrayLike) -> np.ndarray:
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


def transform_points(T, x):
    """Apply a plane homography (e.g. a normalisation) to pixels: ``(N, 2) -> (N, 2)``.

    >>> transform_points(np.diag([2.0, 2.0, 1.0]), np.array([[1.0, 3.0]]))
    array([[2., 6.]])
    """
    x_h = np.hstack([x, np.ones((len(x), 1))]) @ T.T
    return x_h[:, :2] / x_h[:, 2:]


def design_matrix(x1, x2):
    """The 8-point design matrix, rows ``kron(x2_h, x1_h)``: ``A @ F.ravel() = x2_hᵀ F x1_h`` (H&Z eq. 11.3).

    >>> design_matrix(np.array([[1.0, 2.0]]), np.array([[3.0, 4.0]]))
    array([[3., 6., 3., 4., 8., 4., 1., 2., 1.]])
    """
    x1_h = np.hstack([x1, np.ones((len(x1), 1))])
    x2_h = np.hstack([x2, np.ones((len(x2), 1))])
    return (x2_h[:, :, None] * x1_h[:, None, :]).reshape(len(x1), 9)


def canonical_sign(F):
    """F scaled to unit Frobenius norm with its largest-magnitude entry positive (F is defined up to scale and
    sign; every F of the workbook is returned in this form).

    >>> canonical_sign(np.array([[0.0, -2.0], [0.0, 0.0]]))
    array([[-0.,  1.],
           [-0., -0.]])
    """
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


def check_pair(x1, x2, min_n):
    """Two ``(N, 2)`` arrays of corresponding pixels, N >= ``min_n``, or ``ValueError``."""
    x1 = as_points(x1, "x1", min_n=min_n)
    x2 = as_points(x2, "x2", min_n=min_n, like=(x1, "x1"))
    return x1, x2


# --------------------------------------------------------------------------------------------------
# linear estimates
# --------------------------------------------------------------------------------------------------

def sampson_distance(F: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> np.ndarray:
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
    x1, x2 = check_pair(x1, x2, 1)
    x1_h = np.hstack([x1, np.ones((len(x1), 1))])
    x2_h = np.hstack([x2, np.ones((len(x2), 1))])
    Fx1 = x1_h @ F.T
    Ftx2 = x2_h @ F
    num = np.abs(np.einsum("ni,ni->n", x2_h, Fx1))
    den = np.sqrt(Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / den, np.where(num > 0, np.inf, 0.0))


def homography_dlt(x1: ArrayLike, x2: ArrayLike) -> tuple:
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
    x1, x2 = check_pair(x1, x2, 4)
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    y1, y2 = transform_points(T1, x1), transform_points(T2, x2)
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
    s, Vt = _null_space_svd(design_matrix(y1, y2))
    return _enforce_rank2(Vt[-1].reshape(3, 3)), s


def fundamental_8point(x1: ArrayLike, x2: ArrayLike, rank_tol: float = 1e-8, h_ratio: float = 1.25) -> np.ndarray:
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
    h_ratio : float or None
        For N >= 50: degenerate when a homography leaves less than ``h_ratio`` times the noise variance
        per degree of freedom that F leaves (see the module docstring). None turns this test off.

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
    x1, x2 = check_pair(x1, x2, 8)
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    Fn, s = _eight_point_normalised(transform_points(T1, x1), transform_points(T2, x2))
    if s[7] < rank_tol * s[0]:
        raise ValueError(
            f"degenerate correspondences: the normalised 8-point design matrix has rank < 8 "
            f"(8th singular value {s[7] / s[0]:.1e} of the largest). A homography maps x1 to x2: all points "
            "on one plane, or zero baseline (pure rotation), or a critical configuration")
    F = canonical_sign(T2.T @ Fn @ T1)
    n = len(x1)
    if h_ratio is not None and n >= H_TEST_MIN_POINTS:
        e_F = np.sum(sampson_distance(F, x1, x2) ** 2) / (n - 7)
        e_H = np.sum(homography_dlt(x1, x2)[1] ** 2) / (2 * n - 8)
        if e_H < h_ratio * e_F:
            raise ValueError(
                f"degenerate correspondences: a homography explains them as well as F (noise variance per "
                f"degree of freedom {e_H:.3g} px² for H vs {e_F:.3g} px² for F): all points on one plane, "
                "or zero baseline (pure rotation), or too little parallax to determine F")
    return F


def fundamental_7point(x1: ArrayLike, x2: ArrayLike) -> list:
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
    x2 = as_points(x2, "x2", like=(x1, "x1"))
    if x1.shape[0] != 7:
        raise ValueError(f"the 7-point solver needs exactly 7 correspondences; got {x1.shape[0]}")
    return _seven_point(x1, x2)


def _seven_point(x1, x2):
    try:
        T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    except ValueError:
        return []
    s, Vt = _null_space_svd(design_matrix(transform_points(T1, x1), transform_points(T2, x2)))
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
        out.append(canonical_sign(F))
    return out


def fundamental_ransac(x1: ArrayLike, x2: ArrayLike, *, rng: np.random.Generator, threshold_px: float = 1.0,
                       confidence: float = 0.999, max_iter: int = 10000, refits: int = 5) -> tuple:
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
    rng : numpy.random.Generator
        Required.
    threshold_px : float
        Inlier threshold on the Sampson distance, in pixels (about 2σ for noise σ: H&Z Sec. 4.7.1
        gives t² = 3.84 σ² for a codimension-1 model).
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
    >>> F, inl = fundamental_ransac(x1, x2, threshold_px=1.5, rng=np.random.default_rng(0))
    >>> F.shape, inl.shape == (len(x1),)
    ((3, 3), True)
    """
    x1, x2 = check_pair(x1, x2, 8)
    as_rng(rng)
    threshold_px = as_positive(threshold_px, "threshold_px")
    refits = as_count(refits, "refits", 0)
    F, inliers, _ = ransac(len(x1), 7, lambda idx: _seven_point(x1[idx], x2[idx]),
                           lambda F: sampson_distance(F, x1, x2), threshold_px, rng=rng,
                           confidence=confidence, max_iter=max_iter)
    for _ in range(refits):
        if inliers.sum() < 8:
            break
        F_new = fundamental_8point(x1[inliers], x2[inliers])     # raises if the inliers are degenerate
        new = sampson_distance(F_new, x1, x2) < threshold_px
        if new.sum() < 8:
            break
        F, changed, inliers = F_new, np.any(new != inliers), new
        if not changed:
            break
    return F, inliers


