"""Notebook 11's self-checks: the reference solutions pass, and typical wrong answers get the matching hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written

from labutils.exercises.ex11_carving import check_carve_step, check_mask_iou, check_silhouette_from_colour
from labutils.model.carving import inside_silhouette, mask_iou


def reference_silhouette(image, background, threshold):
    return np.linalg.norm(image.astype(float) - np.asarray(background, float), axis=-1) > threshold


@pytest.mark.parametrize("check, func", [(check_silhouette_from_colour, reference_silhouette),
                                         (check_carve_step, inside_silhouette), (check_mask_iou, mask_iou)])
def test_reference_passes(check, func):
    assert_passes(check, func, min_cases=3)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_mask_iou)


@pytest.mark.parametrize("wrong, words", [
    (lambda im, bg, t: np.linalg.norm(im - bg, axis=-1) > t, "wraps around"),                      # uint8 arithmetic
    (lambda im, bg, t: np.linalg.norm(im.astype(float) - bg, axis=-1) < t, "inverted"),
    (lambda im, bg, t: np.any(np.abs(im.astype(float) - bg) > t, axis=-1), "each channel separately"),
    (lambda im, bg, t: ((im.astype(float) - bg) ** 2).sum(-1) > t, "squared distance"),
    (lambda im, bg, t: np.linalg.norm(im.astype(float) - bg, axis=-1) >= t, "strictly greater"),
    (lambda im, bg, t: np.linalg.norm(im.astype(float) - bg, axis=-1), "boolean mask"),
])
def test_silhouette_mistakes_get_their_hint(wrong, words):
    report = check_silhouette_from_colour(wrong, verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints


def carve_variant(swap=False, divide=True, trunc=False, bounds=True, depth=True):
    def carve_step(X, P, mask):
        x_h = X @ P[:, :3].T + P[:, 3]
        x = x_h[:, :2] / x_h[:, 2:] if divide else x_h[:, :2]
        c, r = (np.trunc(x[:, 0]), np.trunc(x[:, 1])) if trunc else (np.round(x[:, 0]), np.round(x[:, 1]))
        h, w = mask.shape
        ok = np.ones(len(X), bool)
        if bounds:
            ok &= (c >= 0) & (c < w) & (r >= 0) & (r < h) if not swap else (r >= 0) & (r < w) & (c >= 0) & (c < h)
        if depth:
            ok &= x_h[:, 2] > 0
        keep = np.zeros(len(X), bool)
        ci, ri = c[ok].astype(int), r[ok].astype(int)
        keep[ok] = mask[ci, ri] if swap else mask[ri, ci]
        return keep
    return carve_step


@pytest.mark.parametrize("wrong, words", [
    (carve_variant(swap=True), "mask[x, y]"),
    (carve_variant(divide=False), "divide by w"),
    (carve_variant(trunc=True), "truncated"),
    (carve_variant(bounds=False), "outside the image"),                  # IndexError or wrap-around
    (carve_variant(depth=False), "behind the camera"),
    (lambda X, P, m: ~inside_silhouette(X, P, m), "inverted"),
    (lambda X, P, m: inside_silhouette(X, P, m).astype(int), "booleans"),
])
def test_carve_step_mistakes_get_their_hint(wrong, words):
    report = check_carve_step(wrong, verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints


def column_first(X, P, mask):
    """Bounds checked right, then mask[col, row]: an IndexError on axis 0 for points inside the (wide) image."""
    x_h = X @ P[:, :3].T + P[:, 3]
    c, r = np.round(x_h[:, 0] / x_h[:, 2]).astype(int), np.round(x_h[:, 1] / x_h[:, 2]).astype(int)
    h, w = mask.shape
    ok = (c >= 0) & (c < w) & (r >= 0) & (r < h) & (x_h[:, 2] > 0)
    keep = np.zeros(len(X), bool)
    keep[ok] = mask[c[ok], r[ok]]
    return keep


def test_column_first_lookup_gets_the_y_first_hint():
    report = check_carve_step(column_first, verbose=False)
    assert not report.passed and any("mask[row, col] = mask[y, x], y first" in h for h in report.hints), report.hints
    assert not any("projects outside the image" in h for h in report.hints), report.hints


def wrap_around(X, P, mask):
    """Bounds checked only on the high side: negative indices wrap (no IndexError, a wrong answer)."""
    x_h = X @ P[:, :3].T + P[:, 3]
    c, r = np.round(x_h[:, 0] / x_h[:, 2]).astype(int), np.round(x_h[:, 1] / x_h[:, 2]).astype(int)
    h, w = mask.shape
    ok = (c < w) & (r < h) & (x_h[:, 2] > 0)
    keep = np.zeros(len(X), bool)
    keep[ok] = mask[r[ok], c[ok]]
    return keep


def test_wrapping_negative_indices_are_named():
    report = check_carve_step(wrap_around, verbose=False)
    assert not report.passed and any("wrap around" in h for h in report.hints), report.hints


@pytest.mark.parametrize("wrong, words", [
    (lambda a, b: np.count_nonzero(a & b) / np.count_nonzero(a), "area of one mask"),
    (lambda a, b: 2 * np.count_nonzero(a & b) / (a.sum() + b.sum()), "Dice"),
    (lambda a, b: np.count_nonzero(a & b) / (a.sum() + b.sum()), "counts the intersection twice"),
    (lambda a, b: np.count_nonzero(a & b) / max(np.count_nonzero(a | b), 1), "raise a ValueError"),
    (lambda a, b: int(np.count_nonzero(a & b)) / int(np.count_nonzero(a | b)), "ZeroDivisionError"),
    (lambda a, b: np.float64(np.count_nonzero(a & b)) / np.count_nonzero(a | b), "raise a ValueError"),   # NaN
])
def test_iou_mistakes_get_their_hint(wrong, words):
    with np.errstate(invalid="ignore", divide="ignore"):
        report = check_mask_iou(wrong, verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints
