"""Seven correspondences and RANSAC: :func:`fundamental_7point` (H&Z Sec. 11.1.2) and :func:`fundamental_ransac`
(H&Z Alg. 11.4: 7-point samples in :func:`labutils.core.ransac`, the chance test, then the 8-point on the inliers).

The linear 8-point, the Sampson distance and the degeneracy test they use are :mod:`labutils.twoview.epipolar`.
"""
import numpy as np
from numpy.typing import ArrayLike

from ..core.ransac import ransac
from ..core.validation import as_count, as_points, as_positive, as_rng
from .epipolar import (
    H_TEST_MIN_POINTS,
    _canonical_sign,
    _design_matrix,
    _enforce_rank2,
    _null_space_svd,
    _raise_if_degenerate,
    _sampson,
    _transform_points,
    check_pair,
    fundamental_8point,
    hartley_normalisation,
    sampson_distance,
)

__all__ = ["FundamentalRansac", "fundamental_7point", "fundamental_ransac"]


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
    >>> from labutils.core.synthetic import make_scene
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
    s, Vt = _null_space_svd(_design_matrix(_transform_points(T1, x1), _transform_points(T2, x2)))
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


def fundamental_ransac(x1: ArrayLike, x2: ArrayLike, *, rng: np.random.Generator, threshold_px: float = 1.0,
                       confidence: float = 0.999, max_iter: int = 10000, refits: int = 5,
                       max_p_chance: float = 0.05) -> tuple:
    """Robust F: adaptive RANSAC on minimal 7-point samples, then the 8-point on the inliers (H&Z Alg. 11.4).

    Why 7-point samples: a sample of 7 instead of 8 needs fewer trials for the same confidence
    (``log(1 - p) / log(1 - w^s)``: 588 against 1177 at 50 % inliers and p = 0.99), and each candidate
    is exactly of rank 2, so its Sampson distances are meaningful; the up-to-3 real roots are all scored.
    A sample with a rank-deficient design matrix (e.g. 7 points on one plane) gives no candidate.
    After the loop the 8-point is fitted to the inliers, the inliers recomputed with it, and this is
    repeated (at most ``refits`` times) until the inlier set stops changing. The sampled F must be better than
    chance (:mod:`labutils.core.ransac`): the fraction ``p`` of 4096 unrelated pairs, spread evenly (a lattice)
    over the bounding boxes of x1 and of x2, within ``threshold_px`` of this F is the chance that an unrelated
    correspondence is its inlier; an inlier count that ``B(N - 7, p)`` reaches in the models tried with
    probability above ``max_p_chance`` is refused.

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
    max_p_chance : float
        Refuse an F whose inlier count unrelated pixels would reach with a probability above this.

    Returns
    -------
    FundamentalRansac
        The pair ``(F, inliers)`` — ``F`` (3, 3), rank 2, unit norm; ``inliers`` (N,) bool — with ``converged``
        (False: stopped at ``max_iter`` before reaching ``confidence``), ``p_chance`` and ``n_iter``.

    Raises
    ------
    ValueError
        Bad input as for :func:`fundamental_8point`, no ``rng``, coincident pixels, no motion (every
        ``|x2 - x1| <= threshold_px``), no non-degenerate sample, no F better than chance (e.g. pure noise),
        or degenerate inliers (the final 8-point's checks).

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(60, 2, noise_px=0.5, outlier_ratio=0.2, rng=np.random.default_rng(0))
    >>> x1, x2, _ = s.pair(0, 1)
    >>> F, inl = fundamental_ransac(x1, x2, threshold_px=1.5, rng=np.random.default_rng(0))
    >>> F.shape, inl.shape == (len(x1),)
    ((3, 3), True)
    >>> r = fundamental_ransac(x1, x2, threshold_px=1.5, rng=np.random.default_rng(0))
    >>> bool(r.converged), bool(r.p_chance < 1e-6)
    (True, True)
    """
    x1, x2 = check_pair(x1, x2, 8)
    as_rng(rng)
    threshold_px = as_positive(threshold_px, "threshold_px")
    refits = as_count(refits, "refits", 0)
    for name, x in (("x1", x1), ("x2", x2)):
        if np.ptp(x, axis=0).max() <= threshold_px:
            raise ValueError(f"all pixels {name} coincide (within threshold_px = {threshold_px:g}): no F is determined")
    if np.abs(x2 - x1).max() <= threshold_px:
        raise ValueError(f"no motion: every |x2 - x1| <= threshold_px = {threshold_px:g}, so F is not determined")
    u = (np.arange(4096)[:, None] * (1597 ** np.arange(4) % 4096) % 4096 + 0.5) / 4096     # a 4D lattice
    r1, r2 = x1.min(0) + u[:, :2] * np.ptp(x1, axis=0), x2.min(0) + u[:, 2:] * np.ptp(x2, axis=0)
    chance = lambda F: (np.sum(_sampson(F, r1, r2) < threshold_px) + 1) / (len(u) + 2)  # noqa: E731
    search = ransac(len(x1), 7, lambda idx: _seven_point(x1[idx], x2[idx]), lambda F: _sampson(F, x1, x2),
                    threshold_px, rng=rng, confidence=confidence, max_iter=max_iter, chance=chance,
                    max_p_chance=max_p_chance)
    F, inliers = search.model, search.inliers
    tested = None
    for _ in range(refits):
        if inliers.sum() < 8:
            break
        F_new = fundamental_8point(x1[inliers], x2[inliers], degeneracy=None)   # raises if exactly degenerate
        tested = inliers
        new = sampson_distance(F_new, x1, x2) < threshold_px
        if new.sum() < 8:
            break
        F, changed, inliers = F_new, np.any(new != inliers), new
        if not changed:
            break
    if tested is not None and tested.sum() >= H_TEST_MIN_POINTS:
        _raise_if_degenerate(x1[tested], x2[tested])             # once, on the inliers of the last refit
    return FundamentalRansac(F, inliers, search)


class FundamentalRansac(tuple):
    """What :func:`fundamental_ransac` returns: the pair ``(F, inliers)`` (it unpacks as one), and the search's
    ``n_iter``, ``converged`` (the confidence was reached before ``max_iter``) and ``p_chance`` (the bound on the
    probability that unrelated pixels give an F this good in the models tried), as :class:`labutils.core.ransac.
    RansacResult` reports them."""

    def __new__(cls, F, inliers, search):
        self = super().__new__(cls, (F, inliers))
        self.n_iter, self.converged, self.p_chance = search.n_iter, search.converged, search.p_chance
        self.search = search
        return self

    F = property(lambda self: self[0])
    inliers = property(lambda self: self[1])


