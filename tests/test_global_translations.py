"""Camera centres from known rotations: the points method (sound for forward motion) and the pairwise directions."""
import numpy as np
import pytest

from labutils.core.geometry import P_from_KRt, project, relative_pose, rotation_from_angle_axis
from labutils.core.metrics import align_similarity
from labutils.core.synthetic import make_scene
from labutils.pose.global_translations import (
    centres_from_directions,
    centres_from_points,
    pair_directions,
    robust_centres_from_points,
    world_rays,
)


def similar(C_est, C_true):
    """Largest centre error after the best similarity, relative to the spread of the true centres."""
    ok = np.isfinite(C_est[:, 0])
    s, R, t = align_similarity(C_est[ok], C_true[ok])
    spread = np.sqrt(((C_true[ok] - C_true[ok].mean(0)) ** 2).sum(1).mean())
    return np.linalg.norm(s * C_est[ok] @ R.T + t - C_true[ok], axis=1).max() / spread


def normalised_error(C_est, C_true):
    """Largest centre error once both sets have mean 0 and RMS spread 1: the rotations are known, so the centres
    are in the world frame up to a translation and a positive scale (no rotation to align, even on a line)."""
    def n(C):
        C = C - C.mean(0)
        return C / np.sqrt((C ** 2).sum(1).mean())
    return np.abs(n(C_est) - n(C_true)).max()


def test_world_rays():
    s = make_scene(20, 3, noise_px=0.0, rng=np.random.default_rng(0))
    d = world_rays(s.x_true, s.K, s.R)
    assert d.shape == (3, 20, 3) and np.allclose(np.linalg.norm(d, axis=2), 1)
    to_point = s.X[None] - s.C[:, None]
    assert np.allclose(d, to_point / np.linalg.norm(to_point, axis=2, keepdims=True))
    x = s.x_true.copy()
    x[1, 4] = np.nan
    assert np.isnan(world_rays(x, s.K, s.R)[1, 4]).all()


@pytest.mark.parametrize("layout, n_views", [("general", 6), ("turntable", 16), ("forward", 8)])
def test_points_method_noise_free_exact(layout, n_views):
    s = make_scene(200, n_views, layout=layout, noise_px=0.0, rng=np.random.default_rng(1))
    C, X = centres_from_points(s.x_true, s.K, s.R)
    assert np.allclose(C.mean(0), 0, atol=1e-12) and np.isclose(np.sqrt((C ** 2).sum(1).mean()), 1)
    assert similar(C, s.C) < 1e-8
    sc, Rs, ts = align_similarity(C, s.C)
    ok = np.isfinite(X[:, 0])
    assert ok.sum() > 0.9 * s.n_points
    assert np.abs(sc * X[ok] @ Rs.T + ts - s.X[ok]).max() < 1e-8 * np.abs(s.X).max()


def test_points_method_leaves_out_views_it_cannot_place():
    s = make_scene(150, 8, layout="general", noise_px=0.0, rng=np.random.default_rng(2))
    R = s.R.copy()
    R[3] = np.nan                                             # no rotation: left out
    x = s.x_true.copy()
    x[5, 1:] = np.nan                                         # one observation: its centre is on a line, left out
    C, _ = centres_from_points(x, s.K, R)
    assert np.isnan(C[[3, 5]]).all() and np.isfinite(C[[0, 1, 2, 4, 6, 7]]).all()
    assert similar(C, s.C) < 1e-8


def test_points_method_refuses_what_it_cannot_solve():
    s = make_scene(50, 4, noise_px=0.0, rng=np.random.default_rng(3))
    with pytest.raises(ValueError, match=r"R must have shape \(4, 3, 3\)"):
        centres_from_points(s.x_true, s.K, s.R[:3])
    with pytest.raises(ValueError, match="at least two finite rotations"):
        centres_from_points(s.x_true, s.K, np.full((4, 3, 3), np.nan))
    with pytest.raises(ValueError, match="mask must be a boolean array"):
        centres_from_points(s.x_true, s.K, s.R, mask=np.ones((3, 50)))
    with pytest.raises(ValueError, match="R.* not a rotation"):
        centres_from_points(s.x_true, s.K, 2 * s.R)
    # every camera at one place (a pure rotation): the rays of a track never cross at an angle
    x = np.stack([s.x_true[0]] * 4)
    with pytest.raises(ValueError, match="cannot be tied together"):
        centres_from_points(x, s.K, np.stack([np.eye(3)] * 4))


def test_robust_points_method_drops_outliers():
    """σ = 0.5 px and 10 % uniform outliers: the outliers are flagged, the centres stay within the noise's reach.

    A uniform random pixel lands within 4 px of the true one with probability π·4²/(720·576) ≈ 1e-4: none of the
    116 outliers should be kept (a few could, in short tracks with a narrow angle, where a point may slide along its
    good rays to meet a wrong one near its epipolar line: at most 2). The centres: BA on the same data is off by
    ~5e-4 of the scene size; the linear method is not optimal but must stay within a few times that.
    """
    s = make_scene(300, 12, layout="turntable", noise_px=0.5, outlier_ratio=0.1, rng=np.random.default_rng(4))
    C, X, inl = robust_centres_from_points(s.x_meas, s.K, s.R, threshold_px=4.0)
    assert (inl & s.outliers).sum() <= 2
    assert (inl & ~s.outliers & s.visible).sum() > 0.95 * (~s.outliers & s.visible).sum()
    assert similar(C, s.C) < 0.002
    C_plain, _ = centres_from_points(s.x_meas, s.K, s.R)
    assert similar(C_plain, s.C) > 3 * similar(C, s.C)                      # the reweighting is what helps


def test_pair_directions_from_relative_poses():
    s = make_scene(20, 5, noise_px=0.0, rng=np.random.default_rng(5))
    pairs = np.array([[0, 1], [3, 1], [2, 4]])
    t_rel = np.array([relative_pose(s.R[i], s.t[i], s.R[j], s.t[j])[1] for i, j in pairs])
    d = pair_directions(s.R, pairs, 3.0 * t_rel)
    want = s.C[pairs[:, 1]] - s.C[pairs[:, 0]]
    assert np.allclose(d, want / np.linalg.norm(want, axis=1, keepdims=True))
    with pytest.raises(ValueError, match=r"t_rel\[1\] is zero"):
        pair_directions(s.R, pairs, np.array([[1.0, 0, 0], [0, 0, 0], [0, 1.0, 0]]))


def test_directions_method_turntable_exact_forward_refused():
    s = make_scene(100, 10, layout="turntable", noise_px=0.0, rng=np.random.default_rng(6))
    pairs = np.array([(i, j) for i in range(10) for j in range(i + 1, 10) if j - i <= 2 or j - i >= 8])
    C = centres_from_directions(pairs, s.C[pairs[:, 1]] - s.C[pairs[:, 0]], 10)
    assert similar(C, s.C) < 1e-9
    assert np.allclose(C - C.mean(0), C) and np.isclose(np.sqrt((C ** 2).sum(1).mean()), 1)
    # exactly collinear centres: the directions say nothing about the spacing
    C_line = np.outer(np.arange(6.0), [0.0, 0.1, 1.0])
    p = np.array([(i, j) for i in range(6) for j in range(i + 1, 6)])
    with pytest.raises(ValueError, match="one line"):
        centres_from_directions(p, C_line[p[:, 1]] - C_line[p[:, 0]], 6)
    with pytest.raises(ValueError, match="not determined"):                # a view in no pair
        centres_from_directions(pairs[pairs.max(1) < 9], (s.C[pairs[:, 1]] - s.C[pairs[:, 0]])[pairs.max(1) < 9], 10)
    with pytest.raises(ValueError, match=r"directions\[0\] is zero"):
        centres_from_directions([[0, 1]], [[0.0, 0, 0]], 2)


def straight_ahead(noise_px, seed=7, n_views=8):
    """A camera driving straight ahead (centres exactly on one line, looking along it): the degenerate case of the
    pairwise directions."""
    rng = np.random.default_rng(seed)
    X = rng.uniform([-1, -1, 1], [1, 1, 4], (300, 3))
    C = np.outer(np.linspace(-1.0, 0.0, n_views), [0.0, 0.0, 1.0])
    R = np.stack([rotation_from_angle_axis(rng.normal(scale=0.01, size=3)) for _ in range(n_views)])
    t = -np.einsum("vij,vj->vi", R, C)
    K = np.array([[800.0, 0, 360], [0, 800, 288], [0, 0, 1]])
    x = np.stack([project(P_from_KRt(K, R[v], t[v]), X) for v in range(n_views)])
    x[~((x >= 0) & (x < [720, 576])).all(-1)] = np.nan
    return x + rng.normal(scale=noise_px, size=x.shape) if noise_px else x, K, R, C


def test_straight_ahead_points_succeed_where_directions_cannot():
    x, K, R, C_true = straight_ahead(0.0)
    pairs = np.array([(i, j) for i in range(8) for j in range(i + 1, 8)])
    with pytest.raises(ValueError, match="one line"):
        centres_from_directions(pairs, C_true[pairs[:, 1]] - C_true[pairs[:, 0]], 8)
    C, _ = centres_from_points(x, K, R)
    assert normalised_error(C, C_true) < 1e-8
    # with 1 px noise the points method stays at the noise level: the depth of a point 1-4 units ahead is known to
    # about σ/f · z²/baseline ≈ 1e-3 · 4 / 0.15 ≈ 3 %, and the 300 points average that down
    x, K, R, C_true = straight_ahead(1.0)
    C, _, _ = robust_centres_from_points(x, K, R)
    assert normalised_error(C, C_true) < 0.02
