"""The self-checks of notebook 07: the reference passes every case; each typical mistake gets its own hint."""
import numpy as np
import pytest
from _exercises import assert_stubs_not_written, hints

from labutils.exercises.ex07_matching import check_build_tracks, check_mutual_check, check_ratio_test
from labutils.match import UnionFind, build_tracks, mutual_check, ratio_test

# --- the ratio test ------------------------------------------------------------------------------


def test_ratio_reference_passes():
    report = check_ratio_test(ratio_test, verbose=False)
    assert report.passed and report.written and len(report.cases) == 3


@pytest.mark.parametrize("wrong, words", [
    (lambda d, r=0.8: d[:, 0] ** 2 < r * d[:, 1] ** 2, "squared distances"),
    (lambda d, r=0.8: d[:, 0] <= r * d[:, 1], "strict '<'"),
    (lambda d, r=0.8: d[:, 0] > r * d[:, 1], "kept the ambiguous matches"),
    (lambda d, r=0.8: d[:, 0] < 0.8 * d[:, 1], "use the ratio argument"),
    (lambda d, r=0.8: np.flatnonzero(d[:, 0] < r * d[:, 1]), "return a boolean mask"),
    (lambda d, r=0.8: d[:, 1] < r * d[:, 0], "you kept nothing"),
    (lambda d, r=0.8: np.divide(d[:, 1], d[:, 0], out=np.full(len(d), np.inf), where=d[:, 0] > 0) > r,
     "you inverted the ratio"),
])
def test_ratio_wrong_answers_get_their_hint(wrong, words):
    report = check_ratio_test(wrong, verbose=False)
    assert words in hints(report), report.hints


def test_ratio_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_ratio_test)


# --- the mutual check ----------------------------------------------------------------------------


def test_mutual_reference_passes():
    assert check_mutual_check(mutual_check, verbose=False).passed


def _naive_mutual(m12, m21):
    i = np.arange(len(m12))
    ok = m21[m12] == i                    # m21[-1] is the last entry: the -1 bug
    return np.column_stack([i[ok], m12[ok]])


def _one_way(m12, m21):
    i = np.flatnonzero(m12 >= 0)
    return np.column_stack([i, m12[i]])


def _swapped(m12, m21):
    return mutual_check(m12, m21)[:, ::-1]


def _sorted_by_j(m12, m21):
    m = mutual_check(m12, m21)
    return m[np.argsort(m[:, 1])]


@pytest.mark.parametrize("wrong, words", [
    (_naive_mutual, "m21[-1] is the LAST entry"),
    (_one_way, "without checking the way back"),
    (_swapped, "columns are swapped"),
    (_sorted_by_j, "sort them by i"),
    (lambda m12, m21: [], "empty (0, 2) array"),
])
def test_mutual_wrong_answers_get_their_hint(wrong, words):
    report = check_mutual_check(wrong, verbose=False)
    assert words in hints(report), report.hints


# --- union-find tracks ---------------------------------------------------------------------------


def test_tracks_reference_passes():
    assert check_build_tracks(build_tracks, verbose=False).passed


def _pairs_only(pair_matches, n_features):
    """No chaining: every match its own two-view track."""
    cols = []
    for (i, j), m in pair_matches.items():
        for a, b in np.asarray(m).reshape(-1, 2):
            c = np.full(len(n_features), -1)
            c[i], c[j] = a, b
            cols.append(c)
    return np.array(cols).T if cols else np.zeros((len(n_features), 0), int)


def _union_find(pair_matches, n_features, reject=True, local=True, singletons=False):
    V = len(n_features)
    off = np.concatenate([[0], np.cumsum(n_features)]).astype(int)
    uf = UnionFind(off[-1])
    for (i, j), m in pair_matches.items():
        for a, b in np.asarray(m).reshape(-1, 2):
            uf.union(off[i] + a, off[j] + b)
    groups = {}
    for node in range(off[-1]):
        groups.setdefault(uf.find(node), []).append(node)
    cols = []
    for nodes in groups.values():
        if len(nodes) < 2 and not singletons:
            continue
        c = np.full(V, -1)
        conflict = False
        for node in nodes:
            v = int(np.searchsorted(off, node, side="right") - 1)
            conflict |= c[v] >= 0
            c[v] = node - off[v] if local else node          # the last feature wins
        if not (conflict and reject):
            cols.append(c)
    return np.array(cols).T if cols else np.zeros((V, 0), int)


@pytest.mark.parametrize("wrong, words", [
    (_pairs_only, "chain the matches across views"),
    (lambda pm, n: _union_find(pm, n, reject=False), "two different features of one view"),
    (lambda pm, n: _union_find(pm, n, local=False), "not the global node number"),
    (lambda pm, n: _union_find(pm, n, singletons=True), "not a track"),
])
def test_tracks_wrong_answers_get_their_hint(wrong, words):
    report = check_build_tracks(wrong, verbose=False)
    assert words in hints(report), report.hints


def test_tracks_student_style_union_find_passes():
    """A correct union-find written differently (dict of roots, other track order) passes too."""
    assert check_build_tracks(lambda pm, n: _union_find(pm, n)[:, ::-1], verbose=False).passed


def test_checks_never_raise_on_garbage():
    for check in (check_ratio_test, check_mutual_check, check_build_tracks):
        report = check(lambda *a, **k: "nonsense", verbose=False)
        assert not report.passed and all(report.hints)
