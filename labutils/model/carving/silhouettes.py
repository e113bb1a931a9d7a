"""Silhouettes from colour: the background's colours learnt from the image borders, each pixel's distance to them,
a cleaned mask; the signed distance to a mask's boundary; the IoU of two masks."""
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike

__all__ = ["QUANTISATION", "BackgroundModel", "background_model", "colour_distance", "clean_mask",
           "silhouette", "signed_distance_map", "mask_iou"]


def _as_number(value, name, *, lo=None, hi=None, integer=False, open_lo=False):
    """A finite float (or int) within [lo, hi] (``open_lo``: lo excluded), else ``ValueError`` naming ``name``."""
    if isinstance(value, (bool, np.bool_, complex, np.complexfloating)):   # True is not 1, 1+2j not 1
        raise ValueError(f"{name} must be a number; got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number; got {value!r}") from None
    if not np.isfinite(v) or (integer and v != int(v)):
        raise ValueError(f"{name} must be a finite {'integer' if integer else 'number'}; got {value!r}")
    if lo is not None and (v < lo or (open_lo and v == lo)):
        raise ValueError(f"{name} must be {'>' if open_lo else '>='} {lo:g}; got {value!r}")
    if hi is not None and v > hi:
        raise ValueError(f"{name} must be <= {hi:g}; got {value!r}")
    return int(v) if integer else v


def _as_image(image, name="image"):
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or a.size == 0:
        raise ValueError(f"{name} must be an RGB image, a (H, W, 3) uint8 array with H, W > 0; got shape {a.shape} "
                         f"and dtype {a.dtype}")
    return a


def _as_mask(mask, name="mask", shape=None):
    try:
        a = np.asarray(mask)
    except ValueError:
        raise ValueError(f"{name} must be a (H, W) boolean mask; got a ragged list") from None
    if a.ndim != 2 or a.size == 0 or (a.dtype != bool and not (a.dtype.kind in "iu" and a.max() <= 1
                                                                and a.min() >= 0)):
        raise ValueError(f"{name} must be a (H, W) boolean mask with H, W > 0; got shape {a.shape} and dtype {a.dtype}")
    if shape is not None and a.shape != tuple(shape):
        raise ValueError(f"{name} has shape {a.shape}; expected {tuple(shape)}")
    return a.astype(bool)


QUANTISATION = 0.5
"""Standard deviation (CIELAB units) added to every background cluster's spread on each axis: about the step of one
grey level of an 8-bit image in CIELAB, so a perfectly flat synthetic background still has a spread."""


def _lab(pixels):
    """CIELAB of uint8 RGB pixels (..., 3) as float32: L in [0, 100], a and b about [-128, 127] (plain, unweighted)."""
    a = np.ascontiguousarray(pixels, dtype=np.uint8)
    flat = a.reshape(1, -1, 3).astype(np.float32) / 255.0
    return cv2.cvtColor(flat, cv2.COLOR_RGB2LAB).reshape(a.shape)


@dataclass
class BackgroundModel:
    """The colours of the background, learnt from the image borders: a few clusters in plain CIELAB.

    A pixel's colour distance is its Mahalanobis distance to the nearest cluster (in units of that cluster's own
    spread); the thresholds come from the distances of the border pixels themselves.

    Attributes
    ----------
    means : (k, 3) float ndarray
        The clusters' centres (L, a, b).
    whiten : (k, 3, 3) float ndarray
        Per cluster, ``W`` with ``Wᵀ W = Σ⁻¹`` (Σ the cluster's covariance plus ``QUANTISATION²``): the distance
        of colour c is ``‖W (c - mean)‖``.
    weights : (k,) float ndarray
        Fraction of the border pixels in each cluster.
    threshold : float
        Above it a pixel may be the object: the border pixels' distance exceeded by a fraction ``false_alarm`` of
        them (a background pixel beyond it is a false alarm). The lowest sensible threshold.
    n_samples : int
        Border pixels the model was learnt from.
    """

    means: np.ndarray
    whiten: np.ndarray
    weights: np.ndarray
    threshold: float
    n_samples: int

    @property
    def n_clusters(self):
        return len(self.means)


def _border_pixels(image, border_px):
    b = border_px
    return np.concatenate([image[:b].reshape(-1, 3), image[-b:].reshape(-1, 3), image[b:-b, :b].reshape(-1, 3),
                           image[b:-b, -b:].reshape(-1, 3)])


def _distances(lab, means, whiten):
    """(N,) Mahalanobis distance of CIELAB colours ``lab`` (N, 3) to the nearest cluster."""
    best = np.full(len(lab), np.inf, np.float32)
    x = [np.ascontiguousarray(lab[:, c], dtype=np.float32) for c in range(3)]
    for m, W in zip(means, whiten):
        W = W.astype(np.float32)
        c = [x[j] - np.float32(m[j]) for j in range(3)]
        sq = np.zeros(len(lab), np.float32)
        for r in range(3):                       # W is upper triangular: z_r = Σ_{j >= r} W[r, j] c_j
            z = W[r, r] * c[r]
            for j in range(r + 1, 3):
                z += W[r, j] * c[j]
            sq += z * z
        np.minimum(best, sq, out=best)
    return np.sqrt(best)


def _kmeans(X, k, iterations=30):
    """Lloyd's k-means, started deterministically at the quantiles of the first principal component.

    Returns the labels (N,) and the number of clusters kept (empty ones are dropped)."""
    Xc = X - X.mean(axis=0)
    axis = np.linalg.svd(Xc[:: max(1, len(X) // 20000)], full_matrices=False)[2][0]
    proj = Xc @ axis
    order = np.argsort(proj)
    centres = X[order[((np.arange(k) + 0.5) / k * len(X)).astype(int)]].astype(np.float64)
    labels = np.zeros(len(X), np.int64)
    for _ in range(iterations):
        d = np.stack([((X - c) ** 2).sum(axis=1) for c in centres], axis=1)
        new = np.argmin(d, axis=1)
        if _ > 0 and np.array_equal(new, labels):
            break
        labels = new
        for j in range(len(centres)):
            if np.any(labels == j):
                centres[j] = X[labels == j].mean(axis=0)
    used = np.unique(labels)
    return np.searchsorted(used, labels), len(used)


def background_model(images: Sequence[ArrayLike], *, border_px: int = 4, n_clusters: int = 4,
                     false_alarm: float = 1e-2, max_samples: int = 50_000) -> BackgroundModel:
    """Learn the background's colours from a frame ``border_px`` wide around every image.

    1. The frame's pixels (the object must not reach into it) are taken in plain CIELAB: lightness counts as much
       as hue, so a grey object on a black cloth is as visible as an orange one on a blue wall.
    2. They are grouped into at most ``n_clusters`` clusters (k-means): a background of several tones (a wall and a
       table, a dark band) gets one cluster per tone. Each cluster keeps its mean and covariance (plus
       :data:`QUANTISATION` ² on each axis); clusters holding less than ``false_alarm`` of the border (stray
       pixels of the object or of dust) are dropped.
    3. A colour's distance is its Mahalanobis distance to the nearest cluster. The border pixels are background, so
       their own distances say how far the background strays: ``threshold`` is the distance that only a fraction
       ``false_alarm`` of them exceed.

    Parameters
    ----------
    images : sequence of (H, W, 3) uint8 RGB images
    border_px : int
        Width of the frame, pixels.
    n_clusters : int
        At most this many background tones.
    false_alarm : float
        In (0, 0.5): the fraction of background pixels allowed above ``threshold`` (they are scattered specks,
        removed by :func:`clean_mask`, or a thin fringe along the object's outline).
    max_samples : int
        The frame's pixels are subsampled evenly to at most this many.

    Returns
    -------
    BackgroundModel

    Examples
    --------
    >>> img = np.zeros((40, 40, 3), np.uint8); img[...] = (40, 60, 200); img[15:25, 15:25] = (230, 120, 20)
    >>> m = background_model([img])
    >>> d = colour_distance(img, m)
    >>> bool(d[20, 20] > 50 * m.threshold), float(d[0, 0]), m.n_clusters
    (True, 0.0, 1)
    """
    border_px = _as_number(border_px, "border_px", lo=1, integer=True)
    n_clusters = _as_number(n_clusters, "n_clusters", lo=1, hi=16, integer=True)
    false_alarm = _as_number(false_alarm, "false_alarm", lo=0, hi=0.5, open_lo=True)
    max_samples = _as_number(max_samples, "max_samples", lo=100, integer=True)
    images = list(images)
    if not images:
        raise ValueError("images is empty: the background is learnt from at least one image")
    samples = []
    for i, img in enumerate(images):
        img = _as_image(img, f"images[{i}]")
        if min(img.shape[:2]) <= 2 * border_px:
            raise ValueError(f"images[{i}] ({img.shape[1]}x{img.shape[0]}) is too small for a {border_px}-pixel border")
        samples.append(_border_pixels(img, border_px))
    rgb = np.concatenate(samples)
    rgb = rgb[:: -(-len(rgb) // max_samples)]
    X = _lab(rgb).astype(np.float64)
    labels, k = _kmeans(X, n_clusters)
    means, whiten, weights = [], [], []
    for j in range(k):
        Xj = X[labels == j]
        if len(Xj) < max(4, false_alarm * len(X)):
            continue
        cov = np.cov(Xj.T) + QUANTISATION ** 2 * np.eye(3)
        means.append(Xj.mean(axis=0))
        whiten.append(np.linalg.cholesky(np.linalg.inv(cov)).T)
        weights.append(len(Xj) / len(X))
    means, whiten, weights = np.array(means), np.array(whiten), np.array(weights)
    d = _distances(X.astype(np.float32), means, whiten)
    threshold = float(np.quantile(d, 1 - false_alarm))
    return BackgroundModel(means, whiten, weights, threshold, int(len(X)))


def colour_distance(image: ArrayLike, model: BackgroundModel) -> np.ndarray:
    """Each pixel's Mahalanobis distance, in plain CIELAB, to the nearest background cluster.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB
    model : BackgroundModel

    Returns
    -------
    (H, W) float32 ndarray
        Small on the background's colours (in units of their own spread); large on the object.
    """
    if not isinstance(model, BackgroundModel):
        raise ValueError(f"model must be a BackgroundModel (from background_model); got {type(model).__name__}")
    image = _as_image(image)
    return _distances(_lab(image).reshape(-1, 3), model.means, model.whiten).reshape(image.shape[:2])


def clean_mask(mask: ArrayLike, *, min_component: float = 0.02, max_hole: float = 0.002) -> np.ndarray:
    """Remove small specks and fill small holes of a silhouette.

    Parameters
    ----------
    mask : (H, W) bool
    min_component : float
        Connected parts (8-connected) smaller than this fraction of the largest part are removed.
    max_hole : float
        Holes (4-connected background regions that do not touch the image border) smaller than this fraction of
        the object's area are filled; larger ones (between the temple's columns) stay.

    Returns
    -------
    (H, W) bool ndarray

    Examples
    --------
    >>> m = np.zeros((30, 30), bool); m[5:25, 5:25] = True; m[10, 10] = False; m[1, 1] = True
    >>> c = clean_mask(m, max_hole=0.01)       # a 1-pixel hole in a 400-pixel object: filled; the speck: removed
    >>> bool(c[10, 10]), bool(c[1, 1]), int(c.sum())
    (True, False, 400)
    """
    mask = _as_mask(mask)
    min_component = _as_number(min_component, "min_component", lo=0, hi=1)
    max_hole = _as_number(max_hole, "max_hole", lo=0, hi=1)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return mask.copy()
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.zeros(n, bool)
    keep[1:] = areas >= min_component * areas.max()
    out = keep[lab]
    n, lab, stats, _ = cv2.connectedComponentsWithStats((~out).astype(np.uint8), connectivity=4)
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    fill = stats[:, cv2.CC_STAT_AREA] < max_hole * out.sum()
    fill[border] = False
    fill[0] = False                                                   # label 0 is the object itself
    return out | (fill[lab] & ~out)


def silhouette(image: ArrayLike, model: BackgroundModel, *, threshold: float | None = None,
               min_component: float = 0.02, max_hole: float = 0.002) -> np.ndarray:
    """The object's silhouette: the pixels whose colour is far from every background colour, cleaned.

    A pixel is the object when its distance (:func:`colour_distance`) exceeds ``threshold``; by default the
    model's own, learnt from the border (``model.threshold``). :func:`segment_views` picks one for all views by how
    well their silhouettes agree.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB
    model : BackgroundModel
        From :func:`background_model`.
    threshold : float, optional
        Mahalanobis distance (see :func:`colour_distance`).
    min_component, max_hole : float
        See :func:`clean_mask`.

    Returns
    -------
    (H, W) bool ndarray
    """
    threshold = model.threshold if threshold is None else _as_number(threshold, "threshold", lo=0)
    return clean_mask(colour_distance(image, model) > threshold, min_component=min_component, max_hole=max_hole)


def signed_distance_map(mask: ArrayLike) -> np.ndarray:
    """Signed distance of each pixel to the silhouette's boundary, pixels: positive inside, negative outside.

    Pixels next to the boundary get ±½ (the boundary runs between pixel centres); outside the image counts
    as outside the silhouette.

    Examples
    --------
    >>> m = np.zeros((9, 9), bool); m[2:7, 2:7] = True
    >>> signed_distance_map(m)[4].tolist()
    [-1.5, -0.5, 0.5, 1.5, 2.5, 1.5, 0.5, -0.5, -1.5]
    """
    mask = _as_mask(mask)
    pad = np.pad(mask, 1).astype(np.uint8)
    # a 5x5 chamfer distance: exact along rows and columns, within 0.05 px of the Euclidean one for the first few
    # pixels (where marching cubes reads it), and twice as fast as the exact transform
    d_in = cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_5)[1:-1, 1:-1]
    d_out = cv2.distanceTransform(1 - pad, cv2.DIST_L2, cv2.DIST_MASK_5)[1:-1, 1:-1]
    return np.where(mask, d_in - 0.5, 0.5 - d_out).astype(np.float32)


def mask_iou(a: ArrayLike, b: ArrayLike) -> float:
    """Intersection over union of two masks: ``|a ∧ b| / |a ∨ b|``, in [0, 1].

    Raises
    ------
    ValueError
        If the shapes differ, or both masks are empty (the IoU is undefined).

    Examples
    --------
    >>> a = np.zeros((2, 4), bool); a[:, :2] = True
    >>> b = np.zeros((2, 4), bool); b[:, 1:3] = True
    >>> mask_iou(a, b)
    0.3333333333333333
    """
    a = _as_mask(a, "a")
    b = _as_mask(b, "b", shape=a.shape)
    union = np.count_nonzero(a | b)
    if union == 0:
        raise ValueError("both masks are empty: their IoU is undefined")
    return float(np.count_nonzero(a & b) / union)
