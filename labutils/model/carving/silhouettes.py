"""Silhouettes from colour: the background's colours learnt from the image borders, each pixel's distance to them,
a cleaned mask; the signed distance to a mask's boundary; the IoU of two masks."""
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

__all__ = ["BackgroundModel", "background_model", "colour_distance", "clean_mask", "silhouette",
           "signed_distance_map", "mask_iou"]


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


def _lab_cells(image, lightness_weight):
    """Each pixel's cell of the (w·L, a, b) colour grid, as a flat index into a ``(nL, 256, 256)`` array.

    OpenCV's 8-bit CIELAB stores ``L·255/100`` and ``a + 128``, ``b + 128``, already on a 1-unit grid for a and b;
    the lightness cell is ``floor(w · L)``.
    """
    lab = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2LAB)
    L = np.floor(lab[..., 0] * (lightness_weight * 100.0 / 255.0) + 1e-9).astype(np.int32)   # exact products: not 15.99
    return (L << 16) | (lab[..., 1].astype(np.int32) << 8) | lab[..., 2].astype(np.int32)


def _n_lightness_cells(lightness_weight):
    return int(np.floor(100 * lightness_weight)) + 1


@dataclass
class BackgroundModel:
    """The colours of the background, learnt from the image borders.

    Attributes
    ----------
    distance : (nL, 256, 256) float32 ndarray
        For each cell of the (w·L, a + 128, b + 128) colour space (1 unit wide), its distance to the nearest
        background cell.
    lightness_weight : float
        w: how much a change of lightness counts against the same change of hue (a, b).
    n_samples : int
        Border pixels the model was learnt from.
    """

    distance: np.ndarray
    lightness_weight: float
    n_samples: int


def _border_pixels(image, border_px):
    b = border_px
    return np.concatenate([image[:b].ravel(), image[-b:].ravel(), image[b:-b, :b].ravel(), image[b:-b, -b:].ravel()])


def background_model(images: Sequence[ArrayLike], *, border_px: int = 4, lightness_weight: float = 0.3,
                     min_count: float = 3) -> BackgroundModel:
    """Learn the background's colours from a frame ``border_px`` wide around every image.

    The colours seen there (in CIELAB, lightness scaled by ``lightness_weight``) mark cells of a 1-unit grid; a
    cell counts as background when at least ``min_count`` border pixels fall in it or its 26 neighbours (so a few
    stray object pixels at the border do not count). A Euclidean distance transform of that set gives, for every
    colour, its distance to the nearest background colour.

    Parameters
    ----------
    images : sequence of (H, W, 3) uint8 RGB images
    border_px : int
        Width of the frame, pixels: the object must not reach into it.
    lightness_weight : float
        In (0, 1]: 1 is plain CIELAB; smaller values forgive shading and shadows on the background.
    min_count : int

    Returns
    -------
    BackgroundModel

    Examples
    --------
    >>> img = np.zeros((40, 40, 3), np.uint8); img[...] = (40, 60, 200); img[15:25, 15:25] = (230, 120, 20)
    >>> m = background_model([img])
    >>> d = colour_distance(img, m)
    >>> bool(d[20, 20] > 50), float(d[0, 0])
    (True, 0.0)
    """
    lightness_weight = _as_number(lightness_weight, "lightness_weight", lo=0, hi=1, open_lo=True)
    border_px = _as_number(border_px, "border_px", lo=1, integer=True)
    min_count = _as_number(min_count, "min_count", lo=1)
    images = list(images)
    if not images:
        raise ValueError("images is empty: the background is learnt from at least one image")
    samples = []
    for i, img in enumerate(images):
        img = _as_image(img, f"images[{i}]")
        if min(img.shape[:2]) <= 2 * border_px:
            raise ValueError(f"images[{i}] ({img.shape[1]}x{img.shape[0]}) is too small for a {border_px}-pixel border")
        samples.append(_border_pixels(_lab_cells(img, lightness_weight), border_px))
    X = np.concatenate(samples)
    nL = _n_lightness_cells(lightness_weight)
    counts = np.bincount(X, minlength=nL * 256 * 256)
    counts = ndimage.uniform_filter(counts.reshape(nL, 256, 256).astype(np.float32), 3, mode="constant") * 27
    occupied = counts >= min_count - 1e-3
    if not occupied.any():
        raise ValueError(f"no colour is seen {min_count} times at the image borders: lower min_count")
    dist = ndimage.distance_transform_edt(~occupied).astype(np.float32)
    return BackgroundModel(dist, float(lightness_weight), int(len(X)))


def colour_distance(image: ArrayLike, model: BackgroundModel) -> np.ndarray:
    """Distance (CIELAB units, lightness weighted) of each pixel's colour to the nearest background colour.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB
    model : BackgroundModel

    Returns
    -------
    (H, W) float32 ndarray
        0 on colours seen at the borders; large on the object.
    """
    if not isinstance(model, BackgroundModel):
        raise ValueError(f"model must be a BackgroundModel (from background_model); got {type(model).__name__}")
    return model.distance.ravel()[_lab_cells(_as_image(image), model.lightness_weight)]


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


def silhouette(image: ArrayLike, model: BackgroundModel, *, threshold: float = 2.5, min_component: float = 0.02,
               max_hole: float = 0.002) -> np.ndarray:
    """The object's silhouette: pixels whose colour is farther than ``threshold`` from every background colour.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB
    model : BackgroundModel
        From :func:`background_model`.
    threshold : float
        CIELAB units (lightness weighted); the background's own colours are at distance 0.
    min_component, max_hole : float
        See :func:`clean_mask`.

    Returns
    -------
    (H, W) bool ndarray
    """
    threshold = _as_number(threshold, "threshold", lo=0)
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
