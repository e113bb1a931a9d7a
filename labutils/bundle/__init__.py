"""Bundle adjustment (notebooks 04 and 06): the reprojection model and its analytic Jacobian, the gauge, our
Levenberg–Marquardt with the Schur complement, and how precise the result can be (the Cramér–Rao prediction).

Modules: :mod:`~labutils.bundle.reprojection` (camera parameters, residuals, the Jacobian and its sparsity),
:mod:`~labutils.bundle.gauge`, :mod:`~labutils.bundle.schur` (the Schur-complement step the LM core calls),
:mod:`~labutils.bundle.adjust` (:func:`bundle_adjust` and ``python -m labutils.bundle``) and
:mod:`~labutils.bundle.uncertainty` (the predicted pose covariance in the aligned gauge).
"""
from .adjust import BundleResult, bundle_adjust, bundle_adjust_params, solve_bal
from .gauge import gauge_basis
from .reprojection import (
    Rt_from_camera_params,
    camera_params_from_Rt,
    jacobian_sparsity,
    project_observations,
    reprojection_blocks,
    reprojection_jacobian,
    reprojection_residuals,
)
from .schur import SchurStep, levenberg_marquardt, schur_step, schur_step_dense
from .uncertainty import (
    PosePrediction,
    aligned_pose_covariance,
    camera_information,
    effective_terms,
    gauge_pose_covariance,
    pose_error_map,
    predict_pose_errors,
)

__all__ = ["BundleResult", "bundle_adjust", "bundle_adjust_params", "solve_bal", "gauge_basis",
           "Rt_from_camera_params", "camera_params_from_Rt", "jacobian_sparsity", "project_observations",
           "reprojection_blocks", "reprojection_jacobian", "reprojection_residuals", "SchurStep", "schur_step",
           "schur_step_dense", "levenberg_marquardt", "PosePrediction",
           "aligned_pose_covariance", "camera_information", "effective_terms", "gauge_pose_covariance",
           "pose_error_map", "predict_pose_errors"]
