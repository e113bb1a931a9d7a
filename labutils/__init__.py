"""labutils: the estimators, data access, metrics and plots behind the 3D reconstruction workbook.

Conventions, used everywhere in this package and the notebooks
---------------------------------------------------------------
- World to camera: ``x_cam = R @ X + t``; camera centre ``C = -R.T @ t``; ``P = K @ [R | t]``;
  camera axes x right, y down, z forward (points in front have positive depth).
- Points are rows: pixels ``x1, x2`` are ``(N, 2)``, world points ``X`` are ``(N, 3)``; a homogeneous
  copy has the suffix ``_h``; ``t`` has shape ``(3,)``, a stack of them ``(V, 3)``.
- Epipolar geometry: ``x2_hᵀ F x1_h = 0``; ``E = [t]× R`` for camera 2 ``[R | t]`` relative to camera 1
  ``[I | 0]``; ``F = K2⁻ᵀ E K1⁻¹``. F and E are defined up to scale, t from E up to scale and sign.
- Bundle adjustment arrays as in the scipy cookbook: ``camera_params (n_cameras, k)``,
  ``points_3d (n_points, 3)``, ``camera_indices``, ``point_indices``, ``points_2d (n_observations, 2)``.
- Pixel thresholds are called ``threshold_px``; every random choice takes a keyword-only ``rng``
  (``numpy.random.Generator``); nothing uses global random state.
- Bad input raises ``ValueError`` naming the argument, what was expected and what it got.

The public names below are importable from the package (``from labutils import fundamental_8point``); each
lives in the module of its idea and is loaded on first use, so ``import labutils`` is cheap and
``python -m labutils.<module>`` runs a command line without importing it twice.

References: Hartley & Zisserman, *Multiple View Geometry*, 2nd ed. (cited as H&Z).
"""
import importlib

_EXPORTS = {
    "datapath": ["DataNotFoundError", "data_dirs", "find_data", "has_data"],
    "ransac": ["ransac_iterations"],
    "ply": ["read_ply", "write_mesh", "write_points"],
    "scene": ["Scene", "Views", "observations"],
    "data": ["load_dino", "load_fountain", "load_scene", "load_temple"],
    "synthetic": ["make_scene", "perturb_cameras"],
    "geometry": ["KRt_from_P", "P_from_KRt", "angle_axis_from_rotation", "camera_center", "dehomogeneous",
                 "homogeneous", "left_jacobian_so3", "project", "relative_pose", "right_jacobian_so3",
                 "rotation_from_angle_axis", "skew"],
    "metrics": ["align_cameras", "align_similarity", "angle_between_deg", "ml_residual_bound", "pose_errors",
                "rotation_error_deg", "up_to_sign_scale"],
    "triangulation": ["fundamental_residual", "triangulate", "triangulate_multiview", "triangulate_optimal",
                      "triangulate_tracks"],
    "epipolar": ["ModelSelection", "fundamental_7point", "fundamental_8point", "fundamental_ransac",
                 "gric_model_selection", "hartley_normalisation", "homography_dlt", "sampson_distance"],
    "gold_standard": ["GoldStandardResult", "fundamental_gold_standard"],
    "features": ["detect_features", "match_descriptors", "match_views", "tracks_from_matches"],
    "essential": ["cheirality_counts", "decompose_essential", "essential_from_fundamental", "fundamental_from_pose",
                  "pose_from_essential"],
    "pnp": ["PnPResult", "bearings", "p3p", "p3p_bearings", "pnp_ransac", "refine_pose", "reprojection_errors"],
    "rotation_averaging": ["RotationAveragingResult", "chordal_rotation_averaging"],
    "reprojection": ["Rt_from_camera_params", "camera_params_from_Rt", "jacobian_sparsity", "reprojection_jacobian",
                     "reprojection_residuals"],
    "bal": ["read_bal", "write_bal"],
    "lm_schur": ["SchurStep", "schur_step"],
    "bundle": ["BundleResult", "bundle_adjust", "bundle_adjust_params"],
    "reconstruction": ["Reconstruction", "camera_errors"],
    "view_selection": ["choose_initial_pair", "covisibility", "pose_covariance", "pyramid_score"],
    "pointcloud": ["PointCloud", "estimate_normals", "oriented_point_cloud"],
    "sfm": ["bundle_from_cameras", "incremental_sfm"],
    "uncertainty": ["aligned_pose_covariance", "gauge_basis", "predict_pose_errors"],
    "noise_study": ["run_noise_study"],
    "carving": ["Carving", "VoxelGrid", "background_model", "silhouette"],
    "meshing": ["delaunay_mesh"],
    "texturing": ["texture_vertices", "vertex_views"],
    "lens": ["distort", "undistort_points"],
    "zhang": ["board_homography", "intrinsics_from_homographies"],
    "calibration": ["CalibrationResult", "calibrate_camera", "calibrate_stereo"],
    "rectification": ["rectify_fusiello"],
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_MODULE_OF)


def __getattr__(name):
    if name in _MODULE_OF:
        value = getattr(importlib.import_module(f".{_MODULE_OF[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'labutils' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
