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
lives in the stage package of its idea (``labutils.twoview``, ``labutils.sfm``, ...) and is loaded on first use, so
``import labutils`` is cheap and ``python -m labutils.<command>`` runs a command line without importing it twice.

References: Hartley & Zisserman, *Multiple View Geometry*, 2nd ed. (cited as H&Z).
"""
import importlib
import os
import sys


def _interrupted_while_loading(signum, frame):
    # exit at once: an exception raised here could surface inside a C extension's import (numpy's) as another error;
    # nothing has been written yet, so there is nothing to clean up
    print("error: interrupted", file=sys.stderr, flush=True)
    os._exit(130)


# ``python -m labutils.<command>``: a Ctrl-C while the command still imports numpy, scipy, OpenCV is one line and exit
# status 130, not a traceback through the imports (labutils.core.cli.run takes Ctrl-C back once the command runs).
_ORIG_ARGV = getattr(sys, "orig_argv", [])
if sys.argv[:1] == ["-m"] and "-m" in _ORIG_ARGV[:-1] and \
        _ORIG_ARGV[_ORIG_ARGV.index("-m") + 1].startswith("labutils."):
    import signal
    try:
        signal.signal(signal.SIGINT, _interrupted_while_loading)
    except ValueError:
        pass

_EXPORTS = {
    "core": ["KRt_from_P", "P_from_KRt", "Scene", "Views", "align_cameras", "align_similarity",
             "angle_axis_from_rotation", "angle_between_deg", "camera_center", "dehomogeneous", "homogeneous",
             "left_jacobian_so3", "make_scene", "ml_residual_bound", "observations", "perturb_cameras",
             "pose_errors", "project", "ransac_iterations", "relative_pose", "right_jacobian_so3",
             "rotation_error_deg", "rotation_from_angle_axis", "skew", "up_to_sign_scale"],
    "data": ["DataNotFoundError", "data_dirs", "find_data", "has_data", "load_dino", "load_fountain", "load_scene",
             "load_temple", "read_bal", "read_ply", "write_bal", "write_mesh", "write_points"],
    "twoview": ["GoldStandardResult", "ModelSelection", "cheirality_counts", "decompose_essential",
                "essential_from_fundamental", "fundamental_7point", "fundamental_8point", "fundamental_from_pose",
                "fundamental_gold_standard", "fundamental_ransac", "fundamental_residual", "gric_model_selection",
                "hartley_normalisation", "homography_dlt", "pose_from_essential", "sampson_distance", "triangulate",
                "triangulate_multiview", "triangulate_optimal", "triangulate_tracks"],
    "match": ["detect_features", "match_descriptors", "match_views", "tracks_from_matches"],
    "pose": ["PnPResult", "RotationAveragingResult", "bearings", "chordal_rotation_averaging", "p3p", "p3p_bearings",
             "pnp_ransac", "pose_covariance", "refine_pose", "reprojection_errors"],
    "bundle": ["BundleResult", "Rt_from_camera_params", "SchurStep", "aligned_pose_covariance", "bundle_adjust",
               "bundle_adjust_params", "camera_params_from_Rt", "gauge_basis", "jacobian_sparsity",
               "predict_pose_errors", "reprojection_jacobian", "reprojection_residuals", "schur_step"],
    "calibrate": ["CalibrationResult", "board_homography", "calibrate_camera", "calibrate_stereo", "distort",
                  "intrinsics_from_homographies", "rectify_fusiello", "undistort_points"],
    "model": ["Carving", "PointCloud", "VoxelGrid", "background_model", "delaunay_mesh", "estimate_normals",
              "oriented_point_cloud", "silhouette", "texture_vertices", "vertex_views"],
    "sfm": ["Reconstruction", "bundle_from_cameras", "camera_errors", "choose_initial_pair", "covisibility",
            "incremental_sfm", "pyramid_score", "run_noise_study"],
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
