"""Two views, calibrated: the relative pose and the points, as the first step of structure from motion
(notebooks 02 and 05; H&Z Sec. 9.6, 11.6, 12.2, 18.1)."""
import numpy as np
from numpy.typing import ArrayLike

from ..bundle.adjust import bundle_adjust
from ..core.geometry import camera_center
from ..core.validation import as_calibration, as_points, as_rng
from ..twoview.essential import check_parallax, essential_from_fundamental, pose_from_essential
from ..twoview.seven_point import fundamental_ransac
from ..twoview.triangulation import ray_angles_deg, triangulate_tracks


def two_view_reconstruction(x1: ArrayLike, x2: ArrayLike, K1: ArrayLike, K2: ArrayLike, *, rng: np.random.Generator,
                            threshold_px: float = 4.0, confidence: float = 0.999, min_angle_deg: float = 1.0,
                            refine: bool = True, loss: str = "cauchy", f_scale: float = 1.0) -> tuple:
    """Relative pose and points from two views, as in the two-view notebooks (H&Z Sec. 9.6, 11.6, 12.2, 18.1).

    F by RANSAC (Sampson distance below ``threshold_px``), ``E = K2ᵀ F K1``, the pose of the four
    decompositions that puts the points in front of both cameras, then DLT triangulation. A point is kept
    when it is an F inlier, in front of both cameras, reprojects within ``threshold_px`` in both views and
    is seen under at least ``min_angle_deg``. With ``refine`` the pose and the points are then
    bundle-adjusted (camera 1 and the baseline length held) and every correspondence is triangulated
    again with the refined pose: F ignores the calibration, and from a narrow field of view (the
    dinosaur's) its translation direction can be off by tens of degrees, which the calibrated BA repairs.
    Refused (``ValueError``): F no better than chance (pure noise), coincident pixels, no motion, and inliers
    that a pure rotation explains as well as F (:func:`labutils.twoview.essential.check_parallax`: no baseline).

    Parameters
    ----------
    x1, x2 : (N, 2) array_like
        Corresponding pixels, N >= 8.
    K1, K2 : (3, 3) array_like
    rng : numpy.random.Generator
    refine : bool
    loss, f_scale : str, float
        Loss of the refinement (see :func:`labutils.bundle.bundle_adjust`).

    Returns
    -------
    R : (3, 3) ndarray
    t : (3,) ndarray
        Camera 2 ``[R | t]`` with camera 1 ``[I | 0]`` and ``‖t‖ = 1``.
    X : (N, 3) ndarray
        NaN for the rejected correspondences.
    median_angle : float
        Median triangulation angle (degrees) of the kept points (0 when none is kept).
    """
    x1 = as_points(x1, "x1", min_n=8)
    x2 = as_points(x2, "x2", min_n=8, like=(x1, "x1"))
    K1, K2 = as_calibration(K1, "K1"), as_calibration(K2, "K2")
    as_rng(rng)
    F, inl = fundamental_ransac(x1, x2, threshold_px=threshold_px, rng=rng, confidence=confidence)
    inl = np.asarray(inl, bool)
    check_parallax(F, x1[inl], x2[inl], K1, K2)        # a pure rotation explains them as well: no baseline
    E = essential_from_fundamental(F, K1, K2)
    R, t = pose_from_essential(E, x1[inl], x2[inl], K1, K2)
    Ks = np.stack([K1, K2])
    Rs, ts = np.stack([np.eye(3), R]), np.stack([np.zeros(3), np.asarray(t, float).reshape(3)])
    xs = np.stack([x1, x2])
    mask = np.tile(inl, (2, 1))
    # E is F projected onto the essential matrices: when F is poorly conditioned the pose is rough and the
    # reprojection errors large, so before the refinement a point only has to be in front of both cameras
    X, used = triangulate_tracks(xs, Ks, Rs, ts, [0, 1], mask, threshold_px=np.inf if refine else threshold_px,
                                 min_angle_deg=min_angle_deg)
    ok = np.isfinite(X[:, 0])
    if refine and ok.sum() >= 8:
        ci, pi = np.nonzero(used[:, ok])
        res = bundle_adjust(Rs, ts, X[ok], ci, pi, xs[ci, np.flatnonzero(ok)[pi]], Ks, loss=loss, f_scale=f_scale,
                            fixed_cameras=[0], max_iter=30, tol=1e-6)     # a repair, not the last word
        s = np.linalg.norm(res.t[1])                              # keep ‖t‖ = 1 exactly
        Rs, ts = np.stack([np.eye(3), res.R[1]]), np.stack([np.zeros(3), res.t[1] / s])
        X, used = triangulate_tracks(xs, Ks, Rs, ts, [0, 1], np.ones_like(mask), threshold_px=threshold_px,
                                     min_angle_deg=min_angle_deg)
        ok = np.isfinite(X[:, 0])
    angle = ray_angles_deg(camera_center(Rs, ts), np.where(ok[:, None], X, 0), used)
    return Rs[1], ts[1], X, float(np.median(angle[ok])) if ok.any() else 0.0


