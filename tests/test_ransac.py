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


# ---------------------------------------------------------------- convergence and the chance test

def test_ransac_result_says_whether_it_converged(rng):
    pts, _ = line_problem(rng)
    err = lambda m: np.abs(pts[:, 1] - m[0] * pts[:, 0] - m[1])          # noqa: E731
    res = ransac(len(pts), 2, fit_line(pts), err, 0.04, rng=rng)
    model, inl, n_iter = res                                              # still unpacks as the triple
    assert res.converged and n_iter >= res.n_needed and res.n_models == n_iter
    assert res.model is model and res.inliers is inl and np.isnan(res.p_chance)
    short = ransac(len(pts), 2, fit_line(pts), err, 0.04, rng=rng, max_iter=2)
    assert not short.converged and short.n_iter == 2 < short.n_needed and "stopped at max_iter" in short.text()


def test_chance_probability_is_the_binomial_tail_times_the_models():
    from math import comb

    from labutils.core.ransac import chance_probability
    for k, n, s, p, m in [(5, 40, 3, 0.01, 1), (12, 40, 7, 0.03, 50), (20, 100, 2, 0.1, 7)]:
        tail = sum(comb(n - s, i) * p ** i * (1 - p) ** (n - s - i) for i in range(k - s, n - s + 1))
        assert np.isclose(chance_probability(k, n, s, p, m), m * tail, rtol=1e-10)
    assert chance_probability(3, 40, 3, 0.01, 1) == 1.0                 # the sample alone proves nothing
    assert chance_probability(10, 40, 3, 0.5, 10) == 1.0                # capped


def test_ransac_refuses_a_line_through_noise_and_keeps_a_real_one():
    """Line in [-1, 1] × [-3, 3] with threshold 0.04: a datum unrelated to a line is within 0.04 of it with
    probability at most 2 · 0.04 · 1 / 6 · (1 + slope²)^½ ≈ 0.03 for |slope| <= 2 (band area over box area): use
    0.05. Noise: the best of ~1000 lines gets about 9 of 200 (binomial mean 6), p_chance ≈ 1. The real line
    (60 % of 200 inliers) has ~118 more than its sample: p_chance ≈ C(198, 118) 0.05¹¹⁸ ≈ 1e-95."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        pts, _ = line_problem(rng)
        err = lambda m, pts=pts: np.abs(pts[:, 1] - m[0] * pts[:, 0] - m[1])     # noqa: E731
        res = ransac(len(pts), 2, fit_line(pts), err, 0.04, rng=rng, chance=0.05)
        assert res.p_chance < 1e-80 and res.inliers.sum() > 100
        noise = np.c_[rng.uniform(-1, 1, 200), rng.uniform(-3, 3, 200)]
        with pytest.raises(ValueError, match="no better than chance"):
            ransac(200, 2, fit_line(noise), lambda m, p=noise: np.abs(p[:, 1] - m[0] * p[:, 0] - m[1]), 0.04,
                   rng=rng, chance=0.05, max_iter=1000)
