import numpy as np
import pytest

from labutils.core.geometry import (
    KRt_from_P,
    P_from_KRt,
    angle_axis_from_rotation,
    camera_center,
    project,
    relative_pose,
    rotation_from_angle_axis,
    skew,
)


def random_rotation(rng):
    return rotation_from_angle_axis(rng.normal(size=3))


def test_skew_is_cross_product(rng):
    a, b = rng.normal(size=(2, 3))
    assert np.allclose(skew(a) @ b, np.cross(a, b))
    assert np.allclose(skew(a), -skew(a).T)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 0.5, 2.0, np.pi - 1e-6, np.pi])
def test_angle_axis_round_trip(angle, rng):
    axis = rng.normal(size=3)
    w = angle * axis / np.linalg.norm(axis)
    R = rotation_from_angle_axis(w)
    assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
    R_back = rotation_from_angle_axis(angle_axis_from_rotation(R))
    assert np.allclose(R_back, R, atol=1e-9)


def test_KRt_round_trip_with_skew_and_scale(rng):
    K = np.array([[3217.3, -78.6, 289.9], [0, 2292.4, -1070.5], [0, 0, 1]])
    R, t = random_rotation(rng), rng.normal(size=3)
    for scale in (1.0, -3.0, 0.01):
        K2, R2, t2 = KRt_from_P(scale * P_from_KRt(K, R, t))
        assert np.allclose(K2, K) and np.allclose(R2, R) and np.allclose(t2, t)
        assert np.linalg.det(R2) > 0


def test_KRt_from_P_rejects_bad_input():
    with pytest.raises(ValueError, match="shape"):
        KRt_from_P(np.eye(3))
    with pytest.raises(ValueError, match="non-finite"):
        KRt_from_P(np.full((3, 4), np.nan))
    with pytest.raises(ValueError, match="singular"):
        KRt_from_P(np.zeros((3, 4)))


def test_project_and_centre(rng):
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    R, t = random_rotation(rng), rng.normal(size=3)
    C = camera_center(R, t)
    assert np.allclose(R @ C + t, 0)
    X = C + (R.T @ np.array([0.1, -0.2, 5.0]))[None]
    x = project(P_from_KRt(K, R, t), X)
    assert np.allclose(x, [[320 + 800 * 0.1 / 5, 240 - 800 * 0.2 / 5]])


def test_relative_pose_maps_camera1_frame_to_camera2(rng):
    R1, R2 = random_rotation(rng), random_rotation(rng)
    t1, t2 = rng.normal(size=(2, 3))
    R, t = relative_pose(R1, t1, R2, t2)
    X = rng.normal(size=3)
    assert np.allclose(R @ (R1 @ X + t1) + t, R2 @ X + t2)
