"""Self-checks of notebook 07 (matching and tracks): the ratio test, the mutual check, union-find tracks."""
from collections.abc import Callable

import numpy as np

from ..match import build_tracks, mutual_check, ratio_test
from .runner import CheckReport, run_checks

# ---------------------------------------------------------------------------------------------
# The ratio test
# ---------------------------------------------------------------------------------------------


def _random_distances(seed, n=400):
    rng = np.random.default_rng(seed)
    d1 = rng.uniform(50, 400, n)
    return np.column_stack([d1, d1 / rng.uniform(0.3, 1.0, n)])       # d2 >= d1, ratios spread over (0.3, 1)


def _as_mask(keep, n, name="ratio_test"):
    keep = np.asarray(keep)
    if keep.shape != (n,):
        if keep.ndim == 1 and keep.size < n and np.issubdtype(keep.dtype, np.integer):
            raise ValueError(f"{name} returned {keep.size} indices; return a boolean mask with one entry per row "
                             f"of dist ({n})")
        raise ValueError(f"{name} must return shape ({n},) (one bool per row of dist); it returned shape {keep.shape}")
    if keep.dtype != bool:
        raise ValueError(f"{name} must return a boolean mask; it returned dtype {keep.dtype}")
    return keep


def _diagnose_ratio(keep, dist, ratio):
    """None if ``keep`` is the ratio test's answer, else the most likely mistake."""
    keep = _as_mask(keep, len(dist))
    ref = ratio_test(dist, ratio)
    if np.array_equal(keep, ref):
        return None
    d1, d2 = dist[:, 0], dist[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        if np.array_equal(keep, d1 ** 2 < ratio * d2 ** 2):
            return (f"you compared squared distances with the ratio: Lowe's test is on distances, d1 < {ratio} d2 "
                    f"(with squares it would be d1² < {ratio ** 2:.2f} d2²)")
        if np.array_equal(keep, d1 <= ratio * d2):
            return "use a strict '<': when d1 = ratio · d2 (e.g. both distances 0, duplicate descriptors) reject"
        if not keep.any() and ref.any():
            return ("you kept nothing: d1 is the nearest distance (column 0) and d2 the second nearest (column 1), "
                    "so d2 >= d1 and the test is d1 < ratio · d2")
        if np.array_equal(keep, ~ref) or np.array_equal(keep, d1 > ratio * d2):
            return ("you kept the ambiguous matches: keep a match when its nearest neighbour is clearly closer than "
                    "the second, d1 < ratio · d2")
        if np.array_equal(keep, d1 < 0.8 * d2):
            return f"use the ratio argument ({ratio}), not a fixed 0.8"
        if np.array_equal(keep, d2 / d1 > ratio):
            return ("you inverted the ratio: d2 / d1 > ratio keeps almost everything; the test is d1 / d2 < ratio, "
                    "i.e. d1 < ratio · d2")
    return (f"{int((keep != ref).sum())} of {len(dist)} rows differ from d1 < ratio · d2 (d1 = dist[:, 0], the "
            "nearest; d2 = dist[:, 1], the second nearest)")


def check_ratio_test(func: Callable, verbose: bool = True) -> CheckReport:
    """Self-check of the exercise ``ratio_test(dist, ratio=0.8) -> keep`` (Lowe 2004, Sec. 7.1).

    Cases: a hand-made list (a clear match, an ambiguous one, duplicate descriptors at distance 0, a second
    neighbour missing), random distances with the default ratio, and another ratio.

    Examples
    --------
    >>> check_ratio_test(ratio_test, verbose=False).passed
    True
    """
    def hand(f):
        dist = np.array([[1.0, 2.0], [1.0, 1.1], [0.0, 0.0], [3.0, np.inf], [8.0, 10.0]])
        return _diagnose_ratio(f(dist.copy(), 0.8), dist, 0.8)

    def default(f):
        dist = _random_distances(1)
        return _diagnose_ratio(f(dist.copy()), dist, 0.8)

    def other(f):
        dist = _random_distances(2)
        return _diagnose_ratio(f(dist.copy(), 0.6), dist, 0.6)

    return run_checks("ratio_test", func, [
        ("hand-made: a clear match, an ambiguous one, duplicates at distance 0, no second neighbour", hand),
        ("400 random distance pairs, default ratio 0.8", default),
        ("the same with ratio = 0.6", other),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------
# The mutual check
# ---------------------------------------------------------------------------------------------

def _as_pairs(m, name="mutual_check"):
    m = np.asarray(m)
    if m.size == 0:
        return np.zeros((0, 2), np.int64)
    if m.ndim != 2 or m.shape[1] != 2:
        raise ValueError(f"{name} must return an (M, 2) array of index pairs (i, j); it returned shape {m.shape}")
    if not np.issubdtype(m.dtype, np.integer):
        raise ValueError(f"{name} must return integer indices; it returned dtype {m.dtype}")
    return m.astype(np.int64)


def _rows(m):
    return {tuple(r) for r in np.asarray(m).tolist()}


def _diagnose_mutual(got, m12, m21):
    got = _as_pairs(got)
    ref = mutual_check(m12, m21)
    if len(ref) == 0 and len(got) == 0:
        return None
    if _rows(got) == _rows(ref):
        if len(got) != len(ref):
            return "some pairs appear twice: return each mutual match once"
        if not np.array_equal(got, ref):
            return "the right pairs, but sort them by i (the index in image 1), as np.flatnonzero gives them"
        return None
    if _rows(got) == _rows(ref[:, ::-1]):
        return "your columns are swapped: each row is (i, j) with i in image 1 and j in image 2"
    if (got < 0).any():
        return ("a feature without a match (-1) slipped through: in numpy m21[-1] is the LAST entry of m21, so "
                "check m12 >= 0 before looking j up")
    one_way = np.column_stack([np.flatnonzero(m12 >= 0), m12[m12 >= 0]])
    if _rows(got) == _rows(one_way):
        return "you kept every i -> j without checking the way back: keep it only if also m21[j] == i"
    back = np.column_stack([m21[m21 >= 0], np.flatnonzero(m21 >= 0)])
    if _rows(got) == _rows(back):
        return "you kept every j -> i of m21 without checking m12: keep (i, j) only if m12[i] == j and m21[j] == i"
    missing, extra = len(_rows(ref) - _rows(got)), len(_rows(got) - _rows(ref))
    return (f"{missing} mutual pairs missing and {extra} pairs that are not mutual (keep (i, j) iff m12[i] == j and "
            "m21[j] == i)")


def _random_lists(seed, n1=300, n2=280):
    rng = np.random.default_rng(seed)
    m12 = rng.integers(0, n2, n1)
    m21 = rng.integers(0, n1, n2)
    true = rng.choice(n1, 150, replace=False)                   # 150 mutual pairs planted
    m12[true] = rng.choice(n2, 150, replace=False)
    m21[m12[true]] = true
    m12[rng.random(n1) < 0.3] = -1                              # ratio test failed
    m21[rng.random(n2) < 0.1] = -1
    return m12, m21


def check_mutual_check(func: Callable, verbose: bool = True) -> CheckReport:
    """Self-check of the exercise ``mutual_check(m12, m21) -> matches (M, 2)``.

    Cases: a hand-made example (with a feature that failed the ratio test while ``m21[-1]`` points back at
    it), random lists with planted mutual pairs, and lists without any mutual pair.

    Examples
    --------
    >>> check_mutual_check(mutual_check, verbose=False).passed
    True
    """
    def hand(f):
        m12 = np.array([-1, 2, 0, 1])
        m21 = np.array([2, 3, 1, 0])                          # m21[-1] = 0: the trap for feature 0
        return _diagnose_mutual(f(m12.copy(), m21.copy()), m12, m21)

    def random(f):
        m12, m21 = _random_lists(3)
        return _diagnose_mutual(f(m12.copy(), m21.copy()), m12, m21)

    def none(f):
        m12, m21 = np.array([1, -1, 1]), np.array([-1, 1])
        got = np.asarray(f(m12.copy(), m21.copy()))
        if got.size == 0:
            return None if got.shape == (0, 2) else f"with no mutual pair return an empty (0, 2) array, not {got.shape}"
        return _diagnose_mutual(got, m12, m21)

    return run_checks("mutual_check", func, [
        ("hand-made: one feature without a match, and m21[-1] pointing back at it", hand),
        ("random one-way lists with 150 planted mutual pairs", random),
        ("no mutual pair at all", none),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------
# Union-find tracks
# ---------------------------------------------------------------------------------------------

def _columns(tracks):
    t = np.asarray(tracks)
    return {tuple(c) for c in t.T.tolist()}


def _as_tracks(t, V, name="build_tracks"):
    t = np.asarray(t)
    if t.ndim != 2 or t.shape[0] != V:
        raise ValueError(f"{name} must return a (V, T) array with V = {V} rows (one per view); got shape {t.shape}")
    if t.size and not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"{name} must return integer feature indices (-1 where unseen); got dtype {t.dtype}")
    return t.astype(np.int64)


def _diagnose_tracks(got, pair_matches, n_features):
    V = len(n_features)
    got = _as_tracks(got, V)
    ref, n_conf = build_tracks(pair_matches, n_features, return_conflicts=True)
    if _columns(got) == _columns(ref):
        return None if got.shape[1] == ref.shape[1] else "some tracks appear twice: return each track once"
    offsets = np.concatenate([[0], np.cumsum(n_features)])
    if got.size and got.max() >= max(n_features):
        glob = np.where(ref >= 0, ref + offsets[:V, None], -1)
        if _columns(got) == _columns(glob):
            return ("store the feature's index within its view (0 .. n_features[v] - 1), not the global node number "
                    "(view offset + index)")
        return f"a feature index is {got.max()}, beyond the features of every view: indices run 0 .. n_features[v] - 1"
    if got.size and ((got >= 0).sum(0) < 2).any():
        return "a feature without any match is not a track: keep only tracks seen in at least two views"
    missing, extra = _columns(ref) - _columns(got), _columns(got) - _columns(ref)
    if got.shape[1] and ((got >= 0).sum(0) == 2).all() and ((ref >= 0).sum(0) > 2).any():
        return ("every track of yours has exactly two views: chain the matches across views (a in view 0 matched to b "
                "in view 1, and b to c in view 2, make ONE track a-b-c: union the nodes, then group them by root)")
    if n_conf and not missing and extra:
        return ("you kept tracks that hold two different features of one view (a conflict): at least one of their "
                "matches is wrong and we cannot tell which, so reject the whole track")
    return (f"{len(missing)} tracks missing, {len(extra)} that should not be there: union both features of every "
            "match, group the nodes by their root, drop groups with two features of one view and groups of one node")


def _random_matches(seed, V=5, n=60):
    """Pairwise matches of n points seen by random subsets of V views, plus a few wrong matches."""
    rng = np.random.default_rng(seed)
    seen = rng.random((V, n)) < 0.6
    ids = [rng.permutation(n + 10) for _ in range(V)]       # feature index of point p in view v: ids[v][p]
    pm = {}
    for i in range(V):
        for j in range(i + 1, V):
            both = np.flatnonzero(seen[i] & seen[j])
            both = both[rng.random(both.size) < 0.7]          # not every match is found
            m = np.column_stack([ids[i][both], ids[j][both]])
            wrong = rng.integers(0, n + 10, (2, 2))           # two wrong matches per pair
            pm[(i, j)] = np.vstack([m, wrong.T]).astype(np.int64)
    return pm, [n + 10] * V


def check_build_tracks(func: Callable, verbose: bool = True) -> CheckReport:
    """Self-check of the exercise ``build_tracks(pair_matches, n_features) -> tracks (V, T)``.

    Cases: a chain over three views, a conflict (two features of one view in one track), and random matches
    over five views with a few wrong ones. Tracks are compared as sets of columns (their order is free).

    Examples
    --------
    >>> check_build_tracks(build_tracks, verbose=False).passed
    True
    """
    def chain(f):
        pm = {(0, 1): np.array([[0, 1]]), (1, 2): np.array([[1, 2]]), (0, 2): np.zeros((0, 2), np.int64)}
        return _diagnose_tracks(f(pm, [2, 3, 3]), pm, [2, 3, 3])

    def conflict(f):
        pm = {(0, 1): np.array([[0, 0], [1, 1]]), (1, 2): np.array([[0, 1], [1, 0]]), (0, 2): np.array([[1, 2]])}
        return _diagnose_tracks(f(pm, [2, 2, 3]), pm, [2, 2, 3])

    def random(f):
        pm, n = _random_matches(4)
        return _diagnose_tracks(f(pm, n), pm, n)

    return run_checks("build_tracks", func, [
        ("a chain: 0 <-> 1 and 1 <-> 2 make one track over three views", chain),
        ("a conflict: a track that holds two features of view 2 is rejected", conflict),
        ("random matches over 5 views, with wrong ones", random),
    ], verbose=verbose)
