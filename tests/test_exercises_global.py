"""Notebook 09's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import numpy as np
import pytest
from _exercises import assert_passes, hints

from labutils.exercises.ex09_global import check_centres_from_directions, check_chordal_rotations
from labutils.pose.global_translations import centres_from_directions
from labutils.pose.rotation_averaging import chordal_rotation_averaging

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def chordal_reference(pairs, R_rel, weights, n_views, *, transpose=False, use_weights=True, normalise=True,
                      fix_reflection=True, project=True):
    w = np.ones(len(pairs)) if weights is None or not use_weights else np.asarray(weights, float)
    G = np.zeros((n_views, 3, n_views, 3))
    d = np.zeros(n_views)
    for (i, j), R_ij, w_ij in zip(pairs, R_rel, w):
        R_ij = R_ij.T if transpose else R_ij
        G[j, :, i, :] += w_ij * R_ij
        G[i, :, j, :] += w_ij * R_ij.T
        d[i] += w_ij
        d[j] += w_ij
    s = np.repeat(1 / np.sqrt(d), 3) if normalise else np.ones(3 * n_views)
    Y = np.linalg.eigh(G.reshape(3 * n_views, 3 * n_views) * s[:, None] * s[None, :])[1][:, -3:]
    M = (Y * s[:, None]).reshape(n_views, 3, 3)
    if fix_reflection and np.sum(np.linalg.det(M) < 0) > n_views / 2:
        M[:, :, 0] *= -1
    if not project:
        return M / np.linalg.norm(M[0]) * np.sqrt(3)
    U, _, Vt = np.linalg.svd(M)
    D = np.ones((n_views, 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[:, None, :]) @ Vt


def centres_reference(pairs, directions, n_views, *, lift=True, sign=True, check=True):
    A = np.zeros((3 * len(pairs), 3 * n_views))
    for k, ((i, j), d) in enumerate(zip(pairs, directions)):
        d = d / np.linalg.norm(d)
        D = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
        A[3 * k:3 * k + 3, 3 * j:3 * j + 3] = D
        A[3 * k:3 * k + 3, 3 * i:3 * i + 3] = -D
    N = np.tile(np.eye(3), (n_views, 1)) / np.sqrt(n_views)
    H = A.T @ A
    lam, vec = np.linalg.eigh(H + (np.trace(H) + 1) * N @ N.T if lift else H)
    if check and lam[1] <= 1e-9 * lam[-1]:
        raise ValueError("the centres are not determined by the directions (centres on one line?)")
    C = vec[:, 0].reshape(n_views, 3)
    if sign and sum(d @ (C[j] - C[i]) for (i, j), d in zip(pairs, directions)) < 0:
        C = -C
    if not lift:
        return C
    C = C - C.mean(0)
    return C / np.sqrt((C ** 2).sum(1).mean())


@pytest.mark.parametrize("check, solution", [
    (check_chordal_rotations, chordal_reference),
    (check_chordal_rotations, lambda p, R, w, n: chordal_rotation_averaging(p, R, n, w)),
    (check_centres_from_directions, centres_reference),
    (check_centres_from_directions, centres_from_directions),
])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


@pytest.mark.parametrize("kwargs, words", [
    (dict(transpose=True), "R_j = R_ij R_i"),
    (dict(use_weights=False), "weights are ignored"),
    (dict(normalise=False), "eigenvectors of G itself"),
    (dict(project=False), "not orthonormal"),
])
def test_chordal_mistakes(kwargs, words):
    assert words in hints(check_chordal_rotations(lambda p, R, w, n: chordal_reference(p, R, w, n, **kwargs),
                                                  verbose=False))


def test_chordal_reflection_left_in():
    def wrong(p, R, w, n):
        Rs = chordal_reference(p, R, w, n, fix_reflection=False)
        return Rs * np.array([1.0, 1.0, -1.0])            # as if the eigenvectors had come out mirrored
    assert "det -1" in hints(check_chordal_rotations(wrong, verbose=False))


@pytest.mark.parametrize("kwargs, words", [
    (dict(sign=False), None),
    (dict(lift=False), "translation gauge"),
    (dict(lift=False, check=False), "translation gauge"),
    (dict(check=False), "raise ValueError"),
])
def test_centres_mistakes(kwargs, words):
    report = check_centres_from_directions(lambda p, d, n: centres_reference(p, d, n, **kwargs), verbose=False)
    if words is None:            # without the sign rule the eigenvector's sign is arbitrary: mirrored in some case
        report = check_centres_from_directions(lambda p, d, n: -centres_reference(p, d, n), verbose=False)
        words = "mirrored"
    assert words in hints(report)
