"""Which views structure from motion starts from and which it registers next.

:func:`choose_initial_pair` picks the two views the reconstruction starts from (many shared tracks, a wide
enough baseline; :func:`covisibility` counts the shared tracks). After that comes next-best-view: each
strategy scores every view from what the growing model knows (which views are registered, in which order,
and which triangulated points each view sees); :func:`next_view` then takes the best-scoring view among
those that see enough points to be registered (``min_inliers`` of :func:`labutils.sfm.incremental_sfm`).
The strategies:

- ``'most_points'`` — the number of triangulated points the view sees (Snavely et al., "Photo tourism", 2006):
  the more 2D–3D correspondences, the more PnP has to go on. The pipeline's default.
- ``'pyramid'`` — the visibility-pyramid score of those points (Schönberger & Frahm, "Structure-from-Motion
  Revisited", CVPR 2016, Sec. 4.2): points spread over the whole image fix a pose better than as many points
  in one corner (:func:`pyramid_score`).
- ``'sequential'`` — the input order, as for a video or a turntable: the first view after the last one
  registered (cyclically) that can be registered.

A strategy is a function ``scores(tracks, visible, registered, order) -> (V,)`` (higher is better); a callable
with that signature can be passed to :func:`labutils.sfm.incremental_sfm` as ``view_selection`` too.

:func:`pose_covariance` gives what the scores stand in for: how precisely a view's pose would be determined by
the points it sees (the Cramér–Rao bound of PnP), which can be computed only once the pose is known.
"""
import warnings

import numpy as np
from numpy.typing import ArrayLike

from ..core.validation import as_array, as_calibration, as_count, as_mask, as_points, as_tracks
from ..pose.pnp import pose_covariance  # noqa: F401  (re-exported: what the scores stand in for; defined beside pose_jacobian)
from .initial_pair import two_view_reconstruction

STRATEGIES = ("most_points", "pyramid", "sequential")
PYRAMID_LEVELS = 6          # as COLMAP (kNumPoint3DVisibilityPyramidLevels)


def pyramid_score(x: ArrayLike, extent: ArrayLike, levels: int = PYRAMID_LEVELS) -> float:
    """Visibility-pyramid score of the points ``x`` seen in an image (Schönberger & Frahm 2016, Sec. 4.2).

    Level ``l = 1 … L`` divides the image into ``K_l × K_l`` cells, ``K_l = 2^l``; a cell is *full* when at least
    one point falls in it; the score is ``Σ_l K_l · (number of full cells at level l)``. A point adds to the
    score only where it fills an empty cell, and a coarse cell weighs less than the fine cells it holds, so
    well-spread points score higher than as many points clustered together. The largest possible score is
    ``Σ_l K_l³``. (COLMAP's code weighs a full cell by ``K_l²`` instead.)

    Parameters
    ----------
    x : (N, 2) array_like
        Pixels (N may be 0).
    extent : (2,) or (4,) array_like
        The image size ``(width, height)``, or a box ``(x_min, y_min, x_max, y_max)``; points outside count in
        the border cells.
    levels : int

    Returns
    -------
    float

    Examples
    --------
    >>> pyramid_score([[10, 10]], (100, 100), levels=2)                     # one cell at each level: 2 + 4
    6.0
    >>> pyramid_score([[10, 10], [90, 90]], (100, 100), levels=2), pyramid_score([[10, 10], [12, 12]], (100, 100), 2)
    (12.0, 6.0)
    """
    x = as_array(x, "x", "(N, 2)")
    x = np.zeros((0, 2)) if x.size == 0 else as_points(x, "x")
    box = _as_extent(extent)
    levels = as_count(levels, "levels", 1)
    return float(_pyramid(x[None], np.ones((1, len(x)), bool), box[None], levels)[0])


def _as_extent(extent, name="extent"):
    e = as_array(extent, name, "(2,) or (4,)")
    if e.shape == (2,):
        e = np.array([0.0, 0.0, e[0], e[1]])
    if e.shape != (4,) or not np.all(np.isfinite(e)) or not (e[2] > e[0] and e[3] > e[1]):
        raise ValueError(f"{name} must be (width, height) or a box (x_min, y_min, x_max, y_max) with a positive "
                         f"width and height; got {np.asarray(extent).tolist()}")
    return e


def _pyramid(x, mask, boxes, levels):
    """(V,) scores of the points ``x`` (V, T, 2) where ``mask`` (V, T), each view in its box (V, 4)."""
    V = x.shape[0]
    n = 2 ** levels
    v, k = np.nonzero(mask)
    b = boxes[v]
    cx = np.clip(np.floor(n * (x[v, k, 0] - b[:, 0]) / (b[:, 2] - b[:, 0])), 0, n - 1).astype(np.int64)
    cy = np.clip(np.floor(n * (x[v, k, 1] - b[:, 1]) / (b[:, 3] - b[:, 1])), 0, n - 1).astype(np.int64)
    score = np.zeros(V)
    for level in range(1, levels + 1):
        shift = levels - level
        cell = (v * n + (cy >> shift)) * n + (cx >> shift)     # a cell id unique within the view
        full = np.unique(cell) // (n * n)                        # the view of each full cell
        score += 2 ** level * np.bincount(full, minlength=V)
    return score


def observation_extent(tracks: ArrayLike) -> np.ndarray:
    """(V, 4) box ``(x_min, y_min, x_max, y_max)`` of each view's observations: the image when its size is unknown.

    >>> x = np.array([[[1.0, 2.0], [5.0, 9.0]]])
    >>> observation_extent(x)
    array([[1., 2., 5., 9.]])
    """
    tracks = as_tracks(tracks)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)            # a view without observations: 'All-NaN slice'
        lo, hi = np.nanmin(tracks, axis=1), np.nanmax(tracks, axis=1)
    box = np.concatenate([lo, hi], axis=1)
    flat = ~(box[:, 2] > box[:, 0]) | ~(box[:, 3] > box[:, 1])            # 0 or 1 observations, or a line
    box[flat] = np.nan_to_num(box[flat]) + [0.0, 0.0, 1.0, 1.0]
    return box


def _check(tracks, visible, registered, order):
    tracks = as_tracks(tracks)
    V, T = tracks.shape[:2]
    vis = as_mask(visible, "visible", (V, T), like="tracks")
    reg = as_mask(registered, "registered", (V,), like="tracks")
    order = [int(v) for v in order]
    if any(not 0 <= v < V for v in order):
        raise ValueError(f"order must list views in 0..{V - 1}; got {order}")
    return tracks, vis.astype(bool) & np.all(np.isfinite(tracks), axis=-1), reg.astype(bool), order


def most_points_scores(tracks: ArrayLike, visible: ArrayLike, registered: ArrayLike, order=()) -> np.ndarray:
    """(V,) how many triangulated points each view sees (``visible.sum(1)``): the ``'most_points'`` strategy.

    >>> most_points_scores(np.zeros((2, 3, 2)), [[1, 1, 0], [1, 0, 0]], [False, False])
    array([2., 1.])
    """
    _, vis, _, _ = _check(tracks, visible, registered, order)
    return vis.sum(1).astype(float)


def pyramid_scores(tracks: ArrayLike, visible: ArrayLike, registered: ArrayLike, order=(), *,
                   levels: int = PYRAMID_LEVELS, extent: ArrayLike = None) -> np.ndarray:
    """(V,) visibility-pyramid score (:func:`pyramid_score`) of the triangulated points each view sees.

    Parameters
    ----------
    tracks : (V, T, 2) array_like
    visible : (V, T) bool array_like
        The observations of triangulated points (the candidates' 2D–3D correspondences).
    registered : (V,) bool array_like
    order : sequence of int
        Not used (the common signature of a strategy).
    levels : int
    extent : (2,) or (V, 4) array_like, optional
        The image size, or one box per view; default :func:`observation_extent` (the box of all of each view's
        observations, triangulated or not).

    Examples
    --------
    >>> x = np.array([[[0.0, 0], [100, 100], [10, 10]], [[0.0, 0], [100, 100], [90, 90]]])
    >>> pyramid_scores(x, [[1, 0, 1], [1, 0, 1]], [False, False], levels=2, extent=(100, 100))
    array([ 6., 12.])
    """
    tracks, vis, _, _ = _check(tracks, visible, registered, order)
    V = tracks.shape[0]
    levels = as_count(levels, "levels", 1)
    if extent is None:
        boxes = observation_extent(tracks)
    elif np.shape(extent) in ((2,), (4,)):
        boxes = np.repeat(_as_extent(extent)[None], V, axis=0)
    else:
        e = as_array(extent, "extent", f"(2,), (4,) or ({V}, 4)")
        if e.shape != (V, 4):
            raise ValueError(f"extent must be (width, height), a box (4,), or one box per view ({V}, 4); got {e.shape}")
        boxes = np.stack([_as_extent(b, f"extent[{k}]") for k, b in enumerate(e)])
    return _pyramid(np.nan_to_num(tracks), vis, boxes, levels)


def sequential_scores(tracks: ArrayLike, visible: ArrayLike, registered: ArrayLike, order=()) -> np.ndarray:
    """(V,) the input order: highest for the first view after the last registered one, going round cyclically.

    Only the views that see triangulated points compete (:func:`next_view` skips the others),
    so a view that cannot be registered yet is passed over until it can.

    >>> sequential_scores(np.zeros((5, 1, 2)), np.ones((5, 1)), [True, True, False, False, False], [0, 1])
    array([-4., -5., -1., -2., -3.])
    """
    _, _, _, order = _check(tracks, visible, registered, order)
    V = np.shape(registered)[0]
    last = order[-1] if order else -1
    return -((np.arange(V) - last - 1) % V + 1).astype(float)


SCORES = {"most_points": most_points_scores, "pyramid": pyramid_scores, "sequential": sequential_scores}


def as_strategy(view_selection):
    """The scoring function of a strategy name (:data:`STRATEGIES`) or of a callable, or ``ValueError``.

    >>> as_strategy("pyramid") is pyramid_scores
    True
    """
    if callable(view_selection):
        return view_selection
    if view_selection in SCORES:
        return SCORES[view_selection]
    raise ValueError(f"view_selection must be one of {STRATEGIES} or a function scores(tracks, visible, registered, "
                     f"order) -> (V,); got {view_selection!r}")


def next_view(visible_points, registered, skip=(), scores=None, min_points=1):
    """The view to register next: the best-scoring unregistered view that sees enough triangulated points.

    Parameters
    ----------
    visible_points : (V,) int array_like
        For each view, how many triangulated points it observes.
    registered : (V,) bool array_like
    skip : collection of int
        Views (indices in ``0..V-1``) not to propose now (e.g. whose registration just failed).
    scores : (V,) array_like, optional
        The strategy's score of each view, higher is better, no NaN (:func:`as_scores`); default
        ``visible_points`` (the view that sees the most points).
    min_points : int
        Fewest triangulated points a candidate must see (PnP needs them: ``min_inliers``).

    Returns
    -------
    int or None
        None when no candidate is left. Ties go to the lowest view.

    >>> next_view([5, 9, 7, 3], [False, True, False, False])
    2
    >>> next_view([5, 9, 7, 3], [False, True, False, False], scores=[0, 0, 1, 2], min_points=4)
    2
    """
    counts = as_array(visible_points, "visible_points", "(V,)")
    if counts.ndim != 1:
        raise ValueError(f"visible_points must have shape (V,) (one count per view); got shape {counts.shape}")
    if not np.all(counts == np.round(counts)) or np.any(counts < 0):
        raise ValueError(f"visible_points must be counts, integers >= 0 (one per view); got {counts.tolist()}")
    min_points = as_count(min_points, "min_points", 1)
    V = len(counts)
    registered = np.asarray(registered)
    if registered.shape != (V,):
        raise ValueError(f"registered must have shape ({V},) like visible_points; got shape {registered.shape}")
    skip = list(skip)
    bad = [w for w in skip if not (isinstance(w, (int, np.integer)) and 0 <= w < V)]
    if bad:
        raise ValueError(f"skip must hold view indices, integers in 0..{V - 1}; got {bad[0]!r}")
    s = counts if scores is None else as_scores(scores, V)
    ok = (counts >= max(min_points, 1)) & ~registered.astype(bool)
    ok[skip] = False
    if not ok.any():
        return None
    return int(np.flatnonzero(ok)[np.argmax(s[ok])])


def as_scores(scores: ArrayLike, n_views: int) -> np.ndarray:
    """A strategy's output checked: ``(n_views,)`` numbers, no NaN (``ValueError`` naming ``view_selection``).

    >>> as_scores([1, 2], 3)
    Traceback (most recent call last):
    ...
    ValueError: view_selection must return one score per view, shape (3,); got shape (2,)
    """
    s = as_array(scores, "the scores of view_selection", f"({n_views},)")
    if s.shape != (n_views,):
        raise ValueError(f"view_selection must return one score per view, shape ({n_views},); got shape {s.shape}")
    if np.isnan(s).any():
        raise ValueError("view_selection returned NaN scores")
    return s




# ---------------------------------------------------------------------------------------------
# The initial pair
# ---------------------------------------------------------------------------------------------

def covisibility(tracks: ArrayLike) -> np.ndarray:
    """(V, V) int: how many tracks each pair of views shares (the diagonal: tracks seen by each view).

    ``tracks`` is a ``(V, T, 2)`` array, NaN where unseen, V >= 1 (:func:`labutils.core.validation.as_tracks`).

    >>> x = np.full((3, 2, 2), np.nan); x[:, 0] = 1.0; x[:2, 1] = 2.0
    >>> covisibility(x)
    array([[2, 2, 1],
           [2, 2, 1],
           [1, 1, 1]])
    """
    seen = np.all(np.isfinite(as_tracks(tracks, "tracks", min_views=1)), axis=-1).astype(np.int64)
    return seen @ seen.T


def choose_initial_pair(tracks: ArrayLike, K: ArrayLike, *, rng: np.random.Generator, n_candidates=6, min_tracks=30,
                        min_angle_deg=3.0, threshold_px=4.0,
                        confidence=0.999):
    """Pick the initial pair: many shared tracks and a wide enough baseline.

    The ``n_candidates`` pairs sharing the most tracks (at least ``min_tracks``) are each reconstructed
    with :func:`two_view_reconstruction`. Among those whose median triangulation angle reaches
    ``min_angle_deg`` the pair with the largest ``points × median angle`` wins (more points, and each
    better determined: a point's depth error falls about as 1 / angle); if none reaches it, the pair with
    the widest median angle.

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        NaN where unseen.
    K : (3, 3) or (V, 3, 3) array_like
    rng : numpy.random.Generator

    Returns
    -------
    best : dict
        ``i, j`` (views), ``R, t`` (view j relative to view i), ``track`` (indices of the accepted tracks),
        ``X`` (their points in view i's frame), ``median_angle``.
    table : list of dict
        One row per candidate, most shared tracks first: ``i, j, shared, points, median_angle`` (and
        ``failed``, the reason, when the two-view reconstruction failed).

    Raises
    ------
    ValueError
        If no pair of views shares ``min_tracks`` tracks.
    """
    tracks = as_tracks(tracks, min_views=2)
    Ks = as_calibration(K, "K", n_views=tracks.shape[0])
    cov = covisibility(tracks)
    i, j = np.triu_indices(len(cov), 1)
    keep = cov[i, j] >= max(min_tracks, 8)
    if not keep.any():
        raise ValueError(f"no pair of views shares {max(min_tracks, 8)} tracks: cannot start a reconstruction "
                         f"(the best pair shares {cov[i, j].max()})")
    i, j = i[keep], j[keep]
    order = np.argsort(-cov[i, j], kind="stable")[:n_candidates]
    table, results = [], []
    for a, b in zip(i[order], j[order]):
        x1, x2, idx = shared_observations(tracks, a, b)
        try:
            R, t, X, med = two_view_reconstruction(x1, x2, Ks[a], Ks[b], rng=rng, threshold_px=threshold_px,
                                                   confidence=confidence)
        except ValueError as exc:          # e.g. no baseline: no pose puts the points in front
            table.append(dict(i=int(a), j=int(b), shared=int(len(idx)), points=0, median_angle=0.0, failed=str(exc)))
            results.append(None)
            continue
        ok = np.isfinite(X[:, 0])
        table.append(dict(i=int(a), j=int(b), shared=int(len(idx)), points=int(ok.sum()), median_angle=med))
        results.append(dict(i=int(a), j=int(b), R=R, t=t, track=idx[ok], X=X[ok], median_angle=med))
    usable = [k for k, r in enumerate(results) if r is not None and table[k]["points"] >= 8]
    if not usable:
        raise ValueError("no candidate pair gave a two-view reconstruction: "
                         + "; ".join(f"({r['i']}, {r['j']}): {r.get('failed', 'too few points')}" for r in table))
    wide = [k for k in usable if table[k]["median_angle"] >= min_angle_deg]
    if wide:
        best = max(wide, key=lambda k: (table[k]["points"] * table[k]["median_angle"], -k))
    else:
        best = max(usable, key=lambda k: (table[k]["median_angle"], -k))
    return results[best], table


def shared_observations(tracks, i, j):
    """The pixels ``(N, 2)`` of views i and j of the tracks both see, and those tracks' indices ``(N,)``."""
    both = np.all(np.isfinite(tracks[i]), axis=-1) & np.all(np.isfinite(tracks[j]), axis=-1)
    idx = np.flatnonzero(both)
    return tracks[i, idx], tracks[j, idx], idx
