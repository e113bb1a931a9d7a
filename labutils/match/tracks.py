"""Tracks: pairwise matches chained across views by union-find, with contradictory tracks rejected."""
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..core.validation import as_positive, as_tracks
from ..twoview.epipolar import sampson_distance

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
    if tracks.size and (tracks.dtype.kind not in "iuf" or not np.array_equal(tracks, np.round(tracks))):
        raise ValueError("tracks must hold integer feature indices (-1 where unseen)")
    tracks = tracks.astype(int)
    out = np.full(tracks.shape + (2,), np.nan)
    for v in range(tracks.shape[0]):
        seen = tracks[v] >= 0
        xv = np.asarray(xy[v], float)
        if xv.ndim != 2 or xv.shape[1] != 2:
            raise ValueError(f"xy[{v}] must have shape (N, 2) (the keypoints of view {v}); got {xv.shape}")
        if seen.any() and tracks[v, seen].max() >= len(xv):
            raise ValueError(f"tracks[{v}] holds feature index {tracks[v, seen].max()}, but xy[{v}] has only "
                             f"{len(xv)} keypoints (tracks and xy must come from the same features)")
        out[v, seen] = xv[tracks[v, seen]]
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
    threshold_px = as_positive(threshold_px, "threshold_px")
    seen = np.isfinite(x[..., 0])
    keep = np.ones(x.shape[1], bool)
    V = x.shape[0]
    for key in geometry:
        ok = np.shape(key) == (2,) and all(isinstance(k, (int, np.integer)) and 0 <= k < V for k in key)
        if not ok:
            raise ValueError(f"geometry keys must be pairs of views (i, j) with 0 <= i, j < {V} (the views of x); "
                             f"got {key!r}")
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
    x = as_tracks(x, "x")
    L = np.isfinite(x[..., 0]).sum(0)
    return dict(tracks=int(x.shape[1]), observations=int(L.sum()), mean_length=float(L.mean()) if L.size else 0.0,
                median_length=float(np.median(L)) if L.size else 0.0, max_length=int(L.max(initial=0)),
                length_counts=np.bincount(L, minlength=x.shape[0] + 1))
