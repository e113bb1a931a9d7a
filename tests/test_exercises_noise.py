"""Notebook 06's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.exercises.ex06_noise import (
    _camera,
    _correlated_cov,
    check_cramer_rao_pose,
    check_nees,
    cramer_rao_reference,
    nees_reference,
)
from labutils.sfm.noise_study import nees, pose_covariance

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def cramer_rao_pose(J, sigma):
    info = J.T @ J
    cov = sigma ** 2 * np.linalg.inv(info)
    rot_rms_deg = np.degrees(np.sqrt(np.trace(cov[:3, :3])))
    return cov, rot_rms_deg


def nees_solution(errors, cov):
    return np.einsum("ki,ij,kj->k", errors, np.linalg.inv(cov), errors)


@pytest.mark.parametrize("check, solution", [(check_cramer_rao_pose, cramer_rao_pose),
                                             (check_cramer_rao_pose, cramer_rao_reference),
                                             (check_nees, nees_solution),
                                             (check_nees, nees_reference),
                                             (check_nees, nees)])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_library_covariance_is_the_reference():
    X, K, R, t, J = _camera(0)
    assert np.allclose(pose_covariance(X, K, R, t, 2.0), cramer_rao_reference(J, 2.0)[0], rtol=1e-8)


def test_correlated_case_has_the_chi2_mean():
    """The case the NEES check draws: its mean is within 3 sd of χ²₆'s mean 6 (variance 12, 2000 draws)."""
    cov = _correlated_cov(3)
    e = np.random.default_rng(4).multivariate_normal(np.zeros(6), cov, size=2000)
    assert abs(nees_reference(e, cov).mean() - 6) < 3 * np.sqrt(12 / 2000)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_nees)


# --- exercise 1: typical mistakes ---------------------------------------------------------------------------------

def _crb(cov_of, rot_of=lambda cov: np.degrees(np.sqrt(np.trace(cov[:3, :3])))):
    def f(J, sigma):
        cov = cov_of(J, sigma)
        return cov, rot_of(cov)
    return f


@pytest.mark.parametrize("wrong, words", [
    (_crb(lambda J, s: np.linalg.inv(J.T @ J)), "left out σ²"),
    (_crb(lambda J, s: s * np.linalg.inv(J.T @ J)), "square σ"),
    (_crb(lambda J, s: np.linalg.inv(J.T @ J) / s ** 2), "multiply by σ²"),
    (_crb(lambda J, s: s ** 2 * J.T @ J), "invert the information"),
    (_crb(lambda J, s: J.T @ J / s ** 2), "*information*"),
    (_crb(lambda J, s: s ** 2 * np.linalg.pinv(J @ J.T)), "not J Jᵀ"),
])
def test_cramer_rao_covariance_mistakes(wrong, words):
    assert words in hints(check_cramer_rao_pose(wrong, verbose=False))


def _ref_cov(J, s):
    return s ** 2 * np.linalg.inv(J.T @ J)


@pytest.mark.parametrize("rot_of, words", [
    (lambda c: np.sqrt(np.trace(c[:3, :3])), "radians"),
    (lambda c: np.degrees(np.sqrt(np.trace(c[3:, 3:]))), "translation block"),
    (lambda c: np.degrees(np.trace(c[:3, :3])), "square root"),
    (lambda c: np.degrees(np.sqrt(np.diag(c)[:3]).sum()), "not the sum"),
    (lambda c: np.degrees(np.sqrt(np.trace(c[:3, :3]) / 3)), "per axis"),
])
def test_cramer_rao_rotation_mistakes(rot_of, words):
    assert words in hints(check_cramer_rao_pose(_crb(_ref_cov, rot_of), verbose=False))


# --- exercise 2: typical mistakes ---------------------------------------------------------------------------------

@pytest.mark.parametrize("wrong, words", [
    (lambda e, c: np.sqrt(nees_solution(e, c)), "Mahalanobis distance"),
    (lambda e, c: np.einsum("ki,ij,kj->k", e, c, e), "*inverse* covariance"),
    (lambda e, c: np.sum(e ** 2 / np.diag(c), axis=1), "only the diagonal"),
    (lambda e, c: nees_solution(e, c).mean(), "not their mean"),
    (lambda e, c: np.sum(e ** 2, axis=1), "|e|²"),
])
def test_nees_mistakes(wrong, words):
    assert words in hints(check_nees(wrong, verbose=False))
