"""Notebook 08's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.exercises.ex08_views import check_pose_covariance, check_pyramid_score
from labutils.sfm.view_selection import pose_covariance, pyramid_score

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def pyramid_reference(x, image_size, levels=6):
    w, h = image_size
    score = 0.0
    for level in range(1, levels + 1):
        K = 2 ** level
        col = np.clip(np.floor(K * x[:, 0] / w), 0, K - 1).astype(int)
        row = np.clip(np.floor(K * x[:, 1] / h), 0, K - 1).astype(int)
        score += K * len(np.unique(row * K + col))
    return score


def _skew_rows(v):
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def covariance_reference(X, K, R, t, sigma=1.0, *, side="left", through_K=True, sign=-1.0, power=2, invert=True):
    RX = X @ R.T
    u = (RX + t) @ K.T
    pix = u[:, :2] / u[:, 2:]
    Kj = K if through_K else np.eye(3)
    if not through_K:
        u = (RX + t)
        pix = u[:, :2] / u[:, 2:]
    A = (Kj[None, :2, :] - pix[:, :, None] * Kj[None, 2:3, :]) / u[:, 2, None, None]
    dw = sign * _skew_rows(RX) if side == "left" else -R[None] @ _skew_rows(X)
    J = np.concatenate([A @ dw, A], axis=2).reshape(-1, 6)
    H = J.T @ J
    return sigma ** power * (np.linalg.inv(H) if invert else H)


@pytest.mark.parametrize("check, solution", [(check_pyramid_score, pyramid_reference),
                                             (check_pyramid_score, pyramid_score),
                                             (check_pose_covariance, covariance_reference),
                                             (check_pose_covariance, pose_covariance)])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_pyramid_score)


# --- exercise 1 ------------------------------------------------------------------------------------------------


def test_pyramid_counts_points():
    def wrong(x, size, levels=6):
        return float(sum(2 ** lv * len(x) for lv in range(1, levels + 1)))
    assert "not the full cells" in hints(check_pyramid_score(wrong, verbose=False))


def test_pyramid_levels_from_zero():
    def wrong(x, size, levels=6):
        return pyramid_reference(x, size, levels) - 2 * 2 ** levels * 0 + _level_zero(x, size, levels)
    assert "l = 0" in hints(check_pyramid_score(wrong, verbose=False))


def _level_zero(x, size, levels):
    """The levels-from-0 score minus the right one: a wrong answer built from the reference."""
    w, h = size
    s0 = 0.0
    for level in range(0, levels):
        K = 2 ** level
        col = np.clip(np.floor(K * x[:, 0] / w), 0, K - 1).astype(int)
        row = np.clip(np.floor(K * x[:, 1] / h), 0, K - 1).astype(int)
        s0 += K * len(np.unique(row * K + col))
    return s0 - pyramid_reference(x, size, levels)


def test_pyramid_weights_squared_or_missing():
    def squared(x, size, levels=6):
        w, h = size
        return sum(4 ** lv * len(np.unique(np.clip(np.floor(2 ** lv * x[:, 1] / h), 0, 2 ** lv - 1) * 2 ** lv
                                           + np.clip(np.floor(2 ** lv * x[:, 0] / w), 0, 2 ** lv - 1)))
                   for lv in range(1, levels + 1))

    def unweighted(x, size, levels=6):
        w, h = size
        return sum(len(np.unique(np.clip(np.floor(2 ** lv * x[:, 1] / h), 0, 2 ** lv - 1) * 2 ** lv
                                 + np.clip(np.floor(2 ** lv * x[:, 0] / w), 0, 2 ** lv - 1)))
                   for lv in range(1, levels + 1))
    assert "K_l²" in hints(check_pyramid_score(squared, verbose=False))
    assert "every full cell counts the same" in hints(check_pyramid_score(unweighted, verbose=False))


def test_pyramid_swapped_axes_and_no_clipping():
    assert "swapped" in hints(check_pyramid_score(lambda x, size, levels=6: pyramid_reference(x, size[::-1], levels),
                                                  verbose=False))

    def no_clip(x, size, levels=6):
        w, h = size
        score = 0.0
        for level in range(1, levels + 1):
            K = 2 ** level
            grid = np.zeros((K, K), bool)
            grid[np.floor(K * x[:, 1] / h).astype(int), np.floor(K * x[:, 0] / w).astype(int)] = True
            score += K * grid.sum()
        return score
    assert "clip the cell index" in hints(check_pyramid_score(no_clip, verbose=False))


# --- exercise 2 ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, words", [
    (dict(invert=False), "information matrix"),
    (dict(power=1), "not σ (JᵀJ)⁻¹"),
    (dict(sign=1.0), "wrong sign"),
    (dict(side="right"), "on the right"),
    (dict(through_K=False), "normalised image units"),
])
def test_covariance_mistakes(kwargs, words):
    def wrong(X, K, R, t, sigma=1.0):
        return covariance_reference(X, K, R, t, sigma, **kwargs)
    assert words in hints(check_pose_covariance(wrong, verbose=False))


def test_covariance_swapped_blocks():
    P = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])
    assert "swapped" in hints(check_pose_covariance(lambda X, K, R, t, s=1.0: P @ pose_covariance(X, K, R, t, s) @ P,
                                                    verbose=False))
