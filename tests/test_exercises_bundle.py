"""Notebook 04's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
import scipy.sparse as sp
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.bundle.reprojection import jacobian_sparsity, reprojection_blocks, reprojection_residuals
from labutils.bundle.schur import levenberg_marquardt
from labutils.core.geometry import left_jacobian_so3, rotation_from_angle_axis
from labutils.exercises.ex04_bundle import (
    check_levenberg_marquardt,
    check_projection_jacobian,
    check_schur_step,
    check_sparsity_mask,
)

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def projection_jacobian_reference(camera_params, points_3d, camera_indices, point_indices, K, left=True):
    w, t = camera_params[camera_indices, :3], camera_params[camera_indices, 3:6]
    R = rotation_from_angle_axis(w)                                  # (n, 3, 3)
    RX = np.einsum("nij,nj->ni", R, points_3d[point_indices])
    P = RX + t                                                       # the points in the cameras
    z = P[:, 2]
    dn = np.zeros((len(P), 2, 3))
    dn[:, 0, 0] = dn[:, 1, 1] = 1 / z
    dn[:, :, 2] = -P[:, :2] / z[:, None] ** 2
    du_dP = K[:2, :2] @ dn                                           # (n, 2, 3)
    skew_RX = np.cross(np.eye(3), RX[:, None, :])                    # [RX]× per observation
    rot = -du_dP @ skew_RX @ (left_jacobian_so3(w) if left else np.eye(3))
    return np.concatenate([rot, du_dP], axis=2), du_dP @ R


def sparsity_mask_reference(n_cameras, n_points, camera_indices, point_indices):
    n = len(camera_indices)
    A = np.zeros((2 * n, 6 * n_cameras + 3 * n_points), bool)
    for i, (c, p) in enumerate(zip(camera_indices, point_indices)):
        A[2 * i:2 * i + 2, 6 * c:6 * c + 6] = True
        A[2 * i:2 * i + 2, 6 * n_cameras + 3 * p:6 * n_cameras + 3 * p + 3] = True
    return A


def schur_step_reference(J, r, n_cam_cols, mu):
    A, g = J.T @ J, J.T @ r
    A = A + mu * np.diag(np.diag(A))                                 # Marquardt's damping
    c = n_cam_cols
    U, W, V = A[:c, :c], A[:c, c:], A[c:, c:]
    V_inv = np.zeros_like(V)
    for j in range(0, V.shape[0], 3):                                # V is block diagonal: 3x3 blocks
        V_inv[j:j + 3, j:j + 3] = np.linalg.inv(V[j:j + 3, j:j + 3])
    S = U - W @ V_inv @ W.T
    delta_c = np.linalg.solve(S, -(g[:c] - W @ V_inv @ g[c:]))
    delta_p = -V_inv @ (g[c:] + W.T @ delta_c)
    return delta_c, delta_p


@pytest.mark.parametrize("check, solution", [(check_projection_jacobian, projection_jacobian_reference),
                                             (check_sparsity_mask, sparsity_mask_reference),
                                             (check_sparsity_mask, jacobian_sparsity),
                                             (check_schur_step, schur_step_reference)])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_projection_jacobian, check_sparsity_mask, check_schur_step)


# --- exercise 1: typical mistakes ---------------------------------------------------------------------------------

def test_jacobian_without_left_jacobian_fails_only_away_from_zero():
    report = check_projection_jacobian(lambda *a: projection_jacobian_reference(*a, left=False), verbose=False)
    assert [c.passed for c in report.cases] == [False, True, False]
    assert "missing J_l(ω)" in hints(report)


def test_jacobian_right_instead_of_left():
    def wrong(cp, X, ci, pi, K):
        Jc, Jp = projection_jacobian_reference(cp, X, ci, pi, K, left=False)
        Jc[:, :, :3] = Jc[:, :, :3] @ np.swapaxes(left_jacobian_so3(cp[ci, :3]), 1, 2)
        return Jc, Jp
    assert "right Jacobian" in hints(check_projection_jacobian(wrong, verbose=False))


def test_jacobian_rotation_sign():
    def wrong(*a):
        Jc, Jp = projection_jacobian_reference(*a)
        Jc[:, :, :3] *= -1
        return Jc, Jp
    assert "wrong sign" in hints(check_projection_jacobian(wrong, verbose=False))


def test_jacobian_point_block_without_R():
    def wrong(cp, X, ci, pi, K):
        Jc, _ = projection_jacobian_reference(cp, X, ci, pi, K)
        return Jc, Jc[:, :, 3:].copy()
    assert "∂P/∂X = R" in hints(check_projection_jacobian(wrong, verbose=False))


def test_jacobian_skew_dropped():
    def wrong(cp, X, ci, pi, K):
        return projection_jacobian_reference(cp, X, ci, pi, np.diag(np.diag(K)))
    report = check_projection_jacobian(wrong, verbose=False)
    assert [c.passed for c in report.cases] == [True, True, False] and "skew" in hints(report)


def test_jacobian_unrotated_point():
    def wrong(cp, X, ci, pi, K):
        Jc, Jp = projection_jacobian_reference(cp, X, ci, pi, K)
        du = Jc[:, :, 3:]
        Jc[:, :, :3] = -du @ np.cross(np.eye(3), X[pi][:, None, :]) @ left_jacobian_so3(cp[ci, :3])
        return Jc, Jp
    assert "[X]×" in hints(check_projection_jacobian(wrong, verbose=False))


# --- exercise 2: typical mistakes ---------------------------------------------------------------------------------

def _mask_variant(change):
    def f(V, M, ci, pi):
        return change(sparsity_mask_reference(V, M, ci, pi), V, M)
    return f


def test_mask_without_point_block():
    def change(A, V, M):
        A[:, 6 * V:] = False
        return A
    assert "point columns are empty" in hints(check_sparsity_mask(_mask_variant(change), verbose=False))


def test_mask_points_first():
    def change(A, V, M):
        return np.hstack([A[:, 6 * V:], A[:, :6 * V]])
    assert "cameras come first" in hints(check_sparsity_mask(_mask_variant(change), verbose=False))


def test_mask_one_row_per_observation():
    def change(A, V, M):
        return A[0::2]
    assert "two residuals" in hints(check_sparsity_mask(_mask_variant(change), verbose=False))


def test_mask_only_x_rows():
    def change(A, V, M):
        A[1::2] = False
        return A
    assert "both rows" in hints(check_sparsity_mask(_mask_variant(change), verbose=False))


def test_mask_shape_from_the_indices():
    def wrong(V, M, ci, pi):
        return sparsity_mask_reference(int(ci.max()) + 1, int(pi.max()) + 1, ci, pi)
    report = check_sparsity_mask(wrong, verbose=False)
    assert [c.passed for c in report.cases] == [True, True, False] and "n_cameras and n_points" in hints(report)


def test_mask_too_full():
    def change(A, V, M):
        A[:, :6 * V] = True                                          # every camera for every row
        return A
    assert "too many" in hints(check_sparsity_mask(_mask_variant(change), verbose=False))


# --- exercise 3: typical mistakes ---------------------------------------------------------------------------------

def _schur_variant(damping="marquardt", rhs_sign=-1, S_sign=-1, back_sign=1, diagonal_V=False):
    def f(J, r, c, mu):
        A, g = J.T @ J, J.T @ r
        if damping == "marquardt":
            A = A + mu * np.diag(np.diag(A))
        elif damping == "levenberg":
            A = A + mu * np.eye(len(A))
        elif damping == "U only":
            A[:c, :c] += mu * np.diag(np.diag(A[:c, :c]))
        U, W, V = A[:c, :c], A[:c, c:], A[c:, c:]
        V_inv = np.diag(1 / np.diag(V)) if diagonal_V else np.linalg.inv(V)
        dc = np.linalg.solve(U + S_sign * W @ V_inv @ W.T, rhs_sign * (g[:c] - W @ V_inv @ g[c:]))
        return dc, -V_inv @ (g[c:] + back_sign * W.T @ dc)
    return f


@pytest.mark.parametrize("kwargs, words", [
    (dict(damping="levenberg"), "Levenberg's μI"),
    (dict(damping="U only"), "only U is damped"),
    (dict(damping="none"), "no damping"),
    (dict(rhs_sign=1), "wrong sign"),
    (dict(S_sign=1), "U - W V⁻¹ Wᵀ"),
    (dict(back_sign=-1), "back-substitution"),
    (dict(diagonal_V=True), "3×3 blocks"),
])
def test_schur_mistakes(kwargs, words):
    assert words in hints(check_schur_step(_schur_variant(**kwargs), verbose=False))


def test_mask_without_the_camera_offset_is_named():
    def f(V, M, ci, pi):
        A = sparsity_mask_reference(V, M, ci, pi)
        A[:, 6 * V:] = False
        for i, p in enumerate(pi):
            A[2 * i:2 * i + 2, 3 * p:3 * p + 3] = True                 # 3·p, without the 6·n_cameras before it
        return A
    assert "6·n_cameras + 3·p" in hints(check_sparsity_mask(f, verbose=False))


# --- exercise 4: the Levenberg–Marquardt loop -----------------------------------------------------------------------

def _lm(variant=None):
    """The notebook's reference loop (with the library's blocks and dense step), or a variant with one mistake."""
    def lm(camera_params, points_3d, camera_indices, point_indices, points_2d, K, *, mu=1e-4, max_iter=50, tol=1e-10):
        cp, X = np.array(camera_params, float), np.array(points_3d, float)
        V, M, n = len(cp), len(X), len(camera_indices)
        rows = np.repeat(np.arange(2 * n), 9)
        cols = np.concatenate([6 * camera_indices[:, None] + np.arange(6),
                               6 * V + 3 * point_indices[:, None] + np.arange(3)], axis=1)
        cols = np.repeat(cols, 2, axis=0).ravel()

        def residual_and_cost(cp, X):
            r = reprojection_residuals(cp, X, camera_indices, point_indices, points_2d, K)
            return r, (1.0 if variant == "no half" else 0.5) * r @ r

        r, cost = residual_and_cost(cp, X)
        costs = [cost]
        for _ in range(max_iter):
            Jc, Jp = reprojection_blocks(cp, X, camera_indices, point_indices, K)
            J = sp.csr_matrix((np.concatenate([Jc, Jp], axis=2).ravel(), (rows, cols)), shape=(2 * n, 6 * V + 3 * M))
            dc, dp = schur_step_reference(J.toarray(), r, 6 * V, mu)
            sign = -1 if variant == "minus" else 1
            cp_new, X_new = cp + sign * dc.reshape(V, 6), X + sign * dp.reshape(M, 3)
            r_new, cost_new = residual_and_cost(cp_new, X_new)
            if cost_new < cost or variant == "always accept":
                done = cost - cost_new <= tol * cost
                cp, X, r, cost = cp_new, X_new, r_new, cost_new
                mu = mu if variant == "mu never shrinks" else mu / 3
            else:
                mu *= 4
                done = mu > 1e12
            costs.append(cost)
            if done and variant != "never stops":
                break
        return cp, X, np.array(costs)
    return lm


def test_lm_reference_and_library_pass():
    assert_passes(check_levenberg_marquardt, _lm(), min_cases=3)
    assert_passes(check_levenberg_marquardt, levenberg_marquardt)


@pytest.mark.parametrize("variant, words", [
    ("no half", "½ Σ r²"),
    ("minus", "no step was ever accepted"),
    ("always accept", "rejected"),
    ("mu never shrinks", "μ ← μ/3"),
    ("never stops", "stop when an accepted step"),
])
def test_lm_mistakes(variant, words):
    assert words in hints(check_levenberg_marquardt(_lm(variant), verbose=False))


def test_lm_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_levenberg_marquardt)


def test_library_references_have_the_exercises_signatures():
    """yours' fallbacks: the dense Schur step equals the sparse library step; the blocks are the sparse J's."""
    from labutils.bundle import reprojection_jacobian, schur_step, schur_step_dense
    rng = np.random.default_rng(0)
    cp = np.c_[0.3 * rng.normal(size=(3, 3)), rng.normal(size=(3, 2)), 6 + rng.normal(size=3)]
    X = rng.normal(size=(8, 3))
    ci, pi = np.repeat(np.arange(3), 8), np.tile(np.arange(8), 3)
    x = rng.normal(size=(24, 2)) * 50 + 300
    K = np.array([[800.0, 2.0, 320.0], [0, 790.0, 240.0], [0, 0, 1]])
    J = reprojection_jacobian(cp, X, ci, pi, K)
    Jc, Jp = reprojection_blocks(cp, X, ci, pi, K)
    assert np.allclose(J.toarray()[0::2, :6][ci == 0], Jc[ci == 0, 0]) and Jp.shape == (24, 2, 3)
    r = reprojection_residuals(cp, X, ci, pi, x, K)
    dc, dp = schur_step_dense(J, r, 18, 1e-3)
    lib = schur_step(cp, X, ci, pi, x, K, mu=1e-3)
    assert np.allclose(dc, lib.delta_c.ravel(), rtol=1e-6) and np.allclose(dp, lib.delta_p.ravel(), rtol=1e-6)
    with pytest.raises(ValueError, match="n_cam_cols"):
        schur_step_dense(J, r, 17, 1e-3)
