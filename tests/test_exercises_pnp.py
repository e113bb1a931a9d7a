"""Notebook 03's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.core.ransac import ransac
from labutils.exercises.ex03_pnp import check_adaptive_ransac, check_pose_from_depths

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def pose_from_depths_reference(X, y, lam):
    d1, d2 = X[0] - X[1], X[0] - X[2]
    v1, v2 = lam[0] * y[0] - lam[1] * y[1], lam[0] * y[0] - lam[2] * y[2]
    R = np.column_stack([v1, v2, np.cross(v1, v2)]) @ np.linalg.inv(np.column_stack([d1, d2, np.cross(d1, d2)]))
    return R, lam[0] * y[0] - R @ X[0]


def adaptive_ransac_reference(n_data, sample_size, fit, errors, threshold, *, rng, confidence=0.9999,
                              max_iter=10000):
    best, best_inliers, n_needed, n_iter = None, np.zeros(n_data, bool), max_iter, 0
    while n_iter < min(n_needed, max_iter):
        n_iter += 1
        idx = rng.choice(n_data, sample_size, replace=False)
        for model in fit(idx):
            inliers = np.asarray(errors(model)) < threshold
            if inliers.sum() > best_inliers.sum():
                best, best_inliers = model, inliers
                w = inliers.mean() ** sample_size
                n_needed = 1 if w == 1 else int(np.ceil(np.log(1 - confidence) / np.log(1 - w)))
    return best, best_inliers, n_iter


@pytest.mark.parametrize("check, solution", [(check_pose_from_depths, pose_from_depths_reference),
                                             (check_adaptive_ransac, adaptive_ransac_reference),
                                             (check_adaptive_ransac, ransac)])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_pose_from_depths, check_adaptive_ransac)


# --- exercise 1: typical mistakes ---------------------------------------------------------------------------------

def _with(R_of=lambda R: R, t_of=None):
    def f(X, y, lam):
        R, t = pose_from_depths_reference(X, y, lam)
        return R_of(R), (t if t_of is None else t_of(R_of(R), t, X, y, lam))
    return f


@pytest.mark.parametrize("wrong, words", [
    (_with(R_of=lambda R: R.T), "transposed"),
    (_with(t_of=lambda R, t, X, y, lam: -t), "wrong sign"),
    (_with(t_of=lambda R, t, X, y, lam: -R.T @ t), "camera centre"),
    (_with(t_of=lambda R, t, X, y, lam: lam[1] * y[1] - R @ X[0]), "mixes two points"),
    (lambda X, y, lam: pose_from_depths_reference(X, y, np.ones(3)), "scaled by their depths"),
])
def test_pose_from_depths_mistakes(wrong, words):
    assert words in hints(check_pose_from_depths(wrong, verbose=False))


def test_pose_from_depths_without_cross_products():
    def wrong(X, y, lam):
        D = np.column_stack([X[0] - X[1], X[0] - X[2]])
        Vm = np.column_stack([lam[0] * y[0] - lam[1] * y[1], lam[0] * y[0] - lam[2] * y[2]])
        R = Vm @ np.linalg.pinv(D)
        return R, lam[0] * y[0] - R @ X[0]
    assert "cross products" in hints(check_pose_from_depths(wrong, verbose=False))


def test_pose_from_depths_reflection():
    def wrong(X, y, lam):
        d1, d2 = X[0] - X[1], X[0] - X[2]
        v1, v2 = lam[0] * y[0] - lam[1] * y[1], lam[0] * y[0] - lam[2] * y[2]
        R = np.column_stack([v1, v2, np.cross(v2, v1)]) @ np.linalg.inv(np.column_stack([d1, d2, np.cross(d1, d2)]))
        return R, lam[0] * y[0] - R @ X[0]
    assert "reflection" in hints(check_pose_from_depths(wrong, verbose=False))


def test_pose_from_depths_edges_in_the_wrong_order():
    def wrong(X, y, lam):
        d1, d2 = X[0] - X[1], X[0] - X[2]
        v1, v2 = lam[1] * y[1] - lam[0] * y[0], lam[2] * y[2] - lam[0] * y[0]
        R = np.column_stack([v1, v2, np.cross(v1, v2)]) @ np.linalg.inv(np.column_stack([d1, d2, np.cross(d1, d2)]))
        return R, lam[0] * y[0] - R @ X[0]
    assert "half turn" in hints(check_pose_from_depths(wrong, verbose=False))


# --- exercise 2: typical mistakes ---------------------------------------------------------------------------------

def _ransac_variant(adaptive=True, power=True, all_candidates=True, use_rng=True):
    def f(n_data, sample_size, fit, errors, threshold, *, rng, confidence=0.9999, max_iter=10000):
        draw = rng if use_rng else np.random.default_rng()
        best, best_inliers, n_needed, n_iter = None, np.zeros(n_data, bool), max_iter, 0
        while n_iter < min(n_needed, max_iter):
            n_iter += 1
            models = fit(draw.choice(n_data, sample_size, replace=False))
            for model in (models if all_candidates else models[:1]):
                inliers = np.asarray(errors(model)) < threshold
                if inliers.sum() > best_inliers.sum():
                    best, best_inliers = model, inliers
                    w = inliers.mean() ** (sample_size if power else 1)
                    if adaptive:
                        n_needed = 1 if w == 1 else int(np.ceil(np.log(1 - confidence) / np.log(1 - w)))
        return best, best_inliers, n_iter
    return f


def test_ransac_not_adaptive():
    assert "not adaptive" in hints(check_adaptive_ransac(_ransac_variant(adaptive=False), verbose=False))


def test_ransac_w_instead_of_w_to_the_s():
    assert "not w" in hints(check_adaptive_ransac(_ransac_variant(power=False), verbose=False))


def test_ransac_first_candidate_only():
    assert "only the first candidate" in hints(check_adaptive_ransac(_ransac_variant(all_candidates=False),
                                                                     verbose=False))


def test_ransac_global_random_state():
    assert "rng argument was never used" in hints(check_adaptive_ransac(_ransac_variant(use_rng=False),
                                                                        verbose=False))


def test_ransac_indexing_an_empty_candidate_list():
    def wrong(n_data, sample_size, fit, errors, threshold, *, rng, confidence=0.9999, max_iter=10000):
        best, best_inliers, n_needed, n_iter = None, np.zeros(n_data, bool), max_iter, 0
        while n_iter < min(n_needed, max_iter):
            n_iter += 1
            model = fit(rng.choice(n_data, sample_size, replace=False))[0]
            inliers = np.asarray(errors(model)) < threshold
            if inliers.sum() > best_inliers.sum():
                best, best_inliers = model, inliers
                n_needed = int(np.ceil(np.log(1 - confidence) / np.log(1 - inliers.mean() ** sample_size)))
        return best, best_inliers, n_iter
    assert "empty list" in hints(check_adaptive_ransac(wrong, verbose=False))


def test_ransac_keeps_the_first_model_not_the_best():
    def wrong(n_data, sample_size, fit, errors, threshold, *, rng, confidence=0.9999, max_iter=10000):
        best, best_inliers, n_iter = None, np.zeros(n_data, bool), 0
        while n_iter < 50:
            n_iter += 1
            for model in fit(rng.choice(n_data, sample_size, replace=False)):
                if best is None:                                  # never replaced by a better one
                    best, best_inliers = model, np.asarray(errors(model)) < threshold
        return best, best_inliers, n_iter
    assert "most inliers" in hints(check_adaptive_ransac(wrong, verbose=False))
