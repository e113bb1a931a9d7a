"""Notebook 05's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.bundle.schur import levenberg_marquardt
from labutils.core.geometry import camera_center
from labutils.core.ransac import ransac
from labutils.exercises.ex05_sfm import (
    accept_points_reference,
    adjust,
    check_accept_points,
    check_choose_next_view,
    check_incremental_loop,
    incremental_loop_reference,
    next_view_reference,
    register_view,
    triangulate_new,
)
from labutils.sfm.incremental import next_view
from labutils.twoview.triangulation import triangulate

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def choose_next_view(seen, X, registered, min_points=15):
    counts = (seen & np.isfinite(X[:, 0])).sum(axis=1)
    counts[registered] = -1
    v = int(np.argmax(counts))
    return v if counts[v] >= min_points else None


def accept_points(X, K, R, t, tracks, mask, threshold_px, min_angle_deg, *, variant=None):
    """The notebook's solution; ``variant`` makes one typical mistake (for the tests below)."""
    ok = mask.sum(0) >= 2
    if variant == "no count":
        ok = np.ones(mask.shape[1], bool)
    for k in np.flatnonzero(ok):
        views = np.flatnonzero(mask[:, k])
        if variant == "all views":
            views = np.flatnonzero(np.isfinite(tracks[:, k, 0]))
        Xc = R[views] @ X[k] + t[views]
        q = Xc @ K.T
        err = np.linalg.norm(q[:, :2] / q[:, 2:] - tracks[views, k], axis=1)
        C = camera_center(R[views], t[views])
        rays = X[k] - C
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        cos = np.clip(rays @ rays.T, -1, 1)
        widest = np.degrees(np.arccos(cos)).max()
        if variant == "radians":
            widest = np.radians(widest)
        if variant == "first pair":
            widest = np.degrees(np.arccos(cos[0, 1])) if len(views) > 1 else 0.0
        if variant == "no angle":
            widest = np.inf
        if variant == "no count":
            widest = np.nan if len(views) < 2 else widest
        in_front = np.all(Xc[:, 2] > 0) or variant == "no cheirality"
        within = {"mean": err.mean() <= threshold_px, "squared": np.all(err ** 2 <= threshold_px)}.get(
            variant, np.all(err <= threshold_px))
        ok[k] = in_front and within and not (widest < min_angle_deg)
    return ok


@pytest.mark.parametrize("check, solution", [(check_choose_next_view, choose_next_view),
                                             (check_choose_next_view, next_view_reference),
                                             (check_accept_points, accept_points),
                                             (check_accept_points, accept_points_reference)])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_library_next_view_is_the_reference():
    """The library's ``next_view`` (on the counts) plus the pipeline's minimum is the exercise's reference."""
    def via_library(seen, X, registered, min_points=15):
        counts = (seen & np.isfinite(X[:, 0])).sum(1)
        v = next_view(counts, registered)
        return v if v is not None and counts[v] >= min_points else None
    assert check_choose_next_view(via_library, verbose=False).passed


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_accept_points)


# --- exercise 1: typical mistakes ---------------------------------------------------------------------------------

def test_next_view_counts_every_track():
    def wrong(seen, X, registered, min_points=15):
        counts = seen.sum(1)
        counts[registered] = -1
        v = int(np.argmax(counts))
        return v if counts[v] >= min_points else None
    assert "count only the tracks with a point" in hints(check_choose_next_view(wrong, verbose=False))


def test_next_view_keeps_registered_views():
    def wrong(seen, X, registered, min_points=15):
        counts = (seen & np.isfinite(X[:, 0])).sum(1)
        v = int(np.argmax(counts))
        return v if counts[v] >= min_points else None
    assert "already registered" in hints(check_choose_next_view(wrong, verbose=False))


def test_next_view_argmin():
    def wrong(seen, X, registered, min_points=15):
        counts = (seen & np.isfinite(X[:, 0])).sum(1)
        counts[registered] = 10 ** 6
        return int(np.argmin(counts))
    assert "argmax, not argmin" in hints(check_choose_next_view(wrong, verbose=False))


def test_next_view_without_minimum():
    def wrong(seen, X, registered, min_points=15):
        counts = (seen & np.isfinite(X[:, 0])).sum(1)
        counts[registered] = -1
        return int(np.argmax(counts))
    assert "return None" in hints(check_choose_next_view(wrong, verbose=False))


def test_next_view_strict_minimum():
    def wrong(seen, X, registered, min_points=15):
        counts = (seen & np.isfinite(X[:, 0])).sum(1)
        counts[registered] = -1
        v = int(np.argmax(counts))
        return v if counts[v] > min_points else None
    assert "exactly min_points" in hints(check_choose_next_view(wrong, verbose=False))


def test_next_view_returns_the_count():
    def wrong(seen, X, registered, min_points=15):
        counts = (seen & np.isfinite(X[:, 0])).sum(1)
        counts[registered] = -1
        return int(counts.max()) if counts.max() >= min_points else None
    assert "not its count" in hints(check_choose_next_view(wrong, verbose=False))


# --- exercise 2: typical mistakes ---------------------------------------------------------------------------------

@pytest.mark.parametrize("variant, words", [
    ("no cheirality", "behind the cameras"),
    ("mean", "*every* observation"),
    ("squared", "not its square"),
    ("no angle", "seen under only about 1°"),
    ("first pair", "*widest* angle"),
    ("radians", "in degrees"),
    ("no count", "single observation"),
    ("all views", "not in mask"),
])
def test_accept_points_mistakes(variant, words):
    def wrong(*args):
        return accept_points(*args, variant=variant)
    assert words in hints(check_accept_points(wrong, verbose=False))


def test_accept_points_wrong_shape():
    report = check_accept_points(lambda X, *args: np.ones((len(X), 1), bool), verbose=False)
    assert "shape" in hints(report)


# --- exercise 3: the incremental loop ------------------------------------------------------------------------------

def _loop(variant=None):
    """The notebook's loop (with the library's pieces), or a variant with one typical mistake."""
    def incremental_loop(tracks, K, init, *, rng, threshold_px=4.0, min_angle_deg=1.5, min_points=15, growth=1.3,
                         ba_iter=10):
        V, T = tracks.shape[:2]
        seen = np.isfinite(tracks[..., 0])
        R, t, X = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan), np.full((T, 3), np.nan)
        i, j = init["i"], init["j"]
        R[i], t[i], R[j], t[j] = np.eye(3), np.zeros(3), init["R"], init["t"]
        X[init["track"]] = init["X"]
        registered, inliers = np.zeros(V, bool), seen.copy()
        registered[[i, j]] = True
        order, n_adjusted = ([j, i] if variant == "order" else [i, j]), 2
        while True:
            v = next_view_reference(seen & inliers, X, registered, min_points)
            if variant == "pair only":
                v = None
            if v is not None:
                have = np.flatnonzero(seen[v] & np.isfinite(X[:, 0]))
                R[v], t[v], inl = register_view(X[have], tracks[v, have], K, threshold_px, rng=rng, ransac_loop=ransac)
                inliers[v, have[~inl]] = False
                registered[v] = True
                order.append(v)
                if variant != "no triangulation":
                    new = np.flatnonzero(np.isnan(X[:, 0]) & seen[v] & (seen[registered].sum(0) >= 2))
                    X_new = triangulate_new(tracks, K, R, t, v, new, registered, dlt=triangulate)
                    ok = accept_points_reference(X_new, K, R, t, tracks[:, new], seen[:, new] & registered[:, None],
                                                 threshold_px, min_angle_deg)
                    X[new[ok]] = X_new[ok]
            if v is None or registered.sum() >= growth * n_adjusted:
                R, t, X = adjust(R, t, X, inliers & registered[:, None], tracks, K, ba_iter, lm=levenberg_marquardt)
                n_adjusted = registered.sum()
            if v is None:
                return R, t, X, order
    return incremental_loop


def test_loop_reference_passes():
    assert_passes(check_incremental_loop, incremental_loop_reference, min_cases=2)


@pytest.mark.parametrize("variant, words", [
    ("pair only", "only the initial pair"),
    ("order", "start with the initial pair"),
    ("no triangulation", "triangulate the new tracks"),
])
def test_loop_mistakes(variant, words):
    assert words in hints(check_incremental_loop(_loop(variant), verbose=False))


def test_loop_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_incremental_loop)
