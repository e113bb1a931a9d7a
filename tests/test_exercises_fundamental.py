"""Notebook 01's self-checks: the reference solutions pass every case, and typical mistakes get their own hint."""
import re

import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written, hints

from labutils.exercises.ex01_fundamental import (
    check_eight_point,
    check_gold_standard_residuals,
    check_normalisation_matrix,
    check_sampson,
)
from labutils.twoview.epipolar import fundamental_8point, hartley_normalisation, sampson_distance
from labutils.twoview.gold_standard import gold_standard_residuals

# --- the reference solutions, as written in the notebook ---------------------------------------------------------


def normalisation_reference(x):
    c = x.mean(0)
    s = np.sqrt(2) / np.linalg.norm(x - c, axis=1).mean()
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])


def _h(x):
    return np.hstack([x, np.ones((len(x), 1))])


def eight_point_reference(x1, x2, normalise=hartley_normalisation, rank2_first=True, vector=-1, denorm="T"):
    T1, T2 = normalise(x1), normalise(x2)
    y1, y2 = _h(x1) @ T1.T, _h(x2) @ T2.T
    A = (y2[:, :, None] * y1[:, None, :]).reshape(-1, 9)
    F_hat = np.linalg.svd(A)[2][vector].reshape(3, 3)
    if rank2_first:
        U, s, Vt = np.linalg.svd(F_hat)
        F_hat = U @ np.diag([s[0], s[1], 0.0]) @ Vt
    F = {"T": T2.T @ F_hat @ T1, "none": F_hat, "swapped": T1.T @ F_hat @ T2,
         "inverse": np.linalg.inv(T2).T @ F_hat @ np.linalg.inv(T1)}[denorm]
    if not rank2_first:
        U, s, Vt = np.linalg.svd(F)
        F = U @ np.diag([s[0], s[1], 0.0]) @ Vt
    return F / np.linalg.norm(F)


def sampson_reference(F, x1, x2):
    Fx1, Ftx2 = _h(x1) @ F.T, _h(x2) @ F
    num = np.abs(np.sum(_h(x2) * Fx1, axis=1))
    return num / np.sqrt(Fx1[:, 0] ** 2 + Fx1[:, 1] ** 2 + Ftx2[:, 0] ** 2 + Ftx2[:, 1] ** 2)


@pytest.mark.parametrize("check, solution", [
    (check_normalisation_matrix, normalisation_reference),
    (check_normalisation_matrix, hartley_normalisation),
    (check_eight_point, eight_point_reference),
    (check_eight_point, lambda x1, x2: eight_point_reference(x1, x2, normalise=normalisation_reference)),
    (check_eight_point, lambda x1, x2: fundamental_8point(x1, x2, degeneracy=None)),
    (check_sampson, sampson_reference),
    (check_sampson, sampson_distance),
])
def test_reference_solutions_pass(check, solution):
    assert_passes(check, solution)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_normalisation_matrix, check_eight_point, check_sampson)


def test_a_student_error_is_a_hint_not_an_exception():
    report = check_sampson(lambda F, x1, x2: 1 / 0, verbose=False)
    assert "ZeroDivisionError" in hints(report)


# --- exercise 1: the normalisation --------------------------------------------------------------------------------

def _normalisation(scale_to=2 ** 0.5, centre=True, scale_translation=True, spread="mean"):
    def f(x):
        c = x.mean(0)
        d = np.linalg.norm(x - c, axis=1)
        s = scale_to / (d.mean() if spread == "mean" else np.sqrt((d ** 2).mean()))
        t = (-s * c if scale_translation else -c) if centre else np.zeros(2)
        return np.array([[s, 0, t[0]], [0, s, t[1]], [0, 0, 1]])
    return f


@pytest.mark.parametrize("wrong, words", [
    (_normalisation(scale_to=1.0), "mean distance 1"),
    (_normalisation(centre=False), "does not move the centroid"),
    (_normalisation(scale_translation=False), "translation must be scaled too"),
    (_normalisation(spread="rms"), "RMS distance"),
    (lambda x: np.linalg.inv(normalisation_reference(x)), "T⁻¹"),
    (lambda x: normalisation_reference(x).T, "transposed"),
    (lambda x: normalisation_reference(x)[:2], "(3, 3)"),
])
def test_normalisation_mistakes(wrong, words):
    assert words in hints(check_normalisation_matrix(wrong, verbose=False))


def test_normalisation_from_the_pixel_origin():
    def wrong(x):
        c = x.mean(0)
        s = np.sqrt(2) / np.linalg.norm(x, axis=1).mean()
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])
    assert "from the centroid" in hints(check_normalisation_matrix(wrong, verbose=False))


def test_normalisation_per_axis():
    def wrong(x):
        c = x.mean(0)
        sx, sy = np.sqrt(2) / np.abs(x - c).mean(0)
        return np.array([[sx, 0, -sx * c[0]], [0, sy, -sy * c[1]], [0, 0, 1]])
    assert "one scale s for both axes" in hints(check_normalisation_matrix(wrong, verbose=False))


# --- exercise 2: the 8-point --------------------------------------------------------------------------------------

def test_eight_point_without_rank_2():
    def wrong(x1, x2):
        T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
        y1, y2 = _h(x1) @ T1.T, _h(x2) @ T2.T
        A = (y2[:, :, None] * y1[:, None, :]).reshape(-1, 9)
        return T2.T @ np.linalg.svd(A)[2][-1].reshape(3, 3) @ T1
    assert "rank 3" in hints(check_eight_point(wrong, verbose=False))


@pytest.mark.parametrize("kwargs, words", [
    (dict(denorm="none"), "still in normalised coordinates"),
    (dict(denorm="swapped"), "T1 and T2 swapped"),
    (dict(denorm="inverse"), "denormalised with T⁻¹"),
    (dict(rank2_first=False), "rank 2 after denormalising"),
    (dict(vector=0), "*largest* singular value"),
    (dict(normalise=lambda x: np.eye(3)), "skipped the normalisation"),
])
def test_eight_point_mistakes(kwargs, words):
    assert words in hints(check_eight_point(lambda x1, x2: eight_point_reference(x1, x2, **kwargs), verbose=False))


def test_eight_point_transposed():
    assert "transposed" in hints(check_eight_point(lambda x1, x2: eight_point_reference(x1, x2).T, verbose=False))


def test_eight_point_with_a_wrong_normalisation_is_caught():
    """A student's own normalisation to mean distance 1 gives a (slightly) different F with noise."""
    report = check_eight_point(lambda x1, x2: eight_point_reference(x1, x2, normalise=_normalisation(scale_to=1.0)),
                               verbose=False)
    assert "another normalisation" in hints(report) and "mean distance 1" in hints(report)


# --- exercise 3: the Sampson distance -----------------------------------------------------------------------------

def _parts(F, x1, x2):
    Fx1, Ftx2 = _h(x1) @ F.T, _h(x2) @ F
    return np.sum(_h(x2) * Fx1, axis=1), Fx1, Ftx2


@pytest.mark.parametrize("wrong, words", [
    (lambda F, x1, x2: sampson_reference(F, x1, x2) ** 2, "squared distance"),
    (lambda F, x1, x2: np.abs(_parts(F, x1, x2)[0]) / np.hypot(*_parts(F, x1, x2)[1][:, :2].T), "image 2"),
    (lambda F, x1, x2: np.abs(_parts(F, x1, x2)[0]) / np.hypot(*_parts(F, x1, x2)[2][:, :2].T), "image 1"),
    (lambda F, x1, x2: np.abs(_parts(F, x1, x2)[0]), "algebraic error"),
    (lambda F, x1, x2: sampson_reference(F.T, x1, x2), "transposed"),
    (lambda F, x1, x2: sampson_reference(F, x1, x2)[:, None], "shape"),
])
def test_sampson_mistakes(wrong, words):
    assert words in hints(check_sampson(wrong, verbose=False))


def test_sampson_signed():
    def wrong(F, x1, x2):
        alg, Fx1, Ftx2 = _parts(F, x1, x2)
        return alg / np.sqrt((Fx1[:, :2] ** 2).sum(1) + (Ftx2[:, :2] ** 2).sum(1))
    assert "absolute value" in hints(check_sampson(wrong, verbose=False))


def test_sampson_third_component():
    def wrong(F, x1, x2):
        alg, Fx1, Ftx2 = _parts(F, x1, x2)
        return np.abs(alg) / np.sqrt((Fx1 ** 2).sum(1) + (Ftx2 ** 2).sum(1))
    assert "third component" in hints(check_sampson(wrong, verbose=False))


def test_sampson_symmetric_epipolar_distance():
    def wrong(F, x1, x2):
        alg, Fx1, Ftx2 = _parts(F, x1, x2)
        return np.sqrt((alg / np.hypot(*Fx1[:, :2].T)) ** 2 + (alg / np.hypot(*Ftx2[:, :2].T)) ** 2)
    assert "symmetric epipolar distance" in hints(check_sampson(wrong, verbose=False))


def test_eight_point_hint_names_the_wrong_normalisation():
    report = check_eight_point(lambda x1, x2: eight_point_reference(x1, x2, normalise=_normalisation(centre=False)),
                               verbose=False)
    assert "another normalisation" in hints(report) and "centroid" in hints(report)


def test_eight_point_reduced_svd():
    def wrong(x1, x2):
        T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
        y1, y2 = _h(x1) @ T1.T, _h(x2) @ T2.T
        A = (y2[:, :, None] * y1[:, None, :]).reshape(-1, 9)
        U, s, Vt = np.linalg.svd(np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 3))
        return T2.T @ U @ np.diag([s[0], s[1], 0.0]) @ Vt @ T1
    assert "full_matrices=True" in hints(check_eight_point(wrong, verbose=False))


# --- issue 19: the hints name the right mistake --------------------------------------------------------------------

def _without_rank_2(x1, x2):
    T1, T2 = hartley_normalisation(x1), hartley_normalisation(x2)
    y1, y2 = _h(x1) @ T1.T, _h(x2) @ T2.T
    A = (y2[:, :, None] * y1[:, None, :]).reshape(-1, 9)
    return T2.T @ np.linalg.svd(A)[2][-1].reshape(3, 3) @ T1


def test_rank_3_hint_shows_the_size_of_the_third_singular_value():
    hint = hints(check_eight_point(_without_rank_2, verbose=False))
    third = re.search(r"singular values 1\.0e\+00, \d\.\de-\d\d, (\d\.\de-\d\d)", hint)
    assert third and float(third.group(1)) > 0, hint                  # not printed as 0.0


def test_exactly_eight_points_without_normalisation_names_the_normalisation():
    report = check_eight_point(lambda x1, x2: eight_point_reference(x1, x2, normalise=lambda x: np.eye(3)),
                               verbose=False)
    minimal = next(c for c in report.cases if "exactly eight" in c.name)
    assert not minimal.passed and minimal.hint.startswith("you skipped the normalisation"), minimal.hint


def test_a_self_check_names_the_students_unwritten_helper(capsys):
    def normalisation_matrix(x):
        raise NotImplementedError("write the body of normalisation_matrix(x) here")

    def eight_point(x1, x2):
        T1 = normalisation_matrix(x1)
        return T1

    report = check_eight_point(eight_point)
    out = capsys.readouterr().out
    assert not report.written and report.helper == "normalisation_matrix"
    assert "your eight_point calls normalisation_matrix, which is not written yet" in out, out


def gold_reference(P2, points, x1, x2):
    X = np.column_stack([points[:, 0], points[:, 1], np.ones(len(points)), points[:, 2]])
    y = X @ P2.T
    return np.hstack([points[:, :2] - x1, y[:, :2] / y[:, 2:] - x2]).ravel()


def test_gold_standard_residuals_reference_and_stub(capsys):
    assert_passes(check_gold_standard_residuals, gold_reference, min_cases=4)
    assert_passes(check_gold_standard_residuals, gold_standard_residuals, min_cases=4)
    assert_stubs_not_written(capsys, check_gold_standard_residuals)


def _gs_wrong(kind):
    def f(P2, points, x1, x2):
        n = len(points)
        X = np.column_stack([points[:, 0], points[:, 1], np.ones(n), points[:, 2]])
        if kind == "rho third":
            X = np.column_stack([points[:, 0], points[:, 1], points[:, 2], np.ones(n)])
        y = X @ P2.T
        x2_hat = y[:, :2] if kind == "no division" else y[:, :2] / y[:, 2:]
        r1, r2 = points[:, :2] - x1, x2_hat - x2
        if kind == "grouped":
            return np.hstack([r1.ravel(), r2.ravel()])
        if kind == "cost":
            return (r1 ** 2).sum(1) + (r2 ** 2).sum(1)
        r = np.hstack([r1, r2]).ravel()
        return -r if kind == "sign" else r
    return f


@pytest.mark.parametrize("kind, words", [
    ("grouped", "point by point"),
    ("sign", "predicted minus measured"),
    ("rho third", "ρ is the 4th coordinate"),
    ("no division", "divided by its third coordinate"),
    ("cost", "not the cost"),
])
def test_gold_standard_residuals_mistakes(kind, words):
    assert words in hints(check_gold_standard_residuals(_gs_wrong(kind), verbose=False))
