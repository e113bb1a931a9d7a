"""labutils: the estimators, data access, metrics and plots behind the 3D reconstruction workbook.

Conventions, used everywhere in this package and the notebooks
---------------------------------------------------------------
- World to camera: ``x_cam = R @ X + t``; camera centre ``C = -R.T @ t``; ``P = K @ [R | t]``;
  camera axes x right, y down, z forward (points in front have positive depth).
- Points are rows: pixels ``x1, x2`` are ``(N, 2)``, world points ``X`` are ``(N, 3)``; a homogeneous
  copy has the suffix ``_h``; ``t`` has shape ``(3,)``.
- Epipolar geometry: ``x2_hᵀ F x1_h = 0``; ``E = [t]× R`` for camera 2 ``[R | t]`` relative to camera 1
  ``[I | 0]``; ``F = K2⁻ᵀ E K1⁻¹``. F and E are defined up to scale, t from E up to scale and sign.
- Bundle adjustment arrays as in the scipy cookbook: ``camera_params (n_cameras, k)``,
  ``points_3d (n_points, 3)``, ``camera_indices``, ``point_indices``, ``points_2d (n_observations, 2)``.
- Every random choice takes an ``rng`` (``numpy.random.Generator``); nothing uses global random state.
- Bad input raises ``ValueError`` naming the problem.

References: Hartley & Zisserman, *Multiple View Geometry*, 2nd ed. (cited as H&Z).
"""
from .bal import read_bal, write_bal
from .bundle import (BundleResult, Rt_from_camera_params, bundle_adjust, camera_params_from_Rt, jacobian_sparsity,
                     reprojection_jacobian, reprojection_residuals)
from .data import DataNotFoundError, Scene, data_dirs, find_data, has_data, load_dino, load_scene, observations
from .epipolar import (decompose_essential, essential_from_fundamental, fundamental_7point, fundamental_8point,
                       fundamental_from_pose, fundamental_gold_standard, fundamental_ransac, pose_from_essential,
                       sampson_distance)
from .geometry import (KRt_from_P, P_from_KRt, angle_axis_from_rotation, camera_center, dehomogeneous, homogeneous,
                       project, relative_pose, rotation_from_angle_axis, skew)
from .metrics import align_cameras, align_similarity, angle_between_deg, ml_residual_bound, pose_errors, rotation_error_deg
from .pnp import bearings, p3p, p3p_bearings, pnp_ransac, refine_pose, reprojection_errors
from .sfm import Reconstruction, bundle_from_cameras, camera_errors, incremental_sfm
from .synthetic import make_scene
from .uncertainty import aligned_pose_covariance, gauge_basis, predict_pose_errors, run_noise_study
from .triangulation import fundamental_residual, triangulate, triangulate_multiview, triangulate_optimal

__all__ = [
    "DataNotFoundError", "Scene", "data_dirs", "find_data", "has_data", "load_dino", "load_scene", "observations",
    "KRt_from_P", "P_from_KRt", "angle_axis_from_rotation", "camera_center", "dehomogeneous", "homogeneous",
    "project", "relative_pose", "rotation_from_angle_axis", "skew",
    "align_cameras", "align_similarity", "angle_between_deg", "ml_residual_bound", "pose_errors", "rotation_error_deg",
    "bearings", "p3p", "p3p_bearings", "pnp_ransac", "refine_pose", "reprojection_errors",
    "make_scene",
    "decompose_essential", "essential_from_fundamental", "fundamental_7point", "fundamental_8point",
    "fundamental_from_pose", "fundamental_gold_standard", "fundamental_ransac", "pose_from_essential",
    "sampson_distance", "fundamental_residual", "triangulate", "triangulate_multiview", "triangulate_optimal",
    "Reconstruction", "bundle_from_cameras", "camera_errors", "incremental_sfm",
    "aligned_pose_covariance", "gauge_basis", "predict_pose_errors", "run_noise_study",
    "read_bal", "write_bal", "Rt_from_camera_params", "camera_params_from_Rt",
    "BundleResult", "bundle_adjust", "jacobian_sparsity", "reprojection_jacobian", "reprojection_residuals",
]
