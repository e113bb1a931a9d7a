"""Silhouettes that check themselves: one colour threshold for all views, chosen by how well the views' silhouettes
agree once carved, and the views where the segmentation is unsure."""
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ...core.validation import as_array
from .silhouettes import BackgroundModel, _as_number, background_model, clean_mask, colour_distance
from .surface import silhouette_ious, surface_mesh
from .voxels import VoxelGrid, _as_cameras, _carve_maps, bounding_box_from_silhouettes, signed_distance_map

__all__ = ["threshold_ladder", "choose_threshold", "Silhouettes", "segment_views", "unsure_views", "unsure_warning",
           "MIN_AGREEMENT", "refine_mask"]

MIN_AGREEMENT = 0.9
"""A view whose silhouette and the carved model's overlap less than this (IoU) is flagged unsure: the workbook's
bound for a model that explains its masks."""


BAND = 0.05
"""Half-width of the band around a silhouette's edge that :func:`refine_mask` decides anew, as a fraction of the
silhouette's equivalent radius ``sqrt(area / π)``: the size of the errors a colour threshold makes at a shaded edge."""


def refine_mask(image: ArrayLike, mask: ArrayLike, *, iterations: int = 3) -> np.ndarray:
    """A silhouette refined with spatial coherence: OpenCV's GrabCut (Rother et al., SIGGRAPH 2004) started from
    ``mask``: inside it (less a band) is object, far outside background, the band around its edge is decided by
    colour models of this image with a smoothness term, which a per-pixel threshold lacks.

    Parameters
    ----------
    image : (H, W, 3) uint8 RGB
    mask : (H, W) bool
        The starting silhouette (non-empty).
    iterations : int

    Returns
    -------
    (H, W) bool

    Examples
    --------
    >>> img = np.zeros((60, 80, 3), np.uint8); img[20:40, 30:50] = 200
    >>> truth = img[:, :, 0] > 0
    >>> m = np.zeros((60, 80), bool); m[22:40, 30:48] = True          # a threshold that missed two edges
    >>> from labutils.model.carving import mask_iou
    >>> round(mask_iou(m, truth), 2), bool(mask_iou(refine_mask(img, m), truth) > mask_iou(m, truth))
    (0.81, True)
    """
    img = np.asarray(image)
    m = np.asarray(mask)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image must be an (H, W, 3) uint8 array; got {img.dtype} {img.shape}")
    if m.dtype != bool or m.shape != img.shape[:2]:
        raise ValueError(f"mask must be an (H, W) bool array of the image's size {img.shape[:2]}; got {m.dtype} "
                         f"{m.shape}")
    if not m.any():
        raise ValueError("mask is empty: nothing to refine")
    iterations = _as_number(iterations, "iterations", lo=1, integer=True)
    band = max(1, int(round(BAND * np.sqrt(m.sum() / np.pi))))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1))
    m8 = m.astype(np.uint8)
    inner, outer = cv2.erode(m8, kernel).astype(bool), cv2.dilate(m8, kernel).astype(bool)
    gc = np.full(m.shape, cv2.GC_BGD, np.uint8)
    gc[outer] = cv2.GC_PR_BGD
    gc[m] = cv2.GC_PR_FGD
    gc[inner] = cv2.GC_FGD
    if not inner.any() or outer.all():
        return m.copy()
    cv2.grabCut(np.ascontiguousarray(img[:, :, ::-1]), gc, None, np.zeros((1, 65)), np.zeros((1, 65)), iterations,
                cv2.GC_INIT_WITH_MASK)
    return (gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)


def _as_distance_map(d, name):
    """A finite real (H, W) colour-distance map, or ``ValueError`` naming it."""
    a = as_array(d, name, "(H, W)")
    if a.ndim != 2 or a.size == 0 or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite (H, W) map of colour distances; got shape {a.shape}"
                         + ("" if a.ndim != 2 or a.size == 0 else " with NaN or inf"))
    return a


def threshold_ladder(threshold: float, steps: int = 11) -> np.ndarray:
    """Candidate thresholds ``threshold · 2^(k/2)``, k = 0 … steps - 1: from the border's false-alarm threshold
    (the most inclusive one that makes sense) up to 32 times it, in steps of √2.

    >>> threshold_ladder(2.0, 5).round(3).tolist()
    [2.0, 2.828, 4.0, 5.657, 8.0]
    """
    threshold = _as_number(threshold, "threshold", lo=0, open_lo=True)
    steps = _as_number(steps, "steps", lo=1, integer=True)
    return threshold * 2.0 ** (np.arange(steps) / 2)


def _agreement(masks, P, grid, every):
    """Carve ``grid`` from ``masks`` and return the IoU of the surface's silhouette with every ``every``-th mask
    (all -1 if nothing is left)."""
    carving = _carve_maps([signed_distance_map(m) for m in masks], P, grid)
    if not carving.occupied.any():
        return np.full(len(masks[::every]), -1.0)
    V, F, _ = surface_mesh(carving)
    return silhouette_ious(V, F, masks[::every], P[::every])


def choose_threshold(distances: Sequence[ArrayLike], P: ArrayLike, candidates: Sequence[float], *, n: int = 40,
                     every: int = 1, min_component: float = 0.02, max_hole: float = 0.002
                     ) -> tuple[float, np.ndarray]:
    """Pick the colour threshold whose silhouettes agree best with each other (no ground truth needed).

    With exact cameras, the visual hull of perfect silhouettes reprojects exactly onto each of them; a mask that
    misses part of the object carves it away in every other view, and one with extra background is carved away
    by the others. So for each candidate threshold we carve a coarse grid (``n`` voxels along the box's longest
    side), take its surface and score the silhouettes' agreement: the IoU between the surface's silhouette and the
    mask, in every view scored. The threshold with the highest median plus minimum wins (every view should agree,
    not only most; the lowest among equals: a piece missing from a mask costs the model more than a piece of
    background added). Candidates are tried in increasing order; once one leaves nothing after carving, the higher
    ones (smaller masks) are not tried.

    Parameters
    ----------
    distances : sequence of (H, W) float arrays
        :func:`colour_distance` of each view.
    P : (V, 3, 4) array_like
    candidates : sequence of float
        E.g. :func:`threshold_ladder` of the background model's threshold.
    n : int
    every : int
        Score every ``every``-th view only (all views are carved).

    Returns
    -------
    best : float
    scores : (len(candidates), 2) ndarray
        Per candidate (in increasing order): the median and the minimum IoU over the views scored; -1 when
        nothing is left after carving (or a lower candidate left nothing: not tried).

    Raises
    ------
    ValueError
        If no candidate leaves a non-empty carving.
    """
    P = _as_cameras(P)
    distances = [_as_distance_map(d, f"distances[{i}]") for i, d in enumerate(distances)]
    if len(distances) != len(P):
        raise ValueError(f"distances has {len(distances)} maps for {len(P)} cameras: one per view")
    candidates = sorted(_as_number(c, "candidates", lo=0) for c in candidates)
    if not candidates:
        raise ValueError("candidates is empty: give at least one threshold")
    n = _as_number(n, "n", lo=4, integer=True)
    every = _as_number(every, "every", lo=1, integer=True)
    scores = np.full((len(candidates), 2), -1.0)
    grid = None
    for k, c in enumerate(candidates):
        masks = [clean_mask(d > c, min_component=min_component, max_hole=max_hole) for d in distances]
        if not all(m.any() for m in masks):
            break
        if grid is None:                   # the most inclusive non-empty masks give the largest box
            grid = VoxelGrid.from_box(bounding_box_from_silhouettes(masks, P), n)
        ious = _agreement(masks, P, grid, every)
        scores[k] = np.median(ious), ious.min()
        if scores[k, 0] < 0:
            break
    if np.all(scores[:, 0] < 0):
        raise ValueError("every candidate threshold carves every voxel away: the masks and cameras disagree")
    return candidates[int(np.argmax(scores.sum(axis=1)))], scores


@dataclass
class Silhouettes:
    """What :func:`segment_views` returns.

    Attributes
    ----------
    masks : list of (H, W) bool
        One silhouette per view, at the chosen threshold.
    threshold : float
        The chosen colour threshold (Mahalanobis distance to the background's colours).
    candidates : (C,) ndarray
        The thresholds tried (:func:`threshold_ladder`).
    scores : (C, 2) ndarray
        Per candidate: median and minimum agreement IoU (see :func:`choose_threshold`) on the subsampled images.
    agreement : (V,) ndarray or None
        Per view, at the chosen threshold: the IoU of the carved model's silhouette (a grid of ``n_check`` voxels
        along the box's longest side) with the mask; None when not checked.
    unsure : (U,) int ndarray or None
        The views whose agreement is below :data:`MIN_AGREEMENT` (:func:`unsure_views`); None when not checked.
    model : BackgroundModel
    refined : bool
        True when the check found unsure views and every mask was refined by :func:`refine_mask` (kept because the
        views then agreed better).
    """

    masks: list = field(repr=False)
    threshold: float
    candidates: np.ndarray
    scores: np.ndarray
    agreement: np.ndarray
    unsure: np.ndarray
    model: BackgroundModel = field(repr=False)
    refined: bool = False

    def warning(self, names: Sequence[str] | None = None) -> str | None:
        """One line naming the unsure views (see :func:`unsure_warning`), or None when none is (or not checked)."""
        return None if self.agreement is None else unsure_warning(self.agreement, names)


def unsure_views(agreement: ArrayLike, min_agreement: float = MIN_AGREEMENT) -> np.ndarray:
    """Indices of the views whose silhouette agrees with the carved model less than ``min_agreement`` (IoU).

    >>> unsure_views([0.95, 0.7, 0.99, 0.89]).tolist()
    [1, 3]
    """
    agreement = np.asarray(agreement, dtype=float)
    if agreement.ndim != 1:
        raise ValueError(f"agreement must be a (V,) array of IoUs; got shape {agreement.shape}")
    return np.flatnonzero(~(agreement >= _as_number(min_agreement, "min_agreement", lo=0, hi=1)))


def unsure_warning(agreement: ArrayLike, names: Sequence[str] | None = None,
                   min_agreement: float = MIN_AGREEMENT) -> str | None:
    """One line naming the views whose silhouette the carved model explains poorly, or None when there is none.

    >>> print(unsure_warning([0.95, 0.7, 0.99], names=["a.png", "b.png", "c.png"]))    # doctest: +NORMALIZE_WHITESPACE
    unsure silhouettes in 1 of 3 views: b.png (IoU 0.70 with the carved model, below 0.9): object and background
    colours close there, or a wrong camera
    """
    agreement = np.asarray(agreement, dtype=float)
    bad = unsure_views(agreement, min_agreement)
    if bad.size == 0:
        return None
    names = [str(i) for i in range(len(agreement))] if names is None else [str(x) for x in names]
    shown = ", ".join(f"{names[i]} (IoU {agreement[i]:.2f}" + (" with the carved model, below "
                                                                 f"{min_agreement:g})" if k == 0 else ")")
                      for k, i in enumerate(bad[np.argsort(agreement[bad])][:4]))
    more = f" and {bad.size - 4} more" if bad.size > 4 else ""
    return (f"unsure silhouettes in {bad.size} of {len(agreement)} views: {shown}{more}: object and background "
            "colours close there, or a wrong camera")


def segment_views(images: Sequence[ArrayLike], P: ArrayLike, *, model: BackgroundModel | None = None, n: int = 40,
                  n_check: int = 80, check: bool = True, refine: bool = True, every: int = 1, steps: int = 11,
                  min_component: float = 0.02, max_hole: float = 0.002) -> Silhouettes:
    """Silhouettes of calibrated views of one object, with a threshold from the data and a check of each view.

    1. The background's colours from the image borders (:func:`background_model`), unless ``model`` is given; each
       pixel's distance to them (:func:`colour_distance`).
    2. Candidate thresholds from the border's own false-alarm threshold upwards (:func:`threshold_ladder`); the one
       whose silhouettes agree best after carving a coarse grid wins (:func:`choose_threshold`, on images
       subsampled to about 8 pixels per voxel).
    3. The check: per view, the agreement (IoU) of its mask with the model carved from all masks on a finer grid
       (``n_check``; masks subsampled like the images in 2); a view below :data:`MIN_AGREEMENT` is unsure: its mask
       and the others contradict each other.
    4. With unsure views, every mask is refined by :func:`refine_mask` (GrabCut from the mask: the edges decided
       again with the image's own colour models and spatial coherence) and checked again; kept if the views then
       agree better (median plus minimum IoU).

    Parameters
    ----------
    images : sequence of (H, W, 3) uint8 RGB
    P : (V, 3, 4) array_like
    model : BackgroundModel, optional
    n : int
        Voxels along the longest side of the coarse grids that choose the threshold.
    n_check : int
        Voxels along the longest side of the grid that checks the chosen masks.
    check : bool
        False: skip the check (``agreement`` and ``unsure`` are None), e.g. when the caller carves a finer model and
        checks its silhouettes itself (:func:`unsure_warning`).
    refine : bool
        False: no step 4.
    every : int
        Score every ``every``-th view while choosing the threshold (the check covers every view).
    steps : int
        Candidates on the ladder.

    Returns
    -------
    Silhouettes

    Examples
    --------
    >>> from labutils.model.carving import mask_iou
    >>> from labutils.model.synthetic import make_snowman
    >>> s = make_snowman(8, rng=np.random.default_rng(0), image_size=(80, 60), f=105.0, colour=(200, 200, 200),
    ...                  background=(10, 10, 10))                 # a light-grey object on a black background
    >>> r = segment_views(s.images, s.P, n=24)
    >>> min(mask_iou(m, t) for m, t in zip(r.masks, s.masks)) > 0.97, r.unsure.tolist()
    (True, [])
    """
    P = _as_cameras(P)
    images = list(images)
    if len(images) != len(P):
        raise ValueError(f"images has {len(images)} views for the {len(P)} cameras of P: one per view")
    if model is None:
        model = background_model(images)
    elif not isinstance(model, BackgroundModel):
        raise ValueError(f"model must be a BackgroundModel (from background_model); got {type(model).__name__}")
    n = _as_number(n, "n", lo=4, integer=True)
    n_check = _as_number(n_check, "n_check", lo=4, integer=True)
    for name, flag in (("check", check), ("refine", refine)):
        if not isinstance(flag, bool | np.bool_):
            raise ValueError(f"{name} must be True or False; got {flag!r}")
    distances = [colour_distance(im, model) for im in images]
    candidates = threshold_ladder(model.threshold, steps)
    # the choice works on images subsampled to about 8 pixels per coarse voxel across: finer pixels change nothing
    stride = max(1, int(np.ceil(max(max(d.shape) for d in distances) / (8 * n))))
    small = [d[::stride, ::stride] for d in distances]
    P_small = np.diag([1.0 / stride, 1.0 / stride, 1.0]) @ P          # pixel (r, c) of the subsampled image
    best, scores = choose_threshold(small, P_small, candidates, n=n, every=every, min_component=min_component,
                                    max_hole=max_hole)
    best = float(best)

    masks = [clean_mask(d > best, min_component=min_component, max_hole=max_hole) for d in distances]
    refined_views = False
    if not check:
        return Silhouettes(masks, best, candidates, scores, None, None, model)
    small = [m[::stride, ::stride] for m in masks]
    grid = VoxelGrid.from_box(bounding_box_from_silhouettes(small, P_small), n_check)
    agreement = _agreement(small, P_small, grid, 1)
    if refine and unsure_views(agreement).size:      # 4. unsure: decide the edges again with spatial coherence
        refined = [clean_mask(refine_mask(im, m), min_component=min_component, max_hole=max_hole) if m.any() else m
                   for im, m in zip(images, masks)]
        small_r = [m[::stride, ::stride] for m in refined]
        if all(m.any() for m in small_r):
            grid_r = VoxelGrid.from_box(bounding_box_from_silhouettes(small_r, P_small), n_check)
            agreement_r = _agreement(small_r, P_small, grid_r, 1)
            if np.median(agreement_r) + agreement_r.min() > np.median(agreement) + agreement.min():
                masks, agreement, refined_views = refined, agreement_r, True
    return Silhouettes(masks, best, candidates, scores, agreement, unsure_views(agreement), model, refined_views)
