import numpy as np
import pytest

from labutils.core.geometry import rotation_from_angle_axis
from labutils.core.metrics import align_similarity, angle_between_deg, pose_errors, rotation_error_deg


def test_rotation_error_small_and_large():
    for deg in (1e-7, 0.3, 90.0, 179.9):
        R = rotation_from_angle_axis(np.radians(deg) * np.array([0.6, 0.0, 0.8]))
        assert np.isclose(rotation_error_deg(R, np.eye(3)), deg, rtol=1e-6)
    assert np.isclose(angle_between_deg([1, 0, 0], [1, 1e-9, 0]), np.degrees(1e-9), rtol=1e-6)


def test_similarity_alignment_recovers_transform(rng):
    A = rng.normal(size=(20, 3))
    R = rotation_from_angle_axis(rng.normal(size=3))
    s, R_est, t_est = align_similarity(A, 3.0 * A @ R.T + [1, 2, 3])
    assert np.isclose(s, 3.0) and np.allclose(R_est, R) and np.allclose(t_est, [1, 2, 3])
    with pytest.raises(ValueError, match="collinear"):
        align_similarity(np.outer(np.arange(5.0), [1, 1, 1]), np.outer(np.arange(5.0), [1, 1, 1]))


def test_pose_errors_zero_under_similarity(rng):
    R = np.stack([rotation_from_angle_axis(rng.normal(size=3)) for _ in range(5)])
    t = rng.normal(size=(5, 3))
    G = rotation_from_angle_axis(rng.normal(size=3))
    # a similarity of the world: X' = 2 G X + c  => R' = R G.T, t' = 2 t - R' c
    c = rng.normal(size=3)
    R2 = R @ G.T
    t2 = 2 * t - np.einsum("vij,j->vi", R2, c)
    rot, cen = pose_errors(R2, t2, R, t)
    assert rot.max() < 1e-9 and cen.max() < 1e-9
