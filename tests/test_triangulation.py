import numpy as np
import pytest

from labutils.core.synthetic import make_scene
from labutils.twoview.triangulation import triangulate, triangulate_multiview


def test_two_view_recovers_truth_noise_free(rng):
    s = make_scene(100, 2, noise_px=0.0, rng=rng)
    x1, x2, idx = s.pair(0, 1, which="true")
    X = triangulate(s.P[0], s.P[1], x1, x2)
    assert X.shape == (len(idx), 3) and len(idx) > 90
    assert np.abs(X - s.X[idx]).max() < 1e-9


def test_multiview_with_missing_views(rng):
    s = make_scene(300, 36, layout="turntable", noise_px=0.0, rng=rng)
    X = triangulate_multiview(s.P, s.x_true)
    assert np.abs(X - s.X).max() < 1e-9
    one = s.x_true.copy()
    one[1:, 0] = np.nan
    assert np.isnan(triangulate_multiview(s.P, one)[0]).all()


def test_noisy_error_scales_with_noise(rng):
    errs = []
    for sigma in (0.5, 2.0):
        s = make_scene(400, 2, noise_px=sigma, rng=np.random.default_rng(3))
        x1, x2, idx = s.pair(0, 1)
        X = triangulate(s.P[0], s.P[1], x1, x2)
        errs.append(np.median(np.linalg.norm(X - s.X[idx], axis=1)))
    assert 2.5 < errs[1] / errs[0] < 6.0       # linear in sigma (ratio 4), with sampling slack


def test_bad_input(rng):
    s = make_scene(10, 2, rng=rng)
    s.x_true[np.isnan(s.x_true)] = 0.0
    with pytest.raises(ValueError, match="shape"):
        triangulate(s.P[0], s.P[1], s.x_true[0][:, :1], s.x_true[1])
    with pytest.raises(ValueError, match="row by row"):
        triangulate(s.P[0], s.P[1], s.x_true[0][:5], s.x_true[1])
    with pytest.raises(ValueError, match="non-finite"):
        triangulate(s.P[0], s.P[1], np.full((10, 2), np.nan), s.x_true[1])
    with pytest.raises(ValueError, match="baseline"):
        triangulate(s.P[0], 2 * s.P[0], s.x_true[0], s.x_true[0])
    with pytest.raises(ValueError, match=r"\(V, N, 2\)"):
        triangulate_multiview(s.P, s.x_true[:1])
