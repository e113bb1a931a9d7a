"""The epipolar filter: our robust F; with known K, the relative pose refined on the inliers and a cheirality test."""
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..core.geometry import rotation_from_angle_axis, skew
from ..core.validation import as_array, as_matrix, as_points
from ..twoview.epipolar import fundamental_8point, sampson_distance
from ..twoview.essential import decompose_essential, essential_from_fundamental, fundamental_from_pose
from ..twoview.seven_point import fundamental_ransac

# ---------------------------------------------------------------------------------------------
# The epipolar filter
# ---------------------------------------------------------------------------------------------

@dataclass
class PairGeometry:
    """What :func:`epipolar_filter` found for one pair of views.

    Attributes
    ----------
    F : (3, 3) ndarray
        The fundamental matrix the inliers were judged by (from E when K was given).
    inliers : (N,) bool ndarray
    n_ransac : int
        Inliers of the F RANSAC (before the calibrated refinement, if any).
    R, t : (3, 3), (3,) ndarray or None
        The relative pose (camera 1 ``[I | 0]``, ``|t| = 1``) when K was given.
    n_behind : int
        Matches rejected because their 3D point lies behind a camera (0 without K).
    pose_reliable : bool
        False when more than ``MAX_BEHIND`` of the inliers were behind a camera even for the best of the
        four poses: then the two-view pose is ambiguous (nearly affine views) and no match was rejected for it.
    """

    F: np.ndarray
    inliers: np.ndarray
    n_ransac: int
    R: np.ndarray = None
    t: np.ndarray = None
    n_behind: int = 0
    pose_reliable: bool = True


MAX_BEHIND = 0.05
"""Largest fraction of epipolar inliers the cheirality test may reject in one pair. Wrong matches that pass the
Sampson test are a few per cent; when more are behind a camera, the pose is what is wrong."""


def _signed_sampson(F, x1_h, x2_h):
    Fx1 = x1_h @ F.T
    Ftx2 = x2_h @ F
    num = np.einsum("ni,ni->n", x2_h, Fx1)
    den = np.sqrt(Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2)
    return num / np.maximum(den, 1e-300)


def _tangent_basis(t):
    helper = np.array([1.0, 0.0, 0.0]) if abs(t[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b1 = np.cross(t, helper)
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(t, b1)


def _refine_Rt(K1, K2, R, t, x1, x2):
    """Least-squares (R, t) minimising the Sampson distances of ``x1, x2`` (5 parameters)."""
    import scipy.optimize

    x1_h, x2_h = np.hstack([x1, np.ones((len(x1), 1))]), np.hstack([x2, np.ones((len(x2), 1))])
    K1i, K2it = np.linalg.inv(K1), np.linalg.inv(K2).T
    b1, b2 = _tangent_basis(t)

    def pose(p):
        Rn = rotation_from_angle_axis(p[:3]) @ R
        tn = t + p[3] * b1 + p[4] * b2
        return Rn, tn / np.linalg.norm(tn)

    def residuals(p):
        Rn, tn = pose(p)
        return _signed_sampson(K2it @ skew(tn) @ Rn @ K1i, x1_h, x2_h)

    sol = scipy.optimize.least_squares(residuals, np.zeros(5), method="lm", x_scale=1e-3)
    return pose(sol.x)


def _in_front(K1, K2, R, t, x1, x2):
    """Depth of the midpoint triangulation in both cameras > 0 (the rays meet in front)."""
    r1 = np.hstack([x1, np.ones((len(x1), 1))]) @ np.linalg.inv(K1).T           # rays in camera 1
    r2 = (np.hstack([x2, np.ones((len(x2), 1))]) @ np.linalg.inv(K2).T) @ R     # camera-2 rays, camera-1 frame
    C2 = -R.T @ t
    # depths a, b with a r1 - b r2 = C2 in the least-squares sense (2x2 normal equations per match)
    A11, A12, A22 = (r1 * r1).sum(1), -(r1 * r2).sum(1), (r2 * r2).sum(1)
    b1, b2 = r1 @ C2, -(r2 @ C2)
    det = A11 * A22 - A12 ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (A22 * b1 - A12 * b2) / det
        b = (A11 * b2 - A12 * b1) / det
    return (a > 0) & (b > 0)


def _robust_fundamental(x1, x2, rng, threshold_px, confidence, max_iter, ranking, refits=5):
    """F and its inliers: RANSAC on all matches, or on the best-ranked third and then re-fitted on all."""
    if ranking is None or len(x1) < 40:
        return fundamental_ransac(x1, x2, threshold_px=threshold_px, rng=rng, confidence=confidence, max_iter=max_iter)
    best = np.argsort(ranking, kind="stable")[:max(30, len(x1) // 3)]
    F, _ = fundamental_ransac(x1[best], x2[best], threshold_px=threshold_px, rng=rng, confidence=confidence,
                              max_iter=max_iter)
    inl = sampson_distance(F, x1, x2) < threshold_px
    for _ in range(refits):
        if inl.sum() < 8:
            break
        F_new = fundamental_8point(x1[inl], x2[inl])        # raises if the inliers are degenerate
        new = sampson_distance(F_new, x1, x2) < threshold_px
        if new.sum() < 8:
            break
        F, changed, inl = F_new, np.any(new != inl), new
        if not changed:
            break
    return F, inl


def epipolar_filter(x1: ArrayLike, x2: ArrayLike, *, rng: np.random.Generator, threshold_px: float = 1.0,
                    K1: ArrayLike | None = None, K2: ArrayLike | None = None, ranking: ArrayLike | None = None,
                    confidence: float = 0.999, max_iter: int = 400, refine_rounds: int = 3) -> PairGeometry:
    """Remove the matches that contradict the epipolar geometry of the pair.

    1. F by adaptive RANSAC on 7-point samples with the Sampson distance
       (:func:`labutils.twoview.fundamental_ransac`, H&Z Alg. 11.4): inliers are within ``threshold_px``.
       With a ``ranking`` (e.g. the ratio ``d1 / d2`` of each match), RANSAC samples only the most
       distinctive third of the matches, where wrong matches are rarer (the idea of PROSAC, Chum &
       Matas, CVPR 2005), then every match is judged by that F and F is re-fitted on all the inliers.
       The trials needed grow like ``1 / w⁷`` with the inlier ratio w: at w = 0.45 a 0.999-sure
       sample takes 19,000 trials, at 0.65 only 1,400.
    2. With K1 and K2: ``E = K2ᵀ F K1`` (H&Z eq. 9.12) has four poses (H&Z Result 9.19); each is refined on
       the inliers by least squares on the Sampson distances of ``F(R, t) = K2⁻ᵀ [t]× R K1⁻¹`` (5 parameters:
       the calibrated model is stiffer than a free F with 7) and the one with the most points in front of
       both cameras wins (cheirality, H&Z Sec. 9.6.3). Refining all four matters when the views are nearly
       affine (a narrow field of view): there E from F can be degrees off, and a pose with every point
       behind the cameras may fit the matches slightly better than the right one. The inliers are then
       recomputed, ``refine_rounds`` times at most. A match whose rays meet behind either camera is rejected
       too — no F can tell, E can — unless more than ``MAX_BEHIND`` of them are (see ``pose_reliable``).

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Matched pixels, N >= 8.
    rng : numpy.random.Generator
    threshold_px : float
        Inlier threshold on the Sampson distance (pixels of the images x1, x2 are in).
    K1, K2 : (3, 3) array_like, optional
        Calibrations (both or neither).
    ranking : (N,) array_like, optional
        Lower is more distinctive; used for guided sampling when N >= 40.
    confidence : float
        RANSAC confidence.
    max_iter : int
        RANSAC trials at most. With guided sampling a real pair's best third is rarely below 60 % inliers, and
        400 trials find a clean sample of 7 at 60 % with probability 1 - (1 - 0.6⁷)⁴⁰⁰ > 0.9999; pairs that
        need more are mostly views that do not overlap, and each costs a few tenths of a second.
    refine_rounds : int
        Rounds of the calibrated refinement.

    Returns
    -------
    PairGeometry

    Raises
    ------
    ValueError
        Bad input (shapes, N < 8, no rng, one K only), or degenerate matches (a homography explains
        them: one plane, or no baseline; see :func:`labutils.twoview.fundamental_8point`).

    Examples
    --------
    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(80, 2, noise_px=0.3, outlier_ratio=0.25, rng=np.random.default_rng(0))
    >>> x1, x2, idx = s.pair(0, 1)
    >>> correct = ~(s.outliers[0, idx] | s.outliers[1, idx])          # 43 of the 80 matches
    >>> g = epipolar_filter(x1, x2, rng=np.random.default_rng(1), threshold_px=1.5, K1=s.K, K2=s.K)
    >>> bool(np.array_equal(g.inliers, correct)), g.n_ransac
    (True, 43)
    """
    x1 = as_points(x1, "x1", min_n=8)
    x2 = as_points(x2, "x2", min_n=8, like=x1)
    if (K1 is None) != (K2 is None):
        raise ValueError("give both K1 and K2 (calibrated filter) or neither (F only)")
    if not threshold_px > 0:
        raise ValueError(f"threshold_px must be positive; got {threshold_px}")
    if ranking is not None:
        ranking = as_array(ranking, "ranking", f"({len(x1)},)")
        if ranking.shape != (len(x1),):
            raise ValueError(f"ranking must have one value per match ({len(x1)}); got shape {ranking.shape}")
    F, inl = _robust_fundamental(x1, x2, rng, threshold_px, confidence, max_iter, ranking)
    n_ransac = int(inl.sum())
    if K1 is None:
        return PairGeometry(F=F, inliers=inl, n_ransac=n_ransac)
    K1, K2 = as_matrix(K1, "K1", (3, 3)), as_matrix(K2, "K2", (3, 3))
    E = essential_from_fundamental(F, K1, K2)
    # E from a free F can be far off (near-affine views: the dinosaur); refine each of its four poses and keep the
    # one with the most points in front (ties: the lowest cost). The four start in different basins.
    best_key, R, t = None, None, None
    for R0, t0 in decompose_essential(E):
        Rr, tr = _refine_Rt(K1, K2, R0, t0, x1[inl], x2[inl])
        cost = float(np.sum(sampson_distance(fundamental_from_pose(K1, K2, Rr, tr), x1[inl], x2[inl]) ** 2))
        key = (int(_in_front(K1, K2, Rr, tr, x1[inl], x2[inl]).sum()), -cost)
        if best_key is None or key > best_key:
            best_key, R, t = key, Rr, tr
    for _ in range(refine_rounds):
        F = fundamental_from_pose(K1, K2, R, t)
        new = sampson_distance(F, x1, x2) < threshold_px
        if new.sum() < 8 or not np.any(new != inl):
            break
        inl = new
        R, t = _refine_Rt(K1, K2, R, t, x1[inl], x2[inl])
    F = fundamental_from_pose(K1, K2, R, t)
    inl = sampson_distance(F, x1, x2) < threshold_px
    # the four poses of this E fit equally well: take the one with the most inliers in front (the refinement
    # may have crossed to another of them)
    front_best = -1
    for Rc, tc in decompose_essential(skew(t) @ R):
        front_c = _in_front(K1, K2, Rc, tc, x1, x2)
        if (front_c & inl).sum() > front_best:
            R, t, front, front_best = Rc, tc, front_c, (front_c & inl).sum()
    behind = inl & ~front
    if behind.sum() > MAX_BEHIND * inl.sum():      # the pose is ambiguous, not the matches wrong: no cheirality test
        return PairGeometry(F=F, inliers=inl, n_ransac=n_ransac, R=R, t=t, n_behind=0, pose_reliable=False)
    return PairGeometry(F=F, inliers=inl & front, n_ransac=n_ransac, R=R, t=t, n_behind=int(behind.sum()))
