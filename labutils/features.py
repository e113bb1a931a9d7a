"""Correspondences from images: features, matching, epipolar filtering, tracks and the choice of pairs.

The pipeline, one function per step:

1. **Detect and describe** (:func:`detect_features`): OpenCV's SIFT (Lowe, IJCV 2004) on a grey image,
   optionally reduced first (:func:`read_gray`); the pixels of a reduced image map back to the original
   with :func:`to_original_pixels`, and K follows with :func:`scale_calibration`.
2. **Nearest neighbours** (:func:`nearest_neighbours`): the two closest descriptors in the other image, by
   brute force (a matrix product, in chunks).
3. **Ratio test** (:func:`ratio_test`, Lowe 2004 Sec. 7.1): keep a match only if its nearest neighbour is
   clearly closer than the second nearest, ``d1 < ratio · d2``.
4. **Mutual (cross) check** (:func:`mutual_check`): keep ``i -> j`` only if ``i`` is also the nearest
   neighbour of ``j`` in the first image.
5. **Epipolar filter** (:func:`epipolar_filter`): a robust F from our RANSAC
   (:func:`labutils.epipolar.fundamental_ransac`, Sampson distance, H&Z Alg. 11.4); with known K, E and
   the relative pose are refined on the inliers (5 parameters instead of 7, H&Z Sec. 9.6) and matches
   whose 3D point would lie behind a camera are rejected too (cheirality).
6. **Tracks** (:func:`build_tracks`): pairwise matches chained across views with union-find; a track
   that holds two different features of one view is contradictory and is rejected.
   :func:`verify_tracks` also checks each track against the epipolar geometry of every pair of its views,
   including the pairs it only reaches through a third view.
7. **Which pairs** (:func:`select_pairs`, :func:`retrieval_pairs`): all pairs for a few views, neighbours in
   a sequence or on a ring, or a shortlist from a bag of visual words.

:func:`match_views` runs steps 2-5 over a list of pairs and keeps a table of the survivors of each
stage; :func:`tracks_from_matches` runs step 6. ``python -m labutils.match`` (:mod:`labutils.match`) runs
everything on a folder of images.

Pixel convention: OpenCV puts pixel centres at integer coordinates, so reducing an image by ``s`` maps
a pixel ``x`` of the original to ``s (x + 0.5) - 0.5``, not to ``s x`` (half a pixel apart).
"""
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_matrix, as_points
from .epipolar import (
    decompose_essential,
    essential_from_fundamental,
    fundamental_8point,
    fundamental_from_pose,
    fundamental_ransac,
    sampson_distance,
)
from .geometry import rotation_from_angle_axis, skew

__all__ = ["Features", "read_gray", "resize_gray", "scale_calibration", "to_original_pixels", "to_working_pixels",
           "detect_features", "nearest_neighbours", "ratio_test", "mutual_check", "match_descriptors",
           "PairGeometry", "epipolar_filter", "UnionFind", "build_tracks",
           "track_pixels", "verify_tracks", "select_pairs", "retrieval_pairs", "MatchResult", "match_views",
           "TrackResult", "tracks_from_matches", "track_statistics", "IMAGE_SUFFIXES"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
"""The image files :func:`labutils.match` reads (case-insensitive)."""


# ---------------------------------------------------------------------------------------------
# Images and pixel scales
# ---------------------------------------------------------------------------------------------

def scale_calibration(K: ArrayLike, scale: float) -> np.ndarray:
    """The calibration of an image reduced (or enlarged) by ``scale``, with OpenCV's pixel centres.

    A pixel ``x`` of the original lands at ``s (x + 0.5) - 0.5`` in the scaled image, so
    ``K_s = [[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1]] @ K``. Scaling K by ``diag(s, s, 1)``
    alone moves the principal point by half a pixel of the original image (``(1 - s) / 2`` pixels of
    the reduced one): small, but it costs accuracy (notebook 07 measures it).

    Parameters
    ----------
    K : (3, 3) or (V, 3, 3) array_like
    scale : float
        New size / original size.

    Returns
    -------
    K_s : ndarray, the shape of ``K``

    Examples
    --------
    >>> scale_calibration(np.diag([1000.0, 1000.0, 1.0]), 0.5)
    array([[ 5.0e+02,  0.0e+00, -2.5e-01],
           [ 0.0e+00,  5.0e+02, -2.5e-01],
           [ 0.0e+00,  0.0e+00,  1.0e+00]])
    """
    K = np.asarray(K, float)
    if K.shape[-2:] != (3, 3) or K.ndim not in (2, 3):
        raise ValueError(f"K must have shape (3, 3) or (V, 3, 3); got {K.shape}")
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale must be a positive number; got {scale}")
    S = np.array([[scale, 0.0, (scale - 1) / 2], [0.0, scale, (scale - 1) / 2], [0.0, 0.0, 1.0]])
    return S @ K


def _as_pixels(x, name):
    x = np.asarray(x, float)
    if x.ndim < 1 or x.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (..., 2) (pixels as rows, NaN allowed for unseen); got {x.shape}")
    return x


def to_original_pixels(x: ArrayLike, scale: float) -> np.ndarray:
    """Pixels of an image scaled by ``scale`` back to the original: ``(x + 0.5) / s - 0.5``.

    ``x`` has shape ``(..., 2)``; NaN (unseen) stays NaN.

    >>> to_original_pixels([[0.0, 1.5], [np.nan, np.nan]], 0.5)
    array([[0.5, 3.5],
           [nan, nan]])
    """
    return (_as_pixels(x, "x") + 0.5) / scale - 0.5


def to_working_pixels(x: ArrayLike, scale: float) -> np.ndarray:
    """Pixels of the original image in an image scaled by ``scale``: ``s (x + 0.5) - 0.5``.

    >>> to_working_pixels(to_original_pixels([[3.0, 7.0]], 0.25), 0.25)
    array([[3., 7.]])
    """
    return scale * (_as_pixels(x, "x") + 0.5) - 0.5


def resize_gray(image: ArrayLike, max_size: int | None = None) -> tuple[np.ndarray, float]:
    """A grey copy of ``image`` whose longer side is at most ``max_size``, and the scale used.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8 array_like
        Grey or RGB.
    max_size : int, optional
        Longest side in pixels; None keeps the size. Images are only ever reduced (area averaging).

    Returns
    -------
    gray : (h, w) uint8 ndarray
    scale : float
        ``h / H`` (the same for both axes: OpenCV's resize is given the factor, not the size).

    Examples
    --------
    >>> g, s = resize_gray(np.zeros((400, 600, 3), np.uint8), max_size=300)
    >>> g.shape, s
    ((200, 300), 0.5)
    """
    import cv2

    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img, dtype=np.uint8), cv2.COLOR_RGB2GRAY)
    elif img.ndim != 2:
        raise ValueError(f"image must have shape (H, W) or (H, W, 3); got {img.shape}")
    img = np.ascontiguousarray(img, dtype=np.uint8)
    if max_size is None or max(img.shape) <= max_size:
        return img, 1.0
    if max_size < 16:
        raise ValueError(f"max_size must be at least 16 pixels; got {max_size}")
    s = max_size / max(img.shape)
    return cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA), s


def read_gray(path: str | Path, max_size: int | None = None) -> tuple[np.ndarray, float, tuple[int, int]]:
    """Read an image file as grey, reduced so that its longer side is at most ``max_size``.

    JPEG files are decoded directly at 1/2, 1/4 or 1/8 of their size when that is still at least the
    target (libjpeg's scaled decoding, much faster than decoding the full image; it averages blocks,
    which keeps the pixel-centre convention of :func:`scale_calibration`), then area-averaged to the
    target.

    Parameters
    ----------
    path : str or Path
    max_size : int, optional

    Returns
    -------
    gray : (h, w) uint8 ndarray
    scale : float
        Size of ``gray`` / size of the original image.
    original_size : (width, height)

    Raises
    ------
    ValueError
        If the file cannot be read as an image (the message names the file).
    """
    import cv2

    path = Path(path)
    full = None
    reduce = 1
    if path.suffix.lower() in (".jpg", ".jpeg") and max_size is not None:
        header = cv2.imread(str(path), cv2.IMREAD_REDUCED_GRAYSCALE_8)
        if header is None:
            raise ValueError(f"{path}: cannot read the image (not a PNG/JPEG file, or damaged)")
        approx_long = 8 * max(header.shape)          # the full size to within 7 pixels
        for r, flag in ((8, cv2.IMREAD_REDUCED_GRAYSCALE_8), (4, cv2.IMREAD_REDUCED_GRAYSCALE_4),
                        (2, cv2.IMREAD_REDUCED_GRAYSCALE_2)):
            if approx_long / r >= max_size + 8:
                full = header if r == 8 else cv2.imread(str(path), flag)
                reduce = r
                break
    if full is None:
        full = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        reduce = 1
    if full is None:
        raise ValueError(f"{path}: cannot read the image (not a PNG/JPEG file, or damaged)")
    original = (full.shape[1] * reduce, full.shape[0] * reduce)
    if reduce > 1:        # the exact original size: the header, read cheaply
        original = _jpeg_size(path) or original
    target = None if max_size is None else max_size
    gray, s = resize_gray(full, target)
    return gray, s / reduce, original


def _jpeg_size(path):
    """(width, height) from a JPEG's SOF header, or None."""
    data = Path(path).read_bytes()
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            return None
        marker, length = data[i + 1], int.from_bytes(data[i + 2:i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            h, w = int.from_bytes(data[i + 5:i + 7], "big"), int.from_bytes(data[i + 7:i + 9], "big")
            return (w, h)
        i += 2 + length
    return None


# ---------------------------------------------------------------------------------------------
# Detection
# ---------------------------------------------------------------------------------------------

@dataclass
class Features:
    """Keypoints and descriptors of one image.

    Attributes
    ----------
    xy : (N, 2) ndarray
        Keypoint positions in the pixels of the image they were detected in (the *working* image).
    descriptors : (N, D) float32 ndarray
    scale : float
        Working image size / original image size (1 when detected at full size).
    image_size : (width, height)
        Of the working image.
    """

    xy: np.ndarray
    descriptors: np.ndarray
    scale: float = 1.0
    image_size: tuple = None

    def __len__(self):
        return len(self.xy)

    @property
    def xy_original(self):
        """(N, 2) keypoint positions in the pixels of the original image."""
        return to_original_pixels(self.xy, self.scale)


def detect_features(image: ArrayLike, *, scale: float = 1.0, n_features: int = 0, contrast_threshold: float = 0.04,
                    precise_upscale: bool = True) -> Features:
    """SIFT keypoints and descriptors of one image (OpenCV; Lowe, IJCV 2004).

    SIFT starts from the image enlarged twice. OpenCV's default enlargement is off by half a pixel of the
    enlarged image, which puts every keypoint a quarter pixel right of and below where it should be
    (``x + 0.25``, at every scale; a Gaussian blob drawn at a known position shows it). That is the same
    as a principal point a quarter pixel off: small, but not noise, since it never averages out.
    ``precise_upscale`` (OpenCV's ``enable_precise_upscale``) enlarges with the pixel centres kept.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8 array_like
        Grey or RGB, already at the working size.
    scale : float
        Working size / original size, recorded in the result (see :func:`read_gray`).
    n_features : int
        Keep at most this many (the strongest); 0 keeps all.
    contrast_threshold : float
        SIFT's threshold on the contrast of a keypoint (lower: more, weaker keypoints).
    precise_upscale : bool
        Enlarge the image with the pixel centres kept (False: OpenCV's default, a quarter pixel off).

    Returns
    -------
    Features

    Examples
    --------
    >>> f = detect_features(np.zeros((64, 64), np.uint8))          # a blank image has no keypoints
    >>> f.xy.shape, f.descriptors.shape
    ((0, 2), (0, 128))
    """
    import cv2

    gray, _ = resize_gray(image)
    sift = cv2.SIFT_create(nfeatures=int(n_features), contrastThreshold=float(contrast_threshold),
                           enable_precise_upscale=bool(precise_upscale))
    kps, desc = sift.detectAndCompute(gray, None)
    xy = np.array([k.pt for k in kps], float).reshape(-1, 2)
    desc = np.zeros((0, 128), np.float32) if desc is None else desc.astype(np.float32)
    return Features(xy=xy, descriptors=desc, scale=float(scale), image_size=(gray.shape[1], gray.shape[0]))


# ---------------------------------------------------------------------------------------------
# Matching: nearest neighbours, the ratio test, the mutual check
# ---------------------------------------------------------------------------------------------

def _as_descriptors(d, name):
    d = np.asarray(d)
    if d.ndim != 2:
        raise ValueError(f"{name} must have shape (N, D) (one descriptor per row); got shape {d.shape}")
    d = d.astype(np.float32, copy=False)
    if not np.all(np.isfinite(d)):
        raise ValueError(f"{name} has non-finite entries (NaN or inf)")
    return d


def nearest_neighbours(d1: ArrayLike, d2: ArrayLike, k: int = 2, chunk: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` (1 or 2) nearest descriptors of ``d2`` to each row of ``d1``, by Euclidean distance.

    Brute force: ``|a - b|² = |a|² + |b|² - 2 a·b`` for a chunk of rows at a time (one matrix product).

    Parameters
    ----------
    d1 : (N1, D) array_like
    d2 : (N2, D) array_like
    k : {1, 2}
    chunk : int
        Rows of ``d1`` per matrix product (memory: ``chunk × N2`` floats).

    Returns
    -------
    idx : (N1, k) int ndarray
        Indices into ``d2``, nearest first (-1 when ``d2`` has fewer than k rows).
    dist : (N1, k) ndarray
        Their distances (inf where ``idx`` is -1).

    Examples
    --------
    >>> idx, dist = nearest_neighbours([[0.0, 0.0], [5.0, 5.0]], [[1.0, 0.0], [4.0, 5.0], [0.0, 3.0]])
    >>> idx.tolist(), dist.round(3).tolist()
    ([[0, 2], [1, 2]], [[1.0, 3.0], [1.0, 5.385]])
    """
    d1, d2 = _as_descriptors(d1, "d1"), _as_descriptors(d2, "d2")
    if d1.shape[1] != d2.shape[1]:
        raise ValueError(f"d1 and d2 must have the same descriptor length; got {d1.shape[1]} and {d2.shape[1]}")
    if k not in (1, 2):
        raise ValueError(f"k must be 1 or 2; got {k}")
    n1, n2 = len(d1), len(d2)
    idx = np.full((n1, k), -1, np.int64)
    dist = np.full((n1, k), np.inf)
    if n1 == 0 or n2 == 0:
        return idx, dist
    sq2 = np.einsum("ij,ij->i", d2, d2)
    for s in range(0, n1, chunk):
        a = d1[s:s + chunk]
        rows = np.arange(len(a))
        e = sq2[None, :] - 2.0 * (a @ d2.T)            # |a - b|² - |a|²
        first = np.argmin(e, axis=1)
        best = [(first, e[rows, first])]
        if k == 2 and n2 >= 2:
            e[rows, first] = np.inf
            second = np.argmin(e, axis=1)
            best.append((second, e[rows, second]))
        sqa = np.einsum("ij,ij->i", a, a)
        for c, (i, v) in enumerate(best):
            idx[s:s + chunk, c] = i
            dist[s:s + chunk, c] = np.sqrt(np.maximum(v.astype(float) + sqa, 0.0))
    return idx, dist


def ratio_test(dist: ArrayLike, ratio: float = 0.8) -> np.ndarray:
    """Lowe's ratio test (Lowe 2004, Sec. 7.1): keep a match whose nearest neighbour is clearly the best.

    A correct match is much closer than the closest *wrong* neighbour; for an ambiguous or unmatched
    feature the two nearest are about equally far. Lowe keeps ``d1 < 0.8 d2``, which removed 90 % of his
    false matches and fewer than 5 % of the correct ones.

    Parameters
    ----------
    dist : (N, 2) array_like
        Distances to the nearest and the second-nearest neighbour (not squared).
    ratio : float
        In (0, 1].

    Returns
    -------
    keep : (N,) bool ndarray
        ``dist[:, 0] < ratio * dist[:, 1]``.

    Examples
    --------
    >>> ratio_test([[1.0, 2.0], [1.0, 1.1], [0.0, 0.0]]).tolist()
    [True, False, False]
    """
    d = np.asarray(dist, float)
    if d.ndim != 2 or d.shape[1] != 2:
        raise ValueError(f"dist must have shape (N, 2) (nearest, second nearest); got shape {d.shape}")
    if np.isnan(d).any() or (d < 0).any():
        raise ValueError("dist must hold non-negative distances (inf allowed, no NaN)")
    if not 0 < ratio <= 1:
        raise ValueError(f"ratio must be in (0, 1]; got {ratio}")
    return d[:, 0] < ratio * d[:, 1]


def _as_index_list(m, name):
    m = np.asarray(m)
    if m.ndim != 1 or not (np.issubdtype(m.dtype, np.integer) or m.size == 0):
        raise ValueError(f"{name} must be a 1-D integer array (an index per feature, -1 for none); "
                         f"got shape {m.shape} and dtype {m.dtype}")
    if m.size and m.min() < -1:
        raise ValueError(f"{name} has an index below -1 ({m.min()}); -1 means 'no match'")
    return m.astype(np.int64)


def mutual_check(m12: ArrayLike, m21: ArrayLike) -> np.ndarray:
    """Mutual (cross) check of two one-way match lists: keep ``i -> j`` only if also ``j -> i``.

    Parameters
    ----------
    m12 : (N1,) int array_like
        For each feature of image 1, its match in image 2, or -1 for none.
    m21 : (N2,) int array_like
        For each feature of image 2, its match in image 1, or -1 for none.

    Returns
    -------
    matches : (M, 2) int ndarray
        Rows ``(i, j)`` with ``m12[i] == j`` and ``m21[j] == i``, in increasing ``i``.

    Raises
    ------
    ValueError
        An index below -1, or one beyond the other list.

    Examples
    --------
    >>> mutual_check([1, -1, 0], [2, 0]).tolist()
    [[0, 1], [2, 0]]
    >>> mutual_check([1, 1], [-1, 1]).tolist()          # 0 -> 1 but 1 -> 1: only (1, 1) survives
    [[1, 1]]
    """
    m12, m21 = _as_index_list(m12, "m12"), _as_index_list(m21, "m21")
    if m12.size and m12.max() >= len(m21):
        raise ValueError(f"m12 points to feature {m12.max()} of image 2, which has {len(m21)} (the length of m21)")
    if m21.size and m21.max() >= len(m12):
        raise ValueError(f"m21 points to feature {m21.max()} of image 1, which has {len(m12)} (the length of m12)")
    i = np.flatnonzero(m12 >= 0)
    j = m12[i]
    ok = m21[j] == i
    return np.column_stack([i[ok], j[ok]]).astype(np.int64).reshape(-1, 2)


def match_descriptors(d1: ArrayLike, d2: ArrayLike, *, ratio: float | None = 0.8, cross_check: bool = True,
                      return_info: bool = False) -> np.ndarray | tuple[np.ndarray, dict]:
    """Match two descriptor sets: nearest neighbour, ratio test, then the mutual check.

    Parameters
    ----------
    d1 : (N1, D) array_like
    d2 : (N2, D) array_like
    ratio : float or None
        Ratio-test threshold (None: no ratio test).
    cross_check : bool
        Keep only mutual nearest neighbours.
    return_info : bool
        Also return a dict: the survivors of each stage (``features`` = N1, ``ratio``, ``mutual``) and
        ``distance_ratio``, the ``(M,)`` ratios d1/d2 of the matches returned (a ranking: lower is more
        distinctive).

    Returns
    -------
    matches : (M, 2) int ndarray
        Rows ``(i, j)``: feature i of image 1 matches feature j of image 2.

    Examples
    --------
    >>> d1 = np.eye(4, 8, dtype=np.float32); d2 = d1[[2, 0, 3, 1]] + 0.01
    >>> match_descriptors(d1, d2).tolist()
    [[0, 1], [1, 3], [2, 0], [3, 2]]
    """
    d1, d2 = _as_descriptors(d1, "d1"), _as_descriptors(d2, "d2")
    idx, dist = nearest_neighbours(d1, d2, k=2)
    keep = ratio_test(dist, ratio) if ratio is not None else np.isfinite(dist[:, 0])
    m12 = np.where(keep, idx[:, 0], -1)
    info = {"features": len(d1), "ratio": int(keep.sum())}
    if cross_check:
        m21 = nearest_neighbours(d2, d1, k=1)[0][:, 0]
        matches = mutual_check(m12, m21)
    else:
        i = np.flatnonzero(m12 >= 0)
        matches = np.column_stack([i, m12[i]]).astype(np.int64).reshape(-1, 2)
    info["mutual"] = len(matches)
    with np.errstate(divide="ignore", invalid="ignore"):
        info["distance_ratio"] = np.nan_to_num(dist[matches[:, 0], 0] / dist[matches[:, 0], 1], nan=1.0)
    return (matches, info) if return_info else matches


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
        return fundamental_ransac(x1, x2, threshold=threshold_px, rng=rng, confidence=confidence, max_iter=max_iter)
    ranking = np.asarray(ranking, float).reshape(-1)
    if ranking.shape != (len(x1),):
        raise ValueError(f"ranking must have one value per match ({len(x1)}); got shape {np.shape(ranking)}")
    best = np.argsort(ranking, kind="stable")[:max(30, len(x1) // 3)]
    F, _ = fundamental_ransac(x1[best], x2[best], threshold=threshold_px, rng=rng, confidence=confidence,
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
       (:func:`labutils.epipolar.fundamental_ransac`, H&Z Alg. 11.4): inliers are within ``threshold_px``.
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
        them: one plane, or no baseline; see :func:`labutils.epipolar.fundamental_8point`).

    Examples
    --------
    >>> from labutils.synthetic import make_scene
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


# ---------------------------------------------------------------------------------------------
# Tracks
# ---------------------------------------------------------------------------------------------

class UnionFind:
    """Disjoint sets over ``0 .. n-1`` with path halving and union by size (Tarjan 1975).

    ``find`` and ``union`` take nearly constant time each (inverse Ackermann), so chaining all pairwise
    matches costs about one pass over them.

    Examples
    --------
    >>> uf = UnionFind(5)
    >>> uf.union(0, 3); uf.union(3, 4)
    >>> uf.find(4) == uf.find(0), uf.find(1) == uf.find(0)
    (True, False)
    >>> uf.labels().tolist()
    [0, 1, 2, 0, 0]
    """

    def __init__(self, n: int):
        self.parent = list(range(int(n)))
        self.size = [1] * int(n)

    def find(self, a: int) -> int:
        parent = self.parent
        while parent[a] != a:
            parent[a] = parent[parent[a]]          # path halving
            a = parent[a]
        return a

    def union(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return
        if self.size[ra] < self.size[rb]:
            ra, rb = rb, ra
        self.parent[rb] = ra
        self.size[ra] += self.size[rb]

    def labels(self) -> np.ndarray:
        """(n,) int ndarray: for each element, the smallest element of its set."""
        roots = np.array([self.find(a) for a in range(len(self.parent))], np.int64)
        smallest = np.full(len(roots), len(roots), np.int64)
        np.minimum.at(smallest, roots, np.arange(len(roots)))
        return smallest[roots]


def _check_pair_matches(pair_matches, n_features):
    n_features = [int(n) for n in n_features]
    V = len(n_features)
    out = {}
    for key, m in pair_matches.items():
        try:
            i, j = (int(v) for v in key)
        except (TypeError, ValueError):
            raise ValueError(f"pair_matches keys must be pairs of view indices (i, j); got {key!r}") from None
        if not (0 <= i < V and 0 <= j < V) or i == j:
            raise ValueError(f"pair ({i}, {j}) is not two different views in 0..{V - 1}")
        m = np.asarray(m)
        if m.size == 0:
            continue
        if m.ndim != 2 or m.shape[1] != 2 or not np.issubdtype(m.dtype, np.integer):
            raise ValueError(f"the matches of pair ({i}, {j}) must be an (M, 2) integer array; got shape {m.shape}")
        if m.min() < 0 or m[:, 0].max() >= n_features[i] or m[:, 1].max() >= n_features[j]:
            raise ValueError(f"the matches of pair ({i}, {j}) index features outside 0..{n_features[i] - 1} "
                             f"(view {i}) or 0..{n_features[j] - 1} (view {j})")
        out[(i, j)] = m
    return out, n_features


def build_tracks(pair_matches: dict, n_features: Sequence[int],
                 return_conflicts: bool = False) -> np.ndarray | tuple[np.ndarray, int]:
    """Chain pairwise matches into tracks with union-find; reject tracks with two features of one view.

    Every feature of every view is a node; each match ``(i, a) - (j, b)`` joins two nodes; a track is a
    connected set of nodes (a *connected component*). A track that holds two different features of the
    same view claims that one 3D point is seen in two places of one image: at least one of its matches
    is wrong, and we cannot tell which, so the whole track is rejected. Tracks need two views or more.

    Parameters
    ----------
    pair_matches : dict
        ``{(i, j): (M, 2) int array}``: feature ``a`` of view i matches feature ``b`` of view j for
        each row ``(a, b)``.
    n_features : sequence of int
        Features per view (V views).
    return_conflicts : bool
        Also return the number of rejected (conflicting) tracks.

    Returns
    -------
    tracks : (V, T) int ndarray
        Feature index of each track in each view, -1 where the view does not see it. Tracks are ordered
        by their first node (view, then feature index).
    n_conflicts : int
        With ``return_conflicts``.

    Examples
    --------
    >>> m = {(0, 1): np.array([[0, 0], [1, 1]]), (1, 2): np.array([[0, 1], [1, 0]]),
    ...      (0, 2): np.array([[1, 2]])}
    >>> build_tracks(m, [2, 2, 3], return_conflicts=True)
    (array([[0],
           [0],
           [1]]), 1)
    """
    pair_matches, n_features = _check_pair_matches(pair_matches, n_features)
    V = len(n_features)
    offsets = np.concatenate([[0], np.cumsum(n_features)]).astype(np.int64)
    uf = UnionFind(offsets[-1])
    for (i, j), m in pair_matches.items():
        for a, b in zip((offsets[i] + m[:, 0]).tolist(), (offsets[j] + m[:, 1]).tolist()):
            uf.union(a, b)
    label = uf.labels()
    node_view = np.repeat(np.arange(V), n_features)
    # the nodes of tracks of length >= 2, grouped by label (labels are the smallest node of each set)
    count = np.bincount(label, minlength=len(label))
    nodes = np.flatnonzero(count[label] >= 2)
    lab = label[nodes]
    views_per_track = np.zeros(len(label), np.int64)
    np.add.at(views_per_track, lab, 1)
    # a conflict: two nodes of one track in one view
    pair_key = lab * V + node_view[nodes]
    uniq, per = np.unique(pair_key, return_counts=True)
    bad_labels = np.unique(uniq[per > 1] // V)
    good = ~np.isin(lab, bad_labels)
    nodes, lab = nodes[good], lab[good]
    track_labels = np.unique(lab)
    col = np.searchsorted(track_labels, lab)
    tracks = np.full((V, len(track_labels)), -1, np.int64)
    tracks[node_view[nodes], col] = nodes - offsets[node_view[nodes]]
    return (tracks, int(len(bad_labels))) if return_conflicts else tracks


def track_pixels(tracks: ArrayLike, xy: Sequence[ArrayLike]) -> np.ndarray:
    """Pixels of tracks: ``(V, T, 2)``, NaN where a view does not see a track (like ``Scene.tracks``).

    Parameters
    ----------
    tracks : (V, T) int array_like
        Feature indices, -1 where unseen (from :func:`build_tracks`).
    xy : sequence of V (N_v, 2) arrays
        The keypoint positions of each view (e.g. ``[f.xy for f in features]``).

    Examples
    --------
    >>> track_pixels([[0, -1], [1, 0]], [np.array([[1.0, 2.0]]), np.array([[3.0, 4.0], [5.0, 6.0]])])[:, :, 0]
    array([[ 1., nan],
           [ 5.,  3.]])
    """
    tracks = np.asarray(tracks)
    if tracks.ndim != 2 or len(xy) != tracks.shape[0]:
        raise ValueError(f"tracks must have shape (V, T) with V = len(xy) = {len(xy)}; got {tracks.shape}")
    out = np.full(tracks.shape + (2,), np.nan)
    for v in range(tracks.shape[0]):
        seen = tracks[v] >= 0
        out[v, seen] = np.asarray(xy[v], float)[tracks[v, seen]]
    return out


def verify_tracks(x: ArrayLike, geometry: dict, threshold_px: float) -> np.ndarray:
    """Check every track against the epipolar geometry of every pair of its views that has one.

    Union-find also joins observations that were never matched directly: ``a`` in view i matches ``b``
    in view k, which matches ``c`` in view j, so ``(a, c)`` is assumed without any test of the pair (i, j).
    Where F of (i, j) is known (the pair was matched and verified), such an observation must lie within
    ``threshold_px`` of its epipolar line too; a track that fails for any pair is rejected.

    Parameters
    ----------
    x : (V, T, 2) array_like
        Track pixels, NaN where unseen.
    geometry : dict
        ``{(i, j): F}`` with ``x_jᵀ F x_i = 0``.
    threshold_px : float
        On the Sampson distance.

    Returns
    -------
    keep : (T,) bool ndarray
    """
    x = np.asarray(x, float)
    if x.ndim != 3 or x.shape[2] != 2:
        raise ValueError(f"x must have shape (V, T, 2); got {x.shape}")
    seen = np.isfinite(x[..., 0])
    keep = np.ones(x.shape[1], bool)
    for (i, j), F in geometry.items():
        both = np.flatnonzero(seen[i] & seen[j] & keep)
        if both.size:
            d = sampson_distance(F, x[i, both], x[j, both])
            keep[both[d >= threshold_px]] = False
    return keep


def track_statistics(x: ArrayLike) -> dict:
    """Counts of a track set: tracks, observations, and how many tracks have each length.

    Parameters
    ----------
    x : (V, T, 2) array_like
        NaN where unseen.

    Returns
    -------
    dict
        ``tracks``, ``observations``, ``mean_length``, ``median_length``, ``max_length`` and
        ``length_counts`` (index L: tracks seen in exactly L views).

    Examples
    --------
    >>> x = np.full((3, 2, 2), np.nan); x[:, 0] = 1.0; x[:2, 1] = 2.0
    >>> track_statistics(x)["length_counts"].tolist()
    [0, 0, 1, 1]
    """
    x = np.asarray(x, float)
    L = np.isfinite(x[..., 0]).sum(0)
    return dict(tracks=int(x.shape[1]), observations=int(L.sum()), mean_length=float(L.mean()) if L.size else 0.0,
                median_length=float(np.median(L)) if L.size else 0.0, max_length=int(L.max(initial=0)),
                length_counts=np.bincount(L, minlength=x.shape[0] + 1))


# ---------------------------------------------------------------------------------------------
# Which pairs to match
# ---------------------------------------------------------------------------------------------

def select_pairs(n_views: int, strategy: str = "all", window: int | None = None) -> np.ndarray:
    """The pairs of views to match.

    ``'all'``: every pair (``V (V - 1) / 2``: fine for tens of views, quadratic beyond). ``'sequence'``:
    views at most ``window`` apart in the order given (a video, a walk around). ``'ring'``: the same on a
    closed loop (a turntable), so the last views also meet the first ones.

    Parameters
    ----------
    n_views : int
    strategy : {'all', 'sequence', 'ring'}
    window : int
        Required for 'sequence' and 'ring'.

    Returns
    -------
    pairs : (P, 2) int ndarray
        Rows ``(i, j)`` with ``i < j``, sorted.

    Examples
    --------
    >>> select_pairs(4).tolist()
    [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    >>> select_pairs(5, "ring", window=1).tolist()
    [[0, 1], [0, 4], [1, 2], [2, 3], [3, 4]]
    """
    V = int(n_views)
    if V < 2:
        raise ValueError(f"n_views must be at least 2; got {n_views}")
    i, j = np.triu_indices(V, 1)
    if strategy == "all":
        keep = np.ones(i.size, bool)
    elif strategy in ("sequence", "ring"):
        if window is None or int(window) < 1:
            raise ValueError(f"strategy '{strategy}' needs a window >= 1; got {window}")
        gap = j - i
        if strategy == "ring":
            gap = np.minimum(gap, V - gap)
        keep = gap <= int(window)
    else:
        raise ValueError(f"strategy must be 'all', 'sequence' or 'ring'; got {strategy!r}")
    return np.column_stack([i[keep], j[keep]]).astype(np.int64)


def retrieval_pairs(descriptors: Sequence[ArrayLike], n_neighbours: int, *, rng: np.random.Generator,
                    vocabulary_size: int = 256, sample: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """A shortlist of pairs from a bag of visual words (Sivic & Zisserman, "Video Google", ICCV 2003).

    A vocabulary of ``vocabulary_size`` words is learnt by k-means on a sample of all descriptors; each image
    becomes a histogram of its words, weighted by tf-idf and normalised; each image is paired with the
    ``n_neighbours`` images whose histograms are most similar (cosine). Costs one k-means and one
    ``V × V`` product instead of ``V (V - 1) / 2`` pair matchings.

    Parameters
    ----------
    descriptors : sequence of V (N_v, D) arrays
    n_neighbours : int
        Per image (the shortlist holds at most ``V · n_neighbours`` pairs).
    rng : numpy.random.Generator
        For the sample and the k-means seeds.
    vocabulary_size : int
    sample : int
        Descriptors drawn to learn the vocabulary.

    Returns
    -------
    pairs : (P, 2) int ndarray
        ``i < j``, sorted.
    similarity : (V, V) ndarray
        Cosine similarity of the tf-idf histograms (1 on the diagonal).
    """
    import scipy.cluster.vq

    if not isinstance(rng, np.random.Generator):
        raise ValueError("rng must be a numpy.random.Generator, e.g. np.random.default_rng(0)")
    D = [_as_descriptors(d, f"descriptors[{v}]") for v, d in enumerate(descriptors)]
    V = len(D)
    if V < 2:
        raise ValueError(f"need descriptors of at least 2 images; got {V}")
    every = np.concatenate(D)
    if len(every) < vocabulary_size:
        raise ValueError(f"{len(every)} descriptors in all, fewer than vocabulary_size = {vocabulary_size}")
    train = every[rng.choice(len(every), min(sample, len(every)), replace=False)]
    # random descriptors as the initial words ('++' seeding is better in theory but takes a minute here)
    codebook, _ = scipy.cluster.vq.kmeans2(train, vocabulary_size, iter=10, minit="points", seed=rng)
    H = np.zeros((V, vocabulary_size))
    for v, d in enumerate(D):
        if len(d):
            words = nearest_neighbours(d, codebook.astype(np.float32), k=1)[0][:, 0]
            H[v] = np.bincount(words, minlength=vocabulary_size)
    idf = np.log(V / np.maximum((H > 0).sum(0), 1))
    W = H / np.maximum(H.sum(1, keepdims=True), 1) * idf
    W /= np.maximum(np.linalg.norm(W, axis=1, keepdims=True), 1e-300)
    S = W @ W.T
    order = np.argsort(-(S - 2 * np.eye(V)), axis=1)[:, :int(n_neighbours)]
    pairs = {(min(a, b), max(a, b)) for a in range(V) for b in order[a].tolist()}
    return np.array(sorted(pairs), np.int64).reshape(-1, 2), S


# ---------------------------------------------------------------------------------------------
# Many pairs, and the tracks
# ---------------------------------------------------------------------------------------------

@dataclass
class MatchResult:
    """Verified matches of many pairs of views, with the survivors of each stage.

    Attributes
    ----------
    matches : dict
        ``{(i, j): (M, 2) int ndarray}`` of the matches that passed every stage (pairs with fewer than
        ``min_inliers`` are left out).
    geometry : dict
        ``{(i, j): PairGeometry}`` for every pair the epipolar filter ran on.
    table : list of dict
        One row per pair: ``i, j, features_i, features_j, ratio, mutual, epipolar`` (the survivors of
        each stage), ``behind`` (epipolar inliers rejected by cheirality) and ``note`` (why a pair was
        dropped, if it was).
    seconds : dict
        Time per stage: ``matching`` (nearest neighbours, ratio test, mutual check), ``epipolar``.
    """

    matches: dict
    geometry: dict
    table: list
    seconds: dict = field(default_factory=dict)

    def totals(self) -> dict:
        """Sum of each stage's survivors over all pairs."""
        keys = ("ratio", "mutual", "epipolar", "behind")
        return {k: int(sum(r[k] for r in self.table)) for k in keys}

    def fundamental_matrices(self) -> dict:
        """``{(i, j): F}`` of the pairs that kept their matches (for :func:`verify_tracks`)."""
        return {k: self.geometry[k].F for k in self.matches}


def match_views(features: Sequence[Features], pairs: ArrayLike, *, rng: np.random.Generator, K: ArrayLike | None = None,
                ratio: float = 0.8, cross_check: bool = True, threshold_px: float = 1.0, min_inliers: int = 20,
                guided: bool = True, confidence: float = 0.999, max_iter: int = 400,
                progress: Callable[[int, int], None] | None = None) -> MatchResult:
    """Match every pair in ``pairs``: nearest neighbours, ratio test, mutual check, epipolar filter.

    Parameters
    ----------
    features : sequence of V :class:`Features`
    pairs : (P, 2) int array_like
    rng : numpy.random.Generator
    K : (3, 3) or (V, 3, 3) array_like, optional
        Calibration in the pixels of ``features`` (use :func:`scale_calibration` for reduced images):
        turns on the calibrated epipolar filter.
    ratio, cross_check :
        See :func:`match_descriptors`.
    threshold_px : float
        Sampson-distance threshold of the epipolar filter, in working pixels.
    min_inliers : int
        Pairs with fewer verified matches are dropped (too few to trust their F).
    guided : bool
        RANSAC samples the most distinctive matches first (see :func:`epipolar_filter`).
    confidence, max_iter :
        Of RANSAC.
    progress : callable, optional
        ``progress(done, total)`` after each pair.

    Returns
    -------
    MatchResult
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError("rng must be a numpy.random.Generator, e.g. np.random.default_rng(0)")
    V = len(features)
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= V or np.any(pairs[:, 0] == pairs[:, 1])):
        raise ValueError(f"pairs must hold two different view indices in 0..{V - 1}")
    Ks = None
    if K is not None:
        Ks = np.asarray(K, float)
        Ks = np.repeat(Ks[None], V, axis=0) if Ks.shape == (3, 3) else Ks
        if Ks.shape != (V, 3, 3) or not np.isfinite(Ks).all():
            raise ValueError(f"K must have shape (3, 3) or ({V}, 3, 3) with finite entries; got {np.shape(K)}")
    matches, geometry, table = {}, {}, []
    seconds = {"matching": 0.0, "epipolar": 0.0}
    for n, (i, j) in enumerate(pairs.tolist()):
        t0 = time.perf_counter()
        m, counts = match_descriptors(features[i].descriptors, features[j].descriptors, ratio=ratio,
                                      cross_check=cross_check, return_info=True)
        t1 = time.perf_counter()
        row = dict(i=i, j=j, features_i=len(features[i]), features_j=len(features[j]), ratio=counts["ratio"],
                   mutual=counts["mutual"], epipolar=0, behind=0, note="")
        if len(m) < max(min_inliers, 8):
            row["note"] = f"fewer than {max(min_inliers, 8)} matches"
        else:
            x1, x2 = features[i].xy[m[:, 0]], features[j].xy[m[:, 1]]
            try:
                g = epipolar_filter(x1, x2, rng=rng, threshold_px=threshold_px, confidence=confidence,
                                    ranking=counts["distance_ratio"] if guided else None, max_iter=max_iter,
                                    K1=None if Ks is None else Ks[i], K2=None if Ks is None else Ks[j])
            except ValueError as exc:
                row["note"] = f"epipolar filter failed: {str(exc).split(':')[0]}"
            else:
                geometry[(i, j)] = g
                row["epipolar"], row["behind"] = int(g.inliers.sum()), g.n_behind
                if row["epipolar"] >= min_inliers:
                    matches[(i, j)] = m[g.inliers]
                else:
                    row["note"] = f"fewer than {min_inliers} inliers"
                    row["epipolar"] = 0
        seconds["matching"] += t1 - t0
        seconds["epipolar"] += time.perf_counter() - t1
        table.append(row)
        if progress is not None:
            progress(n + 1, len(pairs))
    return MatchResult(matches=matches, geometry=geometry, table=table, seconds=seconds)


@dataclass
class TrackResult:
    """Tracks built from verified pairwise matches.

    Attributes
    ----------
    x : (V, T, 2) ndarray
        Pixels (working images), NaN where unseen: the input of :func:`labutils.sfm.incremental_sfm`.
    features : (V, T) int ndarray
        Feature index of each observation, -1 where unseen.
    n_candidates : int
        Connected components with two views or more.
    n_conflicts : int
        Rejected: two features of one view.
    n_inconsistent : int
        Rejected by :func:`verify_tracks` (0 when it was not run).
    """

    x: np.ndarray
    features: np.ndarray
    n_candidates: int
    n_conflicts: int
    n_inconsistent: int = 0


def tracks_from_matches(features: Sequence[Features], result: MatchResult, *,
                        verify_px: float | None = None) -> TrackResult:
    """Tracks from the verified matches of :func:`match_views`: union-find, conflicts, and (optionally) the
    epipolar check of every pair of a track's views (:func:`verify_tracks`).

    Parameters
    ----------
    features : sequence of V :class:`Features`
    result : MatchResult
    verify_px : float, optional
        Threshold of :func:`verify_tracks` (None: no check).

    Returns
    -------
    TrackResult
    """
    ids, n_conf = build_tracks(result.matches, [len(f) for f in features], return_conflicts=True)
    x = track_pixels(ids, [f.xy for f in features])
    n_cand = ids.shape[1] + n_conf
    n_bad = 0
    if verify_px is not None:
        keep = verify_tracks(x, result.fundamental_matrices(), verify_px)
        n_bad = int((~keep).sum())
        ids, x = ids[:, keep], x[:, keep]
    return TrackResult(x=x, features=ids, n_candidates=n_cand, n_conflicts=n_conf, n_inconsistent=n_bad)
