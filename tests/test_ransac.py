import numpy as np
import pytest

from labutils.core.ransac import ransac, ransac_iterations


def line_problem(rng, n=200, outlier_ratio=0.4):
    x = rng.uniform(-1, 1, n)
    y = 2 * x + 0.5 + rng.normal(scale=0.01, size=n)
    out = rng.random(n) < outlier_ratio
    y[out] = rng.uniform(-3, 3, out.sum())
    return np.stack([x, y], 1), out


def fit_line(pts):
    def fit(idx):
        (x0, y0), (x1, y1) = pts[idx]
        return [] if abs(x1 - x0) < 1e-9 else [((y1 - y0) / (x1 - x0), y0 - (y1 - y0) / (x1 - x0) * x0)]
    return fit


def test_ransac_finds_line_and_outliers(rng):
    pts, out = line_problem(rng)
    model, inl, n_iter = ransac(len(pts), 2, fit_line(pts), lambda m: np.abs(pts[:, 1] - m[0] * pts[:, 0] - m[1]),
                                threshold=0.04, rng=rng, confidence=0.999)
    assert abs(model[0] - 2) < 0.05 and abs(model[1] - 0.5) < 0.05
    true_in = ~out | (np.abs(pts[:, 1] - 2 * pts[:, 0] - 0.5) < 0.04)
    assert (inl == true_in).mean() > 0.99
    assert n_iter <= ransac_iterations(0.5, 2, 0.999) + 5      # adaptive stop


def test_ransac_is_deterministic_and_checks_input(rng):
    pts, _ = line_problem(rng)
    run = lambda seed: ransac(len(pts), 2, fit_line(pts), lambda m: np.abs(pts[:, 1] - m[0] * pts[:, 0] - m[1]),
                              0.04, rng=np.random.default_rng(seed))
    assert run(1)[2] == run(1)[2] and np.array_equal(run(1)[1], run(1)[1])
    with pytest.raises(ValueError, match="at least 2"):
        ransac(1, 2, fit_line(pts), None, 0.1, rng=rng)
    with pytest.raises(ValueError, match="rng"):
        ransac(10, 2, fit_line(pts), None, 0.1, rng=None)
    with pytest.raises(ValueError, match="degenerate"):
        ransac(10, 2, lambda idx: [], None, 0.1, rng=rng, max_iter=20)
    with pytest.raises(ValueError, match="confidence"):
        ransac(10, 2, fit_line(pts), None, 0.1, rng=rng, confidence=1.0)
