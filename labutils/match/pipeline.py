"""The whole matching pipeline over a list of pairs, with a table of each stage's survivors, and its tracks."""
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..core.validation import as_array, as_calibration, as_positive, as_rng
from .descriptors import Features, match_descriptors
from .geometric import epipolar_filter
from .tracks import build_tracks, track_pixels, verify_tracks

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
    as_rng(rng)
    features = _as_features(features)
    V = len(features)
    pairs = _as_pairs(pairs, V)
    Ks = None if K is None else as_calibration(K, "K", n_views=V, like_name="features")
    matches, geometry, table = {}, {}, []
    seconds = {"matching": 0.0, "epipolar": 0.0}
    for n, (i, j) in enumerate(pairs.tolist()):
        t0 = time.perf_counter()
        dm = match_descriptors(features[i].descriptors, features[j].descriptors, ratio=ratio,
                               cross_check=cross_check)
        m = dm.matches
        t1 = time.perf_counter()
        row = dict(i=i, j=j, features_i=len(features[i]), features_j=len(features[j]), ratio=dm.n_ratio,
                   mutual=dm.n_mutual, epipolar=0, behind=0, note="")
        if len(m) < max(min_inliers, 8):
            row["note"] = f"fewer than {max(min_inliers, 8)} matches"
        else:
            x1, x2 = features[i].xy[m[:, 0]], features[j].xy[m[:, 1]]
            try:
                g = epipolar_filter(x1, x2, rng=rng, threshold_px=threshold_px, confidence=confidence,
                                    ranking=dm.distance_ratio if guided else None, max_iter=max_iter,
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


def _as_features(features):
    """``features`` as a list of :class:`Features` (one per view), or ``ValueError`` naming the first that is not.

    >>> _as_features([np.zeros((3, 2))])
    Traceback (most recent call last):
    ...
    ValueError: features must be a sequence of Features (from detect_features), one per view; features[0] is a ndarray
    """
    if isinstance(features, Features) or not isinstance(features, Sequence):
        raise ValueError(f"features must be a sequence of Features (from detect_features), one per view; "
                         f"got a {type(features).__name__}")
    for v, f in enumerate(features):
        if not isinstance(f, Features):
            raise ValueError(f"features must be a sequence of Features (from detect_features), one per view; "
                             f"features[{v}] is a {type(f).__name__}")
    return list(features)


def _as_pairs(pairs, n_views):
    """``pairs`` as a ``(P, 2)`` int array of two different views in ``0..n_views - 1`` (P may be 0), or ValueError.

    >>> _as_pairs([[0, 1], [2, 1]], 3).tolist()
    [[0, 1], [2, 1]]
    >>> _as_pairs([[0, 1, 2], [1, 2, 0]], 3)
    Traceback (most recent call last):
    ...
    ValueError: pairs must have shape (P, 2) (two view indices per row); got shape (2, 3) — transposed?
    """
    p = as_array(pairs, "pairs", "(P, 2)")
    if p.ndim != 2 or p.shape[1] != 2:
        hint = " — transposed?" if p.ndim == 2 and p.shape[0] == 2 else ""
        raise ValueError(f"pairs must have shape (P, 2) (two view indices per row); got shape {p.shape}{hint}")
    with np.errstate(invalid="ignore"):
        ok = (p == np.round(p)) & (p >= 0) & (p < n_views)
    bad = np.flatnonzero(~ok.all(axis=1) | (p[:, 0] == p[:, 1]))
    if bad.size:
        raise ValueError(f"pairs must hold two different integer view indices in 0..{n_views - 1}; "
                         f"row {bad[0]} is {p[bad[0]].tolist()}")
    return p.astype(np.int64)


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
        Threshold of :func:`verify_tracks`, > 0 (None: no check).

    Returns
    -------
    TrackResult
    """
    if verify_px is not None:
        verify_px = as_positive(verify_px, "verify_px")
    features = _as_features(features)
    ids, n_conf = build_tracks(result.matches, [len(f) for f in features], return_conflicts=True)
    x = track_pixels(ids, [f.xy for f in features])
    n_cand = ids.shape[1] + n_conf
    n_bad = 0
    if verify_px is not None:
        keep = verify_tracks(x, result.fundamental_matrices(), verify_px)
        n_bad = int((~keep).sum())
        ids, x = ids[:, keep], x[:, keep]
    return TrackResult(x=x, features=ids, n_candidates=n_cand, n_conflicts=n_conf, n_inconsistent=n_bad)
