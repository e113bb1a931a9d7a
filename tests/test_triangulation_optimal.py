"""The optimal two-view correction (H&Z Alg. 12.1) and the residual of an F built on it."""
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from labutils.core.geometry import relative_pose, skew
from labutils.core.synthetic import make_scene
from labutils.twoview.triangulation import fundamental_residual, triangulate, triangulate_optimal


def true_F(s, i=0, j=1):
    R, t = relative_pose(s.R[i], s.t[i], s.R[j], s.t[j])
    Ki = np.linalg.inv(s.K)
    return Ki.T @ skew(t) @ R @ Ki


def sq_dist(x1, x2, x1_hat, x2_hat):
    return ((x1 - x1_hat) ** 2).sum(1) + ((x2 - x2_hat) ** 2).sum(1)


def epipolar_error(F, x1, x2):
    """|x2_hᵀ F x1_h| relative to |x2_h| |F| |x1_h|."""
    a = np.hstack([x1, np.ones((len(x1), 1))])
    b = np.hstack([x2, np.ones((len(x2), 1))])
    return np.abs(np.einsum("ni,ij,nj->n", b, F, a)) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
                                                          * np.linalg.norm(F))


def brute_force(F, x1, x2, m=20000):
    """Global minimum over the pencil of epipolar lines: a dense scan of its angle, then a local refine."""
    e1 = np.linalg.svd(F)[2][2]
    theta = np.linspace(0, np.pi, m, endpoint=False)

    def cost(th, a, b):
        d = np.stack([np.cos(th), np.sin(th), np.zeros_like(th)], -1)
        l1, l2 = np.cross(e1, d), d @ F.T               # the line through e1 with direction d, and its mate
        return (l1 @ a) ** 2 / (l1[..., 0] ** 2 + l1[..., 1] ** 2) + (l2 @ b) ** 2 / (l2[..., 0] ** 2 + l2[..., 1] ** 2)

    out = []
    for p, q in zip(x1, x2):
        a, b = np.r_[p, 1.0], np.r_[q, 1.0]
        v = cost(theta, a, b)
        k = np.argmin(v)
        h = np.pi / m
        res = minimize_scalar(lambda th, a=a, b=b: cost(np.array(th), a, b), bounds=(theta[k] - h, theta[k] + h),
                              method="bounded", options=dict(xatol=1e-13))
        out.append(min(res.fun, v[k]))
    return np.array(out)


@pytest.mark.parametrize("layout", ["general", "forward"])
def test_constraint_holds_exactly_and_noise_free_points_stay(layout, rng):
    s = make_scene(200, 2, layout=layout, noise_px=2.0, rng=rng)
    F = true_F(s)
    x1, x2, _ = s.pair(0, 1)
    x1_hat, x2_hat = triangulate_optimal(F, x1, x2)
    assert x1_hat.shape == x1.shape and x2_hat.shape == x2.shape
    assert epipolar_error(F, x1_hat, x2_hat).max() < 1e-12       # exact, to rounding
    xt1, xt2, _ = s.pair(0, 1, which="true")
    y1, y2 = triangulate_optimal(F, xt1, xt2)
    assert np.abs(y1 - xt1).max() < 1e-8 and np.abs(y2 - xt2).max() < 1e-8


@pytest.mark.parametrize("layout", ["general", "forward"])
def test_equals_brute_force_global_minimum(layout):
    rng = np.random.default_rng(7)
    s = make_scene(12, 2, layout=layout, noise_px=3.0, rng=rng)
    F = true_F(s)
    x1, x2, _ = s.pair(0, 1)
    d_opt = sq_dist(x1, x2, *triangulate_optimal(F, x1, x2))
    d_bf = brute_force(F, x1, x2)
    assert np.all(d_opt <= d_bf + 1e-8)                         # never worse than the search ...
    assert np.all(np.abs(d_opt - d_bf) <= 1e-6 * (1 + d_bf))    # ... and the same minimum


def test_never_farther_than_other_corrections(rng):
    """Against the other ways of making a pair consistent: reprojected DLT points, and the true points."""
    s = make_scene(300, 2, layout="general", noise_px=1.5, rng=rng)
    F = true_F(s)
    x1, x2, idx = s.pair(0, 1)
    d_opt = sq_dist(x1, x2, *triangulate_optimal(F, x1, x2))
    X = triangulate(s.P[0], s.P[1], x1, x2)                     # linear triangulation, then reproject
    from labutils.core.geometry import project
    d_dlt = sq_dist(x1, x2, project(s.P[0], X), project(s.P[1], X))
    d_true = sq_dist(x1, x2, *s.pair(0, 1, which="true")[:2])
    assert np.all(d_opt <= d_dlt + 1e-9) and np.all(d_opt <= d_true + 1e-9)
    assert d_opt.sum() < d_dlt.sum()


def test_epipole_at_infinity_and_on_the_axis():
    """f = 0 (epipole at infinity, the polynomial loses its leading terms): rectified cameras."""
    F = np.array([[0.0, 0, 0], [0, 0, -1], [0, 1, 0]])          # x2 = x1 + (d, 0): rows must agree
    x1 = np.array([[0.0, 0.0], [10.0, 3.0], [-4.0, 7.5]])
    x2 = np.array([[5.0, 2.0], [1.0, 1.0], [30.0, 7.5]])
    x1_hat, x2_hat = triangulate_optimal(F, x1, x2)
    mid = (x1[:, 1] + x2[:, 1]) / 2
    assert np.allclose(x1_hat, np.column_stack([x1[:, 0], mid]), atol=1e-12)
    assert np.allclose(x2_hat, np.column_stack([x2[:, 0], mid]), atol=1e-12)


def test_fundamental_residual(rng):
    s = make_scene(100, 2, noise_px=1.0, rng=rng)
    F = true_F(s)
    x1, x2, _ = s.pair(0, 1)
    x1_hat, x2_hat = triangulate_optimal(F, x1, x2)
    expected = np.sqrt(sq_dist(x1, x2, x1_hat, x2_hat).sum() / (4 * len(x1)))
    assert fundamental_residual(F, x1, x2) == pytest.approx(expected, rel=1e-12)
    assert fundamental_residual(-3.0 * F, x1, x2) == pytest.approx(expected, rel=1e-9)     # scale-free
    assert fundamental_residual(F, *s.pair(0, 1, which="true")[:2]) < 1e-9
    # with the true F, each point's squared correction is σ² χ²(1): the RMS over 4N coordinates is ≈ σ/2
    assert 0.5 * 0.75 < fundamental_residual(F, x1, x2) < 0.5 * 1.25


def test_bad_input(rng):
    s = make_scene(10, 2, noise_px=1.0, rng=rng)
    F = true_F(s)
    x1, x2, _ = s.pair(0, 1)
    with pytest.raises(ValueError, match="rank 2"):
        triangulate_optimal(F + 1e-3 * np.abs(F).max() * np.eye(3), x1, x2)
    with pytest.raises(ValueError, match="rank < 2"):
        triangulate_optimal(np.outer([1.0, 2, 3], [1.0, 0, 1]), x1, x2)
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        triangulate_optimal(F[:2], x1, x2)
    with pytest.raises(ValueError, match="non-finite"):
        triangulate_optimal(np.full((3, 3), np.nan), x1, x2)
    with pytest.raises(ValueError, match="shape"):
        triangulate_optimal(F, x1[:, :1], x2)
    with pytest.raises(ValueError, match="row by row"):
        triangulate_optimal(F, x1[:5], x2)
    bad = x1.copy()
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        fundamental_residual(F, bad, x2)
