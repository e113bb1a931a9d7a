"""Notebook 10's self-checks: the reference solutions pass, and typical wrong answers get the matching hint."""
import numpy as np
import pytest
from _exercises import assert_passes, assert_stubs_not_written

from labutils.exercises.ex10_model import (
    _reference_orient,
    _reference_pca_normal,
    check_most_frontal_view,
    check_orient_normal,
    check_pca_normal,
)
from labutils.model.pointcloud import orient_normals
from labutils.model.texturing import most_frontal_view


def _library_orient(X, n, C, seen):
    """labutils.model.orient_normals for one point, cameras given by their centres (R = I, t = -C)."""
    return orient_normals(X[None], n[None], np.stack([np.eye(3)] * len(C)), -C, seen[:, None])[0]


@pytest.mark.parametrize("check, func", [(check_pca_normal, _reference_pca_normal),
                                         (check_orient_normal, _reference_orient),
                                         (check_orient_normal, _library_orient),
                                         (check_most_frontal_view, most_frontal_view)])
def test_reference_passes(check, func):
    assert_passes(check, func, min_cases=3)


def test_stub_is_reported_as_not_written(capsys):
    assert_stubs_not_written(capsys, check_pca_normal)


def _eig(P, centre=True):
    Q = P - P.mean(0) if centre else P
    return np.linalg.eigh(Q.T @ Q)


@pytest.mark.parametrize("wrong, words", [
    (lambda P: _eig(P)[1][:, 2], "LARGEST spread"),
    (lambda P: _eig(P)[1][0], "COLUMNS"),
    (lambda P: _eig(P, centre=False)[1][:, 0], "did not centre"),
    (lambda P: np.linalg.svd(P)[2][-1], "did not centre"),
    (lambda P: 3 * _eig(P)[1][:, 0], "normalise"),
    (lambda P: _eig(P)[1][:, :1], "(3,) vector"),
])
def test_pca_mistakes_get_their_hint(wrong, words):
    report = check_pca_normal(wrong, verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints


def _orient_variant(all_cameras=False, first_only=False, reversed_=False, partial=False):
    def orient_normal(X, n, C, seen):
        cams = C if all_cameras else C[seen]
        d = (X - cams) if reversed_ else (cams - X)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        score = d[0] @ n if first_only else np.sum(d @ n)
        if partial:
            out = n.copy()
            out[2] = abs(out[2]) if score >= 0 else -abs(out[2])
            return out
        return n if score >= 0 else -n
    return orient_normal


@pytest.mark.parametrize("wrong, words", [
    (_orient_variant(all_cameras=True), "only the cameras that SEE"),
    (_orient_variant(first_only=True), "trusted one camera"),
    (_orient_variant(reversed_=True), "C_v - X (not X - C_v)"),
    (_orient_variant(partial=True), "the whole vector"),
    (lambda X, n, C, seen: n if n @ (C[seen] - X).mean(0) >= 0 else -n,
     "divide by ‖C_v − X‖: far cameras would outvote near ones"),
    (lambda X, n, C, seen: n if np.sign((C[seen] - X) @ n).sum() >= 0 else -n, "votes with its cosine, not ±1"),
])
def test_orient_mistakes_get_their_hint(wrong, words):
    report = check_orient_normal(wrong, verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints


def _frontal_variant(ignore_vis=False, argmin=False, unnormalised=False, no_minus_one=False, position=False):
    def frontal(X, normals, C, visible):
        d = C[:, None, :] - X[None]
        cos = np.einsum("vni,ni->vn", d, normals)
        if not unnormalised:
            cos = cos / np.linalg.norm(d, axis=-1)
        if ignore_vis:
            return np.argmax(cos, axis=0)
        if argmin:
            best = np.argmin(np.where(visible, cos, np.inf), axis=0)
        else:
            best = np.argmax(np.where(visible, cos, -np.inf), axis=0)
        if position:
            best = np.array([int(np.argmax(cos[visible[:, i], i])) if visible[:, i].any() else -1
                             for i in range(len(X))])
        if no_minus_one:
            return best
        return np.where(visible.any(axis=0), best, -1)
    return frontal


@pytest.mark.parametrize("wrong, words", [
    (_frontal_variant(ignore_vis=True), "ignored visibility"),
    (_frontal_variant(argmin=True), "least frontal"),
    (_frontal_variant(unnormalised=True), "without dividing by the distance"),
    (_frontal_variant(no_minus_one=True), "must get -1"),
    (_frontal_variant(position=True), "position among the visible views"),
    (lambda X, n, C, v: most_frontal_view(X, n, C, v).astype(float), "integer view indices"),
])
def test_frontal_mistakes_get_their_hint(wrong, words):
    report = check_most_frontal_view(wrong, verbose=False)
    assert not report.passed and any(words in h for h in report.hints), report.hints
