"""Notebook 02's checkpoints fail for the wrong implementations they are meant to catch (issue 9).

Each test runs the checkpoint's own cells, read from the notebook by their tags (``setup``, ``checkpoint-<name>``),
once with the library's function and once with a plausible wrong one bound in its place, on one pair of views.
"""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from _checkpoints import run_cells

from labutils import dehomogeneous, homogeneous
from labutils.twoview.epipolar import fundamental_8point, sampson_distance
from labutils.twoview.essential import cheirality_choice, decompose_essential
from labutils.twoview.gold_standard import gold_standard_residuals
from labutils.twoview.triangulation import triangulate

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "02_essential_and_pose.ipynb"




@pytest.fixture(scope="module")
def setup():
    """The namespace after the notebook's setup cell (imports, parameters, the scene and the pair), with the
    library's functions bound where the notebook uses the student's (issue 19: notebook 01's by ``yours.load``, this
    notebook's picked after their self-checks)."""
    ns = run_cells(NOTEBOOK, "setup", {})
    Kinv = np.linalg.inv(ns["K"])
    return dict(ns, eight_point=fundamental_8point, sampson=sampson_distance,
                gold_standard_residuals=gold_standard_residuals, four_poses=decompose_essential,
                triangulate_linear=triangulate, choose_pose=cheirality_choice,
                normalised=lambda x: dehomogeneous(homogeneous(x) @ Kinv.T))


def _run(setup, tag, **bindings):
    return run_cells(NOTEBOOK, tag, dict(setup, **bindings))


# --- the optimal correction never worse than linear triangulation ------------------------------------------------

def _returns_its_input(F, x1, x2):
    """An 'optimal correction' that corrects nothing."""
    return np.array(x1, float), np.array(x2, float)


def _corrects_image_2_only(F, x1, x2):
    """Moves x2 onto the epipolar line of x1 (the constraint holds), leaves x1 alone: feasible, not optimal."""
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    lines = np.hstack([x1, np.ones((len(x1), 1))]) @ np.asarray(F).T
    d = (np.sum(lines[:, :2] * x2, axis=1) + lines[:, 2]) / np.sum(lines[:, :2] ** 2, axis=1)
    return x1, x2 - d[:, None] * lines[:, :2]


def test_optimal_checkpoint_passes(setup):
    ns = _run(setup, "checkpoint-optimal")
    assert ns["gap"].mean() < 0


def test_optimal_checkpoint_catches_a_correction_that_returns_its_input(setup):
    with pytest.raises(AssertionError, match="x2ᵀ F x1 = 0"):
        _run(setup, "checkpoint-optimal", triangulate_optimal=_returns_its_input)


def test_optimal_checkpoint_catches_a_one_sided_correction(setup):
    with pytest.raises(AssertionError):
        _run(setup, "checkpoint-optimal", triangulate_optimal=_corrects_image_2_only)


# --- the ML F fits at least as well as the truth, and better than its start ---------------------------------------

def _plain_8point(x1, x2, F0=None, **kwargs):
    """The 8-point where the gold standard is expected."""
    return SimpleNamespace(F=fundamental_8point(x1, x2) if F0 is None else np.asarray(F0, float))


def test_ml_fit_checkpoint_passes(setup):
    ns = _run(setup, "checkpoint-ml-fit", PAIRS=[(24, 25)])
    assert len(ns["rows"]) == 3


def test_ml_fit_checkpoint_catches_the_8point(setup):
    with pytest.raises(AssertionError, match="better than its 8-point start"):
        _run(setup, "checkpoint-ml-fit", PAIRS=[(24, 25)], fundamental_gold_standard=_plain_8point)
