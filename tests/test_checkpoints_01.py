"""Notebook 01's checkpoints fail for the wrong implementations they are meant to catch (issue 9).

Each test runs the checkpoint's own cells, read from the notebook by their tags (``setup``, ``checkpoint-<name>``),
once with the library's function and once with a plausible wrong one bound in its place, at sizes small enough to
take a few seconds.
"""
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from _checkpoints import run_cells

from labutils.twoview.epipolar import fundamental_8point, hartley_normalisation
from labutils.twoview.gold_standard import gold_standard_residuals

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "01_fundamental_matrix.ipynb"




@pytest.fixture(scope="module")
def setup():
    """The namespace after the notebook's setup cell (imports, parameters, the scene), with the library's functions
    bound where the notebook uses the student's (issue 19: the exercises' functions are picked after their
    self-checks; a checkpoint cell reads them under the exercise's name)."""
    ns = run_cells(NOTEBOOK, "setup", {})
    return dict(ns, normalisation_matrix=hartley_normalisation, gold_standard_residuals=gold_standard_residuals,
                eight_point=lambda x1, x2: fundamental_8point(x1, x2, degeneracy=None))


def _run(setup, tag, **bindings):
    return run_cells(NOTEBOOK, tag, dict(setup, **bindings))


# --- Hartley's normalisation, checked against its definition ------------------------------------------------------

def _normalisation(target=2 ** 0.5, centre=True):
    def wrong(x):
        x = np.asarray(x, float)
        c = x.mean(0) if centre else np.zeros(2)
        s = target / np.linalg.norm(x - x.mean(0), axis=1).mean()
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])
    return wrong


def test_normalisation_checkpoint_passes(setup):
    ns = _run(setup, "checkpoint-normalisation")
    assert np.allclose(ns["T1"], hartley_normalisation(ns["x1m"]))


@pytest.mark.parametrize("wrong", [_normalisation(target=1.0), _normalisation(centre=False)],
                         ids=["mean distance 1", "not centred"])
def test_normalisation_checkpoint_catches(setup, wrong):
    with pytest.raises(AssertionError):
        _run(setup, "checkpoint-normalisation", normalisation_matrix=wrong)


# --- the gold standard against the ML residual bound --------------------------------------------------------------

SMALL = dict(BOUND_DOF=400, STUDY_NS=(50, 100))         # 10 and 5 trials: the band widens to about 13 %


def _returns_its_start(x1, x2, F0=None, **kwargs):
    """A gold standard whose optimisation does nothing: it returns the 8-point start."""
    return SimpleNamespace(F=fundamental_8point(x1, x2, degeneracy=None) if F0 is None else F0)


def _plain_8point(x1, x2, F0=None, **kwargs):
    """The plain 8-point used as the gold standard (ignoring the start it is given)."""
    return SimpleNamespace(F=fundamental_8point(x1, x2, degeneracy=None))


def test_bound_checkpoint_passes(setup):
    ns = _run(setup, "checkpoint-bound", **SMALL)
    assert set(ns["results"]) == {50, 100}


@pytest.mark.parametrize("wrong", [_returns_its_start, _plain_8point], ids=["returns its start", "plain 8-point"])
def test_bound_checkpoint_catches(setup, wrong):
    with pytest.raises(AssertionError, match="improve on its 8-point start"):
        _run(setup, "checkpoint-bound", fundamental_gold_standard=wrong, **SMALL)
