"""From a calibrated pair to depth: rectify with the known cameras, choose the disparity range, turn disparities into
depth and 3D points, and choose the pairs of a ring of views.

A rectified pair (Fusiello, Trucco & Verri 2000; :func:`labutils.calibrate.rectify_fusiello`) is two
cameras ``K [R_rect R1 | R_rect t1]`` and the same shifted by the baseline ``b`` along its x axis. A point at depth
``Z`` (along the common optical axis) has disparity ``d = x1 - x2 = f b / Z`` (H&Z Sec. 11.12 and Fig. 9.3; Szeliski,
*Computer Vision*, 2nd ed., Sec. 12.1), so ``Z = f b / d`` and the left pixel ``(x, y)`` back-projects to
``X_rect = Z K⁻¹ (x, y, 1)`` — the same point the DLT triangulation of ``(x, y) ↔ (x - d, y)`` finds, in closed form.

Conventions: ``x_cam = R @ X + t`` (world to camera); pixel centres at integer coordinates; image size ``(w, h)``;
a :class:`DepthMap` holds the depth along the camera's z axis with NaN where unknown.
"""
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ...calibrate.rectification import Rectification, rectify_fusiello
from ...core.geometry import camera_center, relative_pose
from ...core.validation import (
    as_array,
    as_calibration,
    as_points,
    as_positive,
    as_rotation,
    as_rotations,
    as_translations,
    as_vector3,
)
from .disparity import disparity_plane_sweep, left_right_check

__all__ = ["RectifiedPair", "rectify_pair", "scale_intrinsics", "disparity_range", "depth_from_disparity",
           "DepthMap", "depth_map_from_disparity", "stereo_depth_map", "ring_pairs"]


def scale_intrinsics(K: ArrayLike, scale: float) -> np.ndarray:
    """K of the same camera after resizing its images by ``scale`` (pixel centres at integer coordinates).

    A pixel ``x`` of the original becomes ``scale · (x + ½) - ½``: pixel edges scale, centres follow
    (``cv2.resize`` with ``INTER_AREA`` by an integer factor averages exactly those pixels).

    >>> scale_intrinsics(np.array([[100.0, 0, 49.5], [0, 100, 39.5], [0, 0, 1]]), 0.5)[:2].tolist()
    [[50.0, 0.0, 24.5], [0.0, 50.0, 19.5]]
    """
    K = as_calibration(K)
    s = as_positive(scale, "scale")
    return np.array([[s, 0.0, (s - 1) / 2], [0.0, s, (s - 1) / 2], [0.0, 0.0, 1.0]]) @ K


def _as_colour_image(image, name):
    try:
        a = np.asarray(image)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an (h, w) or (h, w, 3) uint8 image (an array)") from None
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)) or a.dtype != np.uint8 or min(a.shape[:2]) < 2:
        raise ValueError(f"{name} must be an (h, w) or (h, w, 3) uint8 image; got shape {a.shape} and dtype {a.dtype}")
    return a


@dataclass
class RectifiedPair:
    """Two views warped so that matches lie on the same row, and the cameras that took the warped images.

    Attributes
    ----------
    image1, image2 : (h, w, 3) or (h, w) uint8 ndarray
        The rectified images (black where nothing of the original falls).
    K : (3, 3) ndarray
        The common calibration of both rectified cameras (``rect.K_new``): no skew, ``fx = fy = f``.
    R, t : (3, 3), (3,) ndarray
        Rectified camera 1 in the world: ``x_rect = R @ X + t``. Rectified camera 2 is ``(R, t - (b, 0, 0))``.
    baseline : float
        ``b = |C2 - C1|``, world units: ``d = f b / Z``.
    rect : Rectification
        The homographies (of the possibly resized originals) and the rectified cameras in camera 1's frame.
    views : tuple of int, optional
        Which views of a data set these are.
    """

    image1: np.ndarray = field(repr=False)
    image2: np.ndarray = field(repr=False)
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    baseline: float
    rect: Rectification = field(repr=False)
    views: tuple = None

    @property
    def f(self):
        return float(self.K[0, 0])

    @property
    def P1(self):
        """(3, 4): rectified camera 1 in the world, ``K [R | t]``."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def P2(self):
        """(3, 4): rectified camera 2 in the world, ``K [R | t - (b, 0, 0)]``."""
        return self.K @ np.hstack([self.R, (self.t - [self.baseline, 0.0, 0.0])[:, None]])


def rectify_pair(image1: ArrayLike, image2: ArrayLike, K1: ArrayLike, R1: ArrayLike, t1: ArrayLike, K2: ArrayLike,
                 R2: ArrayLike, t2: ArrayLike, *, scale: float = 1.0, views: tuple | None = None) -> RectifiedPair:
    """Rectify two views of known cameras (world poses ``x_cam = R @ X + t``), optionally at a reduced size.

    The images are first resized by ``scale`` (``cv2.resize``, area averaging; K by :func:`scale_intrinsics`), then
    warped by Fusiello's homographies (:func:`labutils.calibrate.rectify_fusiello`) into images of the
    same size, both taken by ``K_new`` turned to ``R_rect``.

    Parameters
    ----------
    image1, image2 : (h, w, 3) or (h, w) uint8 array_like
    K1, R1, t1, K2, R2, t2 : the two cameras (distortion-free)
    scale : float
        Resize factor, ``0 < scale <= 1``.
    views : tuple of int, optional
        Stored in the result.

    Returns
    -------
    RectifiedPair

    Examples
    --------
    >>> from labutils.core.synthetic import look_at
    >>> K = np.array([[200.0, 0, 79.5], [0, 200, 59.5], [0, 0, 1]])
    >>> (R1, t1), (R2, t2) = look_at([0.2, -3, 0], [0, 0, 0]), look_at([-0.2, -3, 0.05], [0, 0, 0])
    >>> img = np.zeros((120, 160, 3), np.uint8)
    >>> pair = rectify_pair(img, img, K, R1, t1, K, R2, t2)
    >>> X = np.array([[0.1, 0.2, 0.3], [-0.2, 0.1, -0.1]])
    >>> x1 = (X @ pair.P1[:, :3].T + pair.P1[:, 3]); x2 = (X @ pair.P2[:, :3].T + pair.P2[:, 3])
    >>> np.allclose(x1[:, 1] / x1[:, 2], x2[:, 1] / x2[:, 2]), round(pair.baseline, 4)
    (True, 0.4031)
    """
    image1, image2 = _as_colour_image(image1, "image1"), _as_colour_image(image2, "image2")
    if image1.shape != image2.shape:
        raise ValueError(f"image1 and image2 must have the same size; got {image1.shape} and {image2.shape}")
    K1, K2 = as_calibration(K1, "K1"), as_calibration(K2, "K2")
    R1, R2 = as_rotation(R1, "R1"), as_rotation(R2, "R2")
    t1, t2 = as_vector3(t1, "t1"), as_vector3(t2, "t2")
    s = as_positive(scale, "scale")
    if s > 1:
        raise ValueError(f"scale must be in (0, 1] (reduce, never enlarge); got {scale!r}")
    if s != 1:
        h, w = image1.shape[:2]
        size = (max(2, int(round(w * s))), max(2, int(round(h * s))))
        image1 = cv2.resize(image1, size, interpolation=cv2.INTER_AREA)
        image2 = cv2.resize(image2, size, interpolation=cv2.INTER_AREA)
        K1, K2 = scale_intrinsics(K1, s), scale_intrinsics(K2, s)
    R, t = relative_pose(R1, t1, R2, t2)
    size = (image1.shape[1], image1.shape[0])
    rect = rectify_fusiello(K1, K2, R, t, size)
    # the cameras are distortion-free, so the warp is the homography itself (bilinear, black outside the image).
    # rectification.rectify_image would do the same through its undistortion maps, but those drop K's skew (the
    # dinosaur's K has some): warpPerspective takes H as it is.
    flags = cv2.INTER_LINEAR
    out1 = cv2.warpPerspective(image1, rect.H1, size, flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    out2 = cv2.warpPerspective(image2, rect.H2, size, flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return RectifiedPair(out1, out2, rect.K_new.copy(), rect.R_rect @ R1, rect.R_rect @ t1, rect.baseline, rect,
                         None if views is None else tuple(int(v) for v in views))


def disparity_range(pair: RectifiedPair, X: ArrayLike, margin_px: int = 2) -> tuple[int, int]:
    """The integer disparities that world points ``X`` (a box's corners, sparse points) span in a rectified pair.

    ``d = f b / Z`` with ``Z`` each point's depth in rectified camera 1, widened by ``margin_px`` on each side.

    Raises
    ------
    ValueError
        If a point is not in front of the cameras (``Z <= 0``).

    Examples
    --------
    >>> from labutils.core.synthetic import look_at
    >>> K = np.array([[200.0, 0, 79.5], [0, 200, 59.5], [0, 0, 1]]); img = np.zeros((120, 160), np.uint8)
    >>> (R1, t1), (R2, t2) = look_at([0.2, -3, 0], [0, 0, 0]), look_at([-0.2, -3, 0], [0, 0, 0])
    >>> disparity_range(rectify_pair(img, img, K, R1, t1, K, R2, t2), [[0, -0.5, 0], [0, 0.5, 0]])
    (20, 35)
    """
    if not isinstance(pair, RectifiedPair):
        raise ValueError(f"pair must be a RectifiedPair (from rectify_pair); got {type(pair).__name__}")
    X = as_points(X, "X", dim=3)
    if isinstance(margin_px, bool) or not isinstance(margin_px, (int, np.integer)) or margin_px < 0:
        raise ValueError(f"margin_px must be a non-negative integer; got {margin_px!r}")
    Z = X @ pair.R[2] + pair.t[2]
    if np.any(Z <= 0):
        raise ValueError(f"X has {int(np.sum(Z <= 0))} points behind rectified camera 1: they have no disparity")
    d = pair.f * pair.baseline / Z
    return int(np.floor(d.min())) - int(margin_px), int(np.ceil(d.max())) + int(margin_px)


def depth_from_disparity(disparity: ArrayLike, f: float, baseline: float) -> np.ndarray:
    """Depth ``Z = f b / d`` of a rectified pair's disparities (NaN stays NaN).

    Parameters
    ----------
    disparity : array_like
        Disparities ``x1 - x2`` in pixels, NaN where unknown.
    f : float
        The rectified cameras' focal length, pixels.
    baseline : float
        ``|C2 - C1|``, world units.

    Raises
    ------
    ValueError
        If a finite disparity is ``<= 0`` (a point at infinity or behind the cameras) or infinite.

    Examples
    --------
    >>> depth_from_disparity([[100.0, np.nan, 50.0]], 500.0, 0.1).tolist()
    [[0.5, nan, 1.0]]
    """
    f = as_positive(f, "f")
    baseline = as_positive(baseline, "baseline")
    try:
        d = np.asarray(disparity, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("disparity must be a numeric array (NaN where unknown)") from None
    if np.isinf(d).any():
        raise ValueError("disparity has infinite values: mark an unknown disparity with NaN")
    if np.any(d[np.isfinite(d)] <= 0):
        raise ValueError("disparity has values <= 0: in a rectified pair with d = x1 - x2 every point in front of the "
                         "cameras has d > 0 (is the pair the right way round?)")
    with np.errstate(invalid="ignore"):
        return f * baseline / d


@dataclass
class DepthMap:
    """A depth map and the camera whose pixels it is on.

    Attributes
    ----------
    depth : (h, w) ndarray
        Depth along the camera's z axis (world units), NaN where unknown.
    K, R, t : the camera, ``x ~ K (R X + t)``
    colors : (h, w, 3) uint8 ndarray, optional
        The image seen by the camera (to colour the points).
    """

    depth: np.ndarray = field(repr=False)
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    colors: np.ndarray = field(default=None, repr=False)

    @property
    def shape(self):
        return self.depth.shape

    @property
    def n_valid(self):
        return int(np.isfinite(self.depth).sum())

    @property
    def P(self):
        return self.K @ np.hstack([self.R, self.t[:, None]])

    def pixels(self) -> np.ndarray:
        """(N, 2) pixels ``(x, y)`` with a depth, row by row."""
        ys, xs = np.nonzero(np.isfinite(self.depth))
        return np.stack([xs, ys], axis=1).astype(float)

    def points(self) -> np.ndarray:
        """(N, 3) world points of the pixels with a depth (row by row): ``X = Rᵀ (Z K⁻¹ (x, y, 1) - t)``."""
        ys, xs = np.nonzero(np.isfinite(self.depth))
        Z = self.depth[ys, xs]
        rays = np.stack([xs, ys, np.ones(len(xs))], axis=1) @ np.linalg.inv(self.K).T
        return (rays * Z[:, None] - self.t) @ self.R

    def point_colors(self) -> np.ndarray:
        """(N, 3) uint8 colours of the pixels with a depth (row by row), or None without ``colors``."""
        if self.colors is None:
            return None
        c = self.colors if self.colors.ndim == 3 else np.repeat(self.colors[..., None], 3, axis=2)
        return c[np.isfinite(self.depth)]


def depth_map_from_disparity(disparity: ArrayLike, pair: RectifiedPair) -> DepthMap:
    """The depth map of rectified camera 1 from its (left-referenced) disparity map, coloured by its image.

    Examples
    --------
    >>> from labutils.core.synthetic import look_at
    >>> K = np.array([[200.0, 0, 79.5], [0, 200, 59.5], [0, 0, 1]]); img = np.zeros((120, 160, 3), np.uint8)
    >>> (R1, t1), (R2, t2) = look_at([0.2, -3, 0], [0, 0, 0]), look_at([-0.2, -3, 0], [0, 0, 0])
    >>> pair = rectify_pair(img, img, K, R1, t1, K, R2, t2)
    >>> x = pair.P1 @ [0.1, 0.2, 0.3, 1.0]; y, x1 = x[1] / x[2], x[0] / x[2]   # a world point seen at (x1, y) ...
    >>> d = np.full((120, 160), np.nan); d[int(round(y)), int(round(x1))] = pair.f * pair.baseline / x[2]
    >>> dm = depth_map_from_disparity(d, pair)
    >>> bool(np.linalg.norm(dm.points()[0] - [0.1, 0.2, 0.3]) < 0.01)            # ... comes back (to a pixel)
    True
    """
    if not isinstance(pair, RectifiedPair):
        raise ValueError(f"pair must be a RectifiedPair (from rectify_pair); got {type(pair).__name__}")
    try:
        d = as_array(disparity, "disparity", "(h, w)")
    except (TypeError, ValueError):
        d = None
    if d is None or d.shape != pair.image1.shape[:2]:
        got = "a ragged or non-numeric input" if d is None else f"shape {d.shape}"
        raise ValueError(f"disparity must be an (h, w) map of the pair's size {pair.image1.shape[:2]}; got {got}")
    Z = depth_from_disparity(d, pair.f, pair.baseline)
    return DepthMap(Z, pair.K.copy(), pair.R.copy(), pair.t.copy(), pair.image1)


def stereo_depth_map(pair: RectifiedPair, d_min: int, d_max: int, *, window: int = 9, min_zncc: float = 0.5,
                     min_std: float = 2.0, threshold_px: float = 1.0) -> DepthMap:
    """The whole two-view step: plane sweep from both sides, left–right check, depth of what survives.

    Parameters are those of :func:`labutils.model.disparity_plane_sweep` and
    :func:`labutils.model.left_right_check`.

    Returns
    -------
    DepthMap
        Rectified camera 1's depth, NaN where the sweep found nothing or the check failed.
    """
    if not isinstance(pair, RectifiedPair):
        raise ValueError(f"pair must be a RectifiedPair (from rectify_pair); got {type(pair).__name__}")
    kw = dict(window=window, min_zncc=min_zncc, min_std=min_std)
    d_left = disparity_plane_sweep(pair.image1, pair.image2, d_min, d_max, **kw)
    d_right = disparity_plane_sweep(pair.image1, pair.image2, d_min, d_max, reference="right", **kw)
    d_left[~left_right_check(d_left, d_right, threshold_px)] = np.nan
    return depth_map_from_disparity(d_left, pair)


def ring_pairs(R: ArrayLike, t: ArrayLike, target: ArrayLike, *, min_angle_deg: float = 4.0,
               max_angle_deg: float = 15.0) -> np.ndarray:
    """For each view, its partner for stereo: the other view closest in angle (seen from ``target``) within a range.

    Too small an angle gives a short baseline and poor depth; too large, matching fails (appearance changes,
    occlusions grow). Views without a partner in ``[min_angle_deg, max_angle_deg]`` are left out.

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    target : (3,) array_like
        A point on the object (e.g. its box's centre).

    Returns
    -------
    (n, 2) int ndarray
        Pairs ``(i, j)``, one per view ``i`` that has a partner.

    Examples
    --------
    >>> from labutils.core.synthetic import look_at
    >>> Rt = [look_at([np.cos(a), np.sin(a), 0.2], [0, 0, 0]) for a in np.deg2rad([0, 10, 22, 90])]
    >>> ring_pairs([r for r, _ in Rt], [t for _, t in Rt], [0, 0, 0]).tolist()
    [[0, 1], [1, 0], [2, 1]]
    """
    R = as_rotations(R, "R")
    t = as_translations(t, "t", n=len(R), like_name="R")
    target = as_vector3(target, "target")
    lo = as_positive(min_angle_deg, "min_angle_deg", allow_zero=True)
    hi = as_positive(max_angle_deg, "max_angle_deg")
    if hi <= lo:
        raise ValueError(f"max_angle_deg must exceed min_angle_deg; got {min_angle_deg!r} and {max_angle_deg!r}")
    C = camera_center(R, t)
    u = C - target
    norms = np.linalg.norm(u, axis=1)
    if np.any(norms <= 0):
        raise ValueError("target coincides with a camera centre")
    u /= norms[:, None]
    ang = np.degrees(np.arccos(np.clip(u @ u.T, -1.0, 1.0)))
    ang[(ang < lo) | (ang > hi)] = np.inf
    np.fill_diagonal(ang, np.inf)
    pairs = [(i, int(np.argmin(a))) for i, a in enumerate(ang) if np.isfinite(a.min())]
    return np.array(pairs, dtype=int).reshape(-1, 2)
