"""The core every stage stands on: input checks, geometry, metrics, robust losses, RANSAC, the one LM loop, the
records the stages pass around, and synthetic scenes with ground truth.

Modules: :mod:`~labutils.core.validation` (the checks every public function uses: ``ValueError`` naming the
argument, the expected shape and what it got), :mod:`~labutils.core.cli` (what every command line shares),
:mod:`~labutils.core.blas` (BLAS threads), :mod:`~labutils.core.geometry` (homogeneous coordinates, rotations,
cameras), :mod:`~labutils.core.metrics` (errors against truth, similarity alignment, the ML residual bound),
:mod:`~labutils.core.robust` (robust losses), :mod:`~labutils.core.ransac` (one adaptive RANSAC loop),
:mod:`~labutils.core.lm` (Levenberg–Marquardt with Nielsen's damping), :mod:`~labutils.core.scene` (the
``Scene`` and ``Views`` records) and :mod:`~labutils.core.synthetic` (scenes with ground truth). Nothing here
imports another stage.
"""
from .geometry import (
    KRt_from_P,
    P_from_KRt,
    angle_axis_from_rotation,
    camera_center,
    dehomogeneous,
    depths,
    homogeneous,
    left_jacobian_so3,
    project,
    relative_pose,
    right_jacobian_so3,
    rotation_from_angle_axis,
    skew,
)
from .lm import levenberg_marquardt
from .metrics import (
    align_cameras,
    align_similarity,
    angle_between_deg,
    ml_residual_bound,
    pose_errors,
    rms,
    rotation_error_deg,
    up_to_sign_scale,
)
from .ransac import ransac, ransac_iterations
from .scene import CameraRig, Scene, Views, observations
from .synthetic import DEFAULT_K, look_at, make_scene, perturb_cameras

__all__ = ["KRt_from_P", "P_from_KRt", "angle_axis_from_rotation", "camera_center", "dehomogeneous", "depths",
           "homogeneous", "left_jacobian_so3", "project", "relative_pose", "right_jacobian_so3",
           "rotation_from_angle_axis", "skew", "levenberg_marquardt", "align_cameras", "align_similarity",
           "angle_between_deg", "ml_residual_bound", "pose_errors", "rms", "rotation_error_deg", "up_to_sign_scale",
           "ransac", "ransac_iterations", "CameraRig", "Scene", "Views", "observations", "DEFAULT_K", "look_at",
           "make_scene", "perturb_cameras"]
