"""Notebook 06's checkpoints can fail.

Each test runs a checkpoint's own code — the cells tagged ``checkpoint-<name>`` in the notebook, read from it, not a
copy — once with the library and once with a library function replaced by a plausible wrong one. With the right
function the checkpoint passes; with the wrong one it raises ``AssertionError``. The scenes are small (the synthetic
fallback for one camera, a 12-view turntable for the reconstruction) and the trial counts low, so each run takes a few
seconds; the checks' bands are tied to the trial counts, so they stay fair at these sizes.
"""
import functools
import os
from pathlib import Path

import numpy as np
import pytest
from _checkpoints import run_cells, tagged_cells

from labutils import make_scene
from labutils.bundle.reprojection import camera_params_from_Rt, reprojection_jacobian
from labutils.sfm import noise_study as NS
from labutils.sfm.incremental import incremental_sfm

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "06_noise_study.ipynb"


tagged = functools.partial(tagged_cells, NOTEBOOK)
run = functools.partial(run_cells, NOTEBOOK)


def with_ns_module(ns, **replace):
    """``ns`` with the notebook's names of the noise study (imported from labutils.sfm) that ``replace`` overrides."""
    missing = [name for name in replace if name not in ns]
    assert not missing, f"the notebook does not use {missing}"
    return dict(ns, **replace)


@pytest.fixture
def ns(monkeypatch):
    """The notebook's setup cell, on the synthetic fallback (no data needed), with small trial counts."""
    monkeypatch.setenv("LABUTILS_DATA", "none")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    ns = run("setup", {})
    ns.update(N_ONE_CAMERA=20, N_SFM=1)
    return ns


def small(ns):
    """A 12-view turntable in place of the notebook's scene, and the prediction for it (the 'prediction' cell)."""
    scene = make_scene(150, 12, layout="turntable", noise_px=0.0, rng=np.random.default_rng(2))
    ns.update(scene=scene, V=scene.n_views, M=scene.n_points, rot1=float("nan"))
    return run("prediction", ns)


# --- one camera -----------------------------------------------------------------------------------------------------

def sigma_not_squared(X, K, R, t, sigma=1.0):
    """A wrong prediction: the covariance grows as σ, not σ²."""
    return NS.pose_covariance(X, K, R, t, 1.0) * sigma


def for_angle_axis(X, K, R, t, sigma=1.0):
    """A wrong prediction: σ²(JᵀJ)⁻¹ with J taken for the angle-axis parameters ω of R, not the error φ."""
    J = reprojection_jacobian(camera_params_from_Rt(R[None], t[None]), X, np.zeros(len(X), int), np.arange(len(X)), K)
    J = np.asarray(J.todense() if hasattr(J, "todense") else J)[:, :6]
    return sigma ** 2 * np.linalg.inv(J.T @ J)


def test_one_camera_checkpoint(ns):
    run("checkpoint-one-camera", dict(ns))
    for wrong in (sigma_not_squared, for_angle_axis):
        with pytest.raises(AssertionError):
            run("checkpoint-one-camera", with_ns_module(ns, pose_covariance=wrong))


# --- the SfM reaches the ML optimum -------------------------------------------------------------------------------

def test_sfm_checkpoint(ns):
    small(ns)
    run("checkpoint-sfm", dict(ns))

    def robust_everywhere(tracks, K, *, loss=None, **kwargs):
        """A wrong pipeline: the robust (Cauchy) loss kept where there are no outliers ..."""
        return incremental_sfm(tracks, K, loss="cauchy", **kwargs)

    def as_it_is(rec, tracks, K, **kwargs):
        """... and its result returned without the plain least-squares refinement."""
        return rec.R, rec.t
    wrong = with_ns_module(ns, refine_reconstruction=as_it_is)
    wrong["incremental_sfm"] = robust_everywhere
    with pytest.raises(AssertionError):
        run("checkpoint-sfm", wrong)


# --- the robust steps against outliers ------------------------------------------------------------------------------

def test_outliers_checkpoint(ns):
    small(ns)
    run("checkpoint-outliers", dict(ns))

    def no_removal(scene, x_meas, **kwargs):
        """Wrong robust steps: the robust loss alone, no observation removed."""
        return NS.ba_from_truth(scene, x_meas, **dict(kwargs, threshold_px=None))

    def threshold_at_the_noise(scene, x_meas, **kwargs):
        """Wrong robust steps: the removal threshold at the noise level (1 px), not 5σ."""
        if kwargs.get("threshold_px") is not None:
            kwargs["threshold_px"] = 1.0
        return NS.ba_from_truth(scene, x_meas, **kwargs)

    for wrong in (no_removal, threshold_at_the_noise):
        with pytest.raises(AssertionError):
            run("checkpoint-outliers", with_ns_module(ns, ba_from_truth=wrong))
