"""Notebook 02's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.exercises.ex02_essential import check_choose_pose, check_four_poses, check_triangulate_linear
from labutils.twoview.essential import decompose_essential
from labutils.twoview.triangulation import triangulate

W = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
P1 = np.hstack([np.eye(3), np.zeros((3, 1))])

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def four_poses_reference(E, fix_det=True, transpose_vt=False, t_from="U"):
    U, _, Vt = np.linalg.svd(E)
    if fix_det:
        U, Vt = U * np.sign(np.linalg.det(U)), Vt * np.sign(np.linalg.det(Vt))
    V_t = Vt.T if transpose_vt else Vt
    t = U[:, 2] if t_from == "U" else Vt[2]
    Ra, Rb = U @ W @ V_t, U @ W.T @ V_t
    return [(Ra, t), (Ra, -t), (Rb, t), (Rb, -t)]


def choose_pose_reference(poses, y1, y2, camera2=True, use_t=True, all_points=False):
    counts = []
    for R, t in poses:
        X = triangulate(P1, np.hstack([R, t[:, None]]), y1, y2)
        front = X[:, 2] > 0
        if camera2:
            front &= (X @ R[2] + (t[2] if use_t else 0.0)) > 0
        counts.append(front.sum())
    if all_points:
        return next(p for p, c in zip(poses, counts) if c == len(y1))
    return poses[int(np.argmax(counts))]


def triangulate_linear_reference(P1, P2, x1, x2, unit_rows=False, dehom=True, vector=-1, rows="right"):
    X = []
    for (u1, v1), (u2, v2) in zip(x1, x2):
        if rows == "right":
            A = np.array([u1 * P1[2] - P1[0], v1 * P1[2] - P1[1], u2 * P2[2] - P2[0], v2 * P2[2] - P2[1]])
        else:
            A = np.array([u1 * P1[2] - P1[1], v1 * P1[2] - P1[0], u2 * P2[2] - P2[1], v2 * P2[2] - P2[0]])
        if unit_rows:
            A /= np.linalg.norm(A, axis=1, keepdims=True)
        X_h = np.linalg.svd(A)[2][vector]
        X.append(X_h[:3] / X_h[3] if dehom else X_h)
    return np.array(X)


@pytest.mark.parametrize("check, solution", [
    (check_four_poses, four_poses_reference),
    (check_four_poses, decompose_essential),
    (check_four_poses, lambda E: four_poses_reference(E)[::-1]),
    (check_choose_pose, choose_pose_reference),
    (check_triangulate_linear, triangulate_linear_reference),
    (check_triangulate_linear, lambda *a: triangulate_linear_reference(*a, unit_rows=True)),
    (check_triangulate_linear, triangulate),
])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_four_poses, check_choose_pose, check_triangulate_linear)


# --- exercise 1: the four poses -----------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, words", [
    (dict(fix_det=False), "det -1"),
    (dict(transpose_vt=True), "without transposing Vt again"),
    (dict(t_from="V"), "left* null vector"),
])
def test_four_poses_mistakes(kwargs, words):
    assert words in hints(check_four_poses(lambda E: four_poses_reference(E, **kwargs), verbose=False))


def test_four_poses_with_singular_values_in_r():
    def wrong(E):
        U, s, Vt = np.linalg.svd(E)
        U, Vt = U * np.sign(np.linalg.det(U)), Vt * np.sign(np.linalg.det(Vt))
        R = U @ np.diag(s) @ W @ Vt
        return [(R, U[:, 2]), (R, -U[:, 2]), (U @ W.T @ Vt, U[:, 2]), (U @ W.T @ Vt, -U[:, 2])]
    assert "not a rotation" in hints(check_four_poses(wrong, verbose=False))


def test_four_poses_one_rotation_twice():
    def wrong(E):
        poses = four_poses_reference(E)
        return [poses[0], poses[1], poses[0], poses[1]]
    assert "same rotation twice" in hints(check_four_poses(wrong, verbose=False))


def test_four_poses_t_not_unit():
    def wrong(E):
        return [(R, 2 * t) for R, t in four_poses_reference(E)]
    assert "unit vector" in hints(check_four_poses(wrong, verbose=False))


def test_four_poses_t_as_column():
    assert "U[:, 2]" in hints(check_four_poses(lambda E: [(R, t[:, None]) for R, t in four_poses_reference(E)],
                                               verbose=False))


# --- exercise 2: the cheirality choice ---------------------------------------------------------------------------

def test_choose_pose_camera_1_only():
    found = hints(check_choose_pose(lambda *a: choose_pose_reference(*a, camera2=False), verbose=False))
    assert "in front of camera 2 too" in found and "camera 1 alone" in found


def test_choose_pose_without_t():
    found = hints(check_choose_pose(lambda *a: choose_pose_reference(*a, use_t=False), verbose=False))
    assert "you left out t" in found and "with t" in found


def test_choose_pose_every_point_in_front():
    assert "the most points in front" in hints(check_choose_pose(lambda *a: choose_pose_reference(*a, all_points=True),
                                                      verbose=False))


def test_choose_pose_first_candidate():
    assert "choose the one with the most" in hints(check_choose_pose(lambda poses, y1, y2: poses[0], verbose=False))


def test_choose_pose_new_pose():
    assert "unchanged" in hints(check_choose_pose(lambda poses, y1, y2: (poses[0][0], 2 * poses[0][1]),
                                                  verbose=False))


# --- exercise 3: linear triangulation ----------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, words", [
    (dict(dehom=False), "(N, 3)"),
    (dict(vector=0), "smallest singular value"),
    (dict(rows="swapped"), "x goes with the first row"),
])
def test_triangulate_mistakes(kwargs, words):
    assert words in hints(check_triangulate_linear(lambda *a: triangulate_linear_reference(*a, **kwargs),
                                                   verbose=False))


def test_triangulate_camera_1_twice():
    assert "camera 1's P for both" in hints(check_triangulate_linear(
        lambda P1, P2, x1, x2: triangulate_linear_reference(P1, P1, x1, x2), verbose=False))


def test_triangulate_not_dehomogenised():
    def wrong(P1, P2, x1, x2):
        return triangulate_linear_reference(P1, P2, x1, x2, dehom=False)[:, :3]
    assert "4th coordinate" in hints(check_triangulate_linear(wrong, verbose=False))
