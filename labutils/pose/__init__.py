"""Camera pose (notebooks 03 and 09): one camera from known points — P3P (Lambda Twist), RANSAC, refinement — and
every camera at once from pairs of views — rotation averaging, then positions from known rotations.

Modules: :mod:`~labutils.pose.pnp`, :mod:`~labutils.pose.rotation_averaging` and
:mod:`~labutils.pose.global_translations`.
"""
from .global_translations import centres_from_directions, pair_directions, robust_centres_from_points
from .pnp import (
    PnPResult,
    bearings,
    p3p,
    p3p_bearings,
    pnp_ransac,
    pose_covariance,
    pose_jacobian,
    pose_residuals,
    refine_pose,
    reprojection_errors,
)
from .rotation_averaging import (
    RotationAveragingResult,
    aligned_rotation_errors_deg,
    chordal_rotation_averaging,
    largest_component,
    refine_rotations,
    rotation_averaging,
)

__all__ = ["centres_from_directions", "pair_directions", "robust_centres_from_points", "PnPResult", "bearings", "p3p",
           "p3p_bearings", "pnp_ransac", "pose_covariance", "pose_jacobian", "pose_residuals", "refine_pose",
           "reprojection_errors",
           "RotationAveragingResult", "aligned_rotation_errors_deg", "chordal_rotation_averaging", "largest_component",
           "refine_rotations", "rotation_averaging"]
