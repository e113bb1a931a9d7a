"""The noise study of notebook 06: estimate poses from noisy copies of the data many times and compare the errors with
the Cramér–Rao prediction.

One camera with known points first (no gauge: the points fix the frame): :func:`pose_covariance` is the prediction
``σ² (JᵀJ)⁻¹`` for the pose error ``(φ, δt)``, :func:`one_camera_trials` the Monte Carlo of P3P-RANSAC on noisy
pixels, :func:`pose_error_vectors` the measured errors, and :func:`nees` the normalised estimation error squared
that tests the whole covariance (its mean is 6 when the prediction is right).

Then the whole reconstruction, where the errors are measured after a similarity alignment and predicted by
:mod:`labutils.bundle.uncertainty`: :func:`run_noise_study` runs any pipeline (the incremental SfM, bundle adjustment
from the truth, ...) on noisy observations and collects the errors in a :class:`NoiseStudy`; the helpers build the
pipelines' pieces (:func:`ba_from_truth`, :func:`reconstruct_without_ba`, :func:`refine_reconstruction`).
"""
from ...pose.pnp import pose_covariance  # the prediction of section 1, defined beside pnp.pose_jacobian
from .one_camera import nees, one_camera_trials, pose_error_vectors
from .study import (
    NoiseStudy,
    Progress,
    ba_from_truth,
    loglog_slope,
    noisy_observations,
    reconstruct_without_ba,
    refine_reconstruction,
    rms_errors,
    run_noise_study,
)

__all__ = ["NoiseStudy", "Progress", "ba_from_truth", "loglog_slope", "nees", "noisy_observations",
           "one_camera_trials", "pose_covariance", "pose_error_vectors", "reconstruct_without_ba",
           "refine_reconstruction", "rms_errors", "run_noise_study"]
