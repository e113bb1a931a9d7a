"""Features and their matches: SIFT, nearest neighbours, the ratio test and the mutual (cross) check."""
import numbers
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ..core.validation import as_array, as_count, as_positive
from .images import resize_gray, to_original_pixels

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
        Working size / original size (> 0), recorded in the result (see :func:`read_gray`).
    n_features : int
        Keep at most this many (the strongest); 0 keeps all.
    contrast_threshold : float
        SIFT's threshold on the contrast of a keypoint, >= 0 (lower: more, weaker keypoints).
    precise_upscale : bool
        Enlarge the image with the pixel centres kept (False: OpenCV's default, a quarter pixel off).

    Returns
    -------
    Features

    Raises
    ------
    ValueError
        An image that is not a non-empty ``(H, W)`` or ``(H, W, 3)`` uint8 array, or a bad setting.

    Examples
    --------
    >>> f = detect_features(np.zeros((64, 64), np.uint8))          # a blank image has no keypoints
    >>> f.xy.shape, f.descriptors.shape
    ((0, 2), (0, 128))
    """
    gray, _ = resize_gray(image)
    scale = as_positive(scale, "scale")
    n_features = as_count(n_features, "n_features", minimum=0)
    contrast_threshold = as_positive(contrast_threshold, "contrast_threshold", allow_zero=True)
    sift = cv2.SIFT_create(nfeatures=n_features, contrastThreshold=contrast_threshold,
                           enable_precise_upscale=bool(precise_upscale))
    kps, desc = sift.detectAndCompute(gray, None)
    xy = np.array([k.pt for k in kps], float).reshape(-1, 2)
    desc = np.zeros((0, 128), np.float32) if desc is None else desc.astype(np.float32)
    return Features(xy=xy, descriptors=desc, scale=scale, image_size=(gray.shape[1], gray.shape[0]))


# ---------------------------------------------------------------------------------------------
# Matching: nearest neighbours, the ratio test, the mutual check
# ---------------------------------------------------------------------------------------------

def _as_descriptors(d, name):
    d = as_array(d, name, "(N, D)")
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
    if not (isinstance(ratio, numbers.Real) and not isinstance(ratio, bool) and 0 < ratio <= 1):
        raise ValueError(f"ratio must be in (0, 1]; got {ratio!r}")
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


@dataclass
class DescriptorMatches:
    """What :func:`match_descriptors` returns.

    Attributes
    ----------
    matches : (M, 2) int ndarray
        Rows ``(i, j)``: feature i of image 1 matches feature j of image 2.
    n_features : int
        Features of image 1 (every one has a nearest neighbour).
    n_ratio, n_mutual : int
        Survivors of the ratio test and of the mutual check.
    distance_ratio : (M,) ndarray
        The ratio d1/d2 of each match returned (a ranking: lower is more distinctive).
    """

    matches: np.ndarray
    n_features: int
    n_ratio: int
    n_mutual: int
    distance_ratio: np.ndarray = field(repr=False)


def match_descriptors(d1: ArrayLike, d2: ArrayLike, *, ratio: float | None = 0.8,
                      cross_check: bool = True) -> DescriptorMatches:
    """Match two descriptor sets: nearest neighbour, ratio test, then the mutual check.

    Parameters
    ----------
    d1 : (N1, D) array_like
    d2 : (N2, D) array_like
    ratio : float or None
        Ratio-test threshold (None: no ratio test).
    cross_check : bool
        Keep only mutual nearest neighbours.

    Returns
    -------
    DescriptorMatches
        ``.matches`` (M, 2), rows ``(i, j)``; the survivors of each stage; each match's distance ratio.

    Examples
    --------
    >>> d1 = np.eye(4, 8, dtype=np.float32); d2 = d1[[2, 0, 3, 1]] + 0.01
    >>> match_descriptors(d1, d2).matches.tolist()
    [[0, 1], [1, 3], [2, 0], [3, 2]]
    """
    d1, d2 = _as_descriptors(d1, "d1"), _as_descriptors(d2, "d2")
    idx, dist = nearest_neighbours(d1, d2, k=2)
    keep = ratio_test(dist, ratio) if ratio is not None else np.isfinite(dist[:, 0])
    m12 = np.where(keep, idx[:, 0], -1)
    if cross_check:
        m21 = nearest_neighbours(d2, d1, k=1)[0][:, 0]
        matches = mutual_check(m12, m21)
    else:
        i = np.flatnonzero(m12 >= 0)
        matches = np.column_stack([i, m12[i]]).astype(np.int64).reshape(-1, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        distance_ratio = np.nan_to_num(dist[matches[:, 0], 0] / dist[matches[:, 0], 1], nan=1.0)
    return DescriptorMatches(matches=matches, n_features=len(d1), n_ratio=int(keep.sum()), n_mutual=len(matches),
                             distance_ratio=distance_ratio)
