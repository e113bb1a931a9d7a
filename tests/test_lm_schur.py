"""LM-Schur's single step (schur_step): the damped normal equations solved directly, the solver's own iteration,
and bad input."""
import numpy as np
import pytest

from labutils.bundle.reprojection import camera_params_from_Rt, reprojection_jacobian, reprojection_residuals
from labutils.bundle.schur import lm_schur, schur_step
from labutils.core.scene import observations
from labutils.core.synthetic import make_scene


@pytest.fixture(scope="module")
def problem():
    """A small scene away from its optimum (cameras and points perturbed), plain least squares."""
    rng = np.random.default_rng(4)
    s = make_scene(25, 4, noise_px=1.0, rng=rng)
    ci, pi, x = observations(s.x_meas)
    cp = camera_params_from_Rt(s.R, s.t) + 0.02 * rng.normal(size=(4, 6))
    X = s.X + 0.02 * rng.normal(size=s.X.shape)
    return cp, X, ci, pi, x, s.K


@pytest.mark.parametrize("mu", [1e-6, 1e-2, 10.0])
def test_step_solves_the_damped_normal_equations(problem, mu):
    cp, X, ci, pi, x, K = problem
    step = schur_step(cp, X, ci, pi, x, K, mu=mu)
    J = reprojection_jacobian(cp, X, ci, pi, K).toarray()
    r = reprojection_residuals(cp, X, ci, pi, x, K)
    A, g = J.T @ J, J.T @ r
    delta = np.linalg.solve(A + mu * np.diag(np.diag(A)), -g)
    got = np.r_[step.delta_c.ravel(), step.delta_p.ravel()]
    assert np.abs(got - delta).max() < 1e-8 * np.abs(delta).max()
    # the blocks are those of JᵀJ and Jᵀr
    c = cp.size
    assert np.allclose(step.U[1], A[6:12, 6:12]) and np.allclose(step.V[2], A[c + 6:c + 9, c + 6:c + 9])
    assert np.allclose(np.r_[step.g_c.ravel(), step.g_p.ravel()], g)
    # S is the Schur complement of the damped point block
    Ad = A + mu * np.diag(np.diag(A))
    S = Ad[:c, :c] - Ad[:c, c:] @ np.linalg.solve(Ad[c:, c:], Ad[c:, :c])
    assert np.abs(step.S - S).max() < 1e-8 * np.abs(S).max()


def test_step_is_the_solvers_first_iteration(problem):
    """lm_schur starts with μ = 1e-4; its first accepted step is schur_step's (to rounding)."""
    cp, X, ci, pi, x, K = problem
    out = lm_schur(cp, X, ci, pi, x, K[None], np.ones(cp.shape, bool), np.ones(len(X), bool), "linear", 1.0, 1,
                   1e-6, False)
    step = schur_step(cp, X, ci, pi, x, K, mu=1e-4)
    assert out["n_iter"] == 1
    assert np.allclose(out["cp"], cp + step.delta_c, rtol=0, atol=1e-12)
    assert np.allclose(out["X"], X + step.delta_p, rtol=0, atol=1e-12)


@pytest.mark.parametrize("mu", [0.0, -1.0, np.nan, np.inf])
def test_bad_mu_is_refused(problem, mu):
    with pytest.raises(ValueError, match="mu"):
        schur_step(*problem, mu=mu)


def test_bad_problem_is_refused(problem):
    cp, X, ci, pi, x, K = problem
    with pytest.raises(ValueError, match="points_2d"):
        schur_step(cp, X, ci, pi, x[:-1], K, mu=1.0)
    with pytest.raises(ValueError, match="camera_params"):
        schur_step(cp[:, :5], X, ci, pi, x, K, mu=1.0)


def test_sparse_reduced_system_gives_the_dense_step():
    """The sparse L D Lᵀ of the reduced camera system (large, banded problems) and dense Cholesky give one step,
    and a system that is not positive definite is refused by both (a rejected step for the LM loop)."""
    from labutils.bundle.reprojection import project_observations
    from labutils.bundle.schur import _damped_step, _normal_blocks, _SchurStructure
    from labutils.tools.reference import synthetic_ba_problem

    cp, X, ci, pi, x, K = synthetic_ba_problem(40, 15, rng=np.random.default_rng(1))
    u, Jc, Jp = project_observations(cp, X, ci, pi, K[None], jac=True)
    steps = []
    for dense in (True, False):
        st = _SchurStructure(ci, pi, len(cp), len(X), 6, dense=dense)
        U, Vp, W, gc, gp = _normal_blocks(st, Jc, Jp, u - x)
        Dc, Dp = np.diagonal(U, axis1=1, axis2=2), np.diagonal(Vp, axis1=1, axis2=2)
        steps.append(_damped_step(st, U, Vp, W, gc, gp, Dc, Dp, 1e-3, ci, pi))
        with pytest.raises(np.linalg.LinAlgError):
            _damped_step(st, -U, Vp, W, gc, gp, Dc, Dp, 1e-3, ci, pi)
    (dc, dp, S, _), (dc_s, dp_s, S_s, _) = steps
    assert np.abs(S_s.toarray() - S).max() < 1e-9 * np.abs(S).max()
    assert np.abs(dc_s - dc).max() < 1e-8 * np.abs(dc).max() and np.abs(dp_s - dp).max() < 1e-8 * np.abs(dp).max()
