"""Notebook 12's self-checks: the reference solutions pass, and typical wrong answers get the matching hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written

from labutils.exercises.ex12_stereo import (
    _lr_variant,
    check_left_right_consistent,
    check_points_from_disparity,
    check_zncc_patch,
    reference_points_from_disparity,
)
from labutils.model.stereo import left_right_check, zncc


@pytest.mark.parametrize("check, func", [(check_zncc_patch, zncc), (check_left_right_consistent, left_right_check),
                                         (check_points_from_disparity, reference_points_from_disparity)])
def test_reference_passes(check, func):
    assert_passes(check, func, min_cases=3)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_zncc_patch, check_left_right_consistent, check_points_from_disparity)


# --- exercise 1: ZNCC -------------------------------------------------------------------------------------------
def _zncc_without_means(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


def _covariance(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(((a - a.mean()) * (b - b.mean())).mean())


def _mixed_ddof(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(((a - a.mean()) * (b - b.mean())).sum() / (a.size * a.std(ddof=1) * b.std(ddof=1)))


def _uint8_products(a, b):
    """Mean-free products computed on the raw (maybe uint8) arrays: a·b wraps around before the float division."""
    n = a.size
    ab = (a * b).sum() if a.dtype != np.uint8 else (a * b).astype(np.uint8).sum()
    cov = ab / n - float(a.mean()) * float(b.mean())
    return float(cov / (np.asarray(a, float).std() * np.asarray(b, float).std()))


def _nan_for_flat(a, b):
    a, b = np.asarray(a, float) - np.mean(a), np.asarray(b, float) - np.mean(b)
    with np.errstate(all="ignore"):
        return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()))


@pytest.mark.parametrize("wrong, words", [
    (_zncc_without_means, "subtract each window's mean"),
    (lambda a, b: 1 - zncc(a, b), "cost 1 - ZNCC"),
    (_covariance, "covariance"),
    (_mixed_ddof, "(n - 1)/n"),
    (lambda a, b: zncc(a, b) ** 2, "squared"),
    (lambda a, b: abs(zncc(a, b)), "absolute value"),
    (_uint8_products, "uint8"),
    (_nan_for_flat, "0/0, undefined"),
])
def test_zncc_mistakes_get_their_hint(wrong, words):
    report = check_zncc_patch(wrong, verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints


# --- exercise 2: the left-right check ------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, words", [
    (dict(sign=+1), "not x + d"),
    (dict(same_pixel=True), "at the same pixel"),
    (dict(rnd="trunc"), "truncated"),
    (dict(strict=True), "use <=, not <"),
    (dict(nan_passes=True), "(NaN) must fail"),
    (dict(bounds=False), "wrap around"),
])
def test_left_right_mistakes_get_their_hint(kwargs, words):
    report = check_left_right_consistent(lambda dl, dr, t: _lr_variant(dl, dr, t, **kwargs), verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints


def test_left_right_inverted_and_crashing_answers_get_their_hint():
    report = check_left_right_consistent(lambda dl, dr, t: ~left_right_check(dl, dr, t), verbose=False)
    assert any("inverted" in h for h in report.hints), report.hints

    def indexes_blindly(dl, dr, t):
        ys, xs = np.nonzero(np.isfinite(dl))
        xr = np.round(xs - dl[ys, xs]).astype(int) + dl.shape[1]        # far outside the map
        keep = np.zeros(dl.shape, bool)
        keep[ys, xs] = np.abs(dl[ys, xs] - dr[ys, xr]) <= t
        return keep

    report = check_left_right_consistent(indexes_blindly, verbose=False)
    assert any("outside the right image" in h for h in report.hints), report.hints
    report = check_left_right_consistent(lambda dl, dr, t: left_right_check(dl, dr, t).astype(int), verbose=False)
    assert any("booleans" in h for h in report.hints), report.hints


# --- exercise 3: points from disparity -----------------------------------------------------------------------------
def _points(d, K, b, mistake=None):
    ys, xs = np.nonzero(np.isfinite(d))
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    disp = d[ys, xs]
    Z = {"no_f": b / disp, "negative": -f * b / disp, "f_d_over_b": f * disp / b, "d_as_depth": disp}.get(mistake,
                                                                                                          f * b / disp)
    if mistake == "no_principal_point":
        cx = cy = 0.0
    if mistake == "swap":
        xs, ys = ys, xs
    X = np.stack([(xs - cx) * Z / f, (ys - cy) * Z / f, Z], axis=1)
    if mistake == "column_major":
        order = np.lexsort((ys, xs))
        X = X[order]
    return X.T if mistake == "transposed" else X


@pytest.mark.parametrize("mistake, words", [
    ("no_f", "left out the focal length"),
    ("negative", "behind the camera"),
    ("f_d_over_b", "not f d / b"),
    ("d_as_depth", "disparity as the depth"),
    ("no_principal_point", "principal point"),
    ("swap", "x is the column"),
    ("column_major", "not in the order"),
    ("transposed", "transposed?"),
])
def test_points_mistakes_get_their_hint(mistake, words):
    report = check_points_from_disparity(lambda d, K, b: _points(d, K, b, mistake), verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints


def test_points_correct_variant_passes():
    assert check_points_from_disparity(lambda d, K, b: _points(d, K, b), verbose=False).passed
