"""A sweep of the public API with bad input, the way a careful user would try it (issues 8 and 21).

Every function in ``labutils.__all__``, and every helper a notebook imports from a stage package (``HELPERS``,
named ``module:function``), gets a valid call (``VALID``) and, for each of its array and number arguments, the
typical mistakes: a transposed array, a NaN, an inf, a missing column, too few rows, an empty array, a ragged list,
a string, a complex array, a negative or non-finite number, ``True`` or 5.5 for a count, a boolean or float array
for integer indices, and no ``rng``; and, by the argument's meaning, a K with negative focal lengths (an RQ split
whose signs were not fixed), a scaled "rotation", a zero or rank-3 F, ``E = I`` and a rank-1 P. Each must raise
``ValueError`` whose message names the argument — never a plausible result, a silent NaN, or another exception type
(numpy's ``IndexError``, ``ZeroDivisionError``...). The deliberately accepted cases are listed in ``ACCEPTED`` with
the reason. Degenerate geometry is swept in ``test_degenerate_geometry``; rotations printed to 6 digits must be
accepted (``test_rounded_rotations_are_accepted``); properties of the checks are tested with hypothesis.
"""
import importlib
import inspect
import json
import pkgutil
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import labutils as lu
from labutils.calibrate.chessboard import synthetic_board_views
from labutils.calibrate.lens import project_points
from labutils.core.scene import observations
from labutils.core.validation import (
    RotationProjectedWarning,
    as_calibration,
    as_essential,
    as_fundamental,
    as_indices,
    as_rotations,
)
from labutils.data.bal import BALProblem
from labutils.match import Features

S = lu.make_scene(40, 4, noise_px=0.5, rng=np.random.default_rng(0))
T = lu.make_scene(120, 8, layout="turntable", noise_px=0.3, rng=np.random.default_rng(1))
X1, X2, _ = S.pair(0, 1)
F = lu.fundamental_8point(X1, X2)
E = lu.essential_from_fundamental(F, S.K, S.K)
R01, T01 = lu.relative_pose(S.R[0], S.t[0], S.R[1], S.t[1])
CI, PI, XY = observations(S.x_meas)
CP = lu.camera_params_from_Rt(S.R, S.t)
REC = lu.incremental_sfm(T.tracks, T.K, rng=np.random.default_rng(0))
CIT, PIT, _ = observations(T.x_true)
P3 = S.X[:3]
x3 = lu.project(S.P[0], P3)

# the extensions: tiny scenes, so that the whole sweep stays cheap
PAIRS = np.array([[0, 1], [1, 2], [2, 3], [0, 3]])
R_REL = S.R[PAIRS[:, 1]] @ np.swapaxes(S.R[PAIRS[:, 0]], 1, 2)
DESC = np.random.default_rng(4).normal(size=(40, 16)).astype(np.float32)      # one descriptor per scene point
FEATS = [Features(S.x_meas[v], DESC + 0.01 * np.random.default_rng(5 + v).normal(size=DESC.shape).astype(np.float32),
                  image_size=(720, 576)) for v in range(4)]
VIEW_PAIRS = np.array([[0, 1], [1, 2], [2, 3]])
MATCHED = lu.match_views(FEATS, VIEW_PAIRS, rng=np.random.default_rng(0))
BLOCKS = (np.random.default_rng(7).uniform(size=(12, 16)) > 0.5).astype(np.uint8) * 255
TEXTURE = np.kron(BLOCKS, np.ones((4, 4), np.uint8))                   # 48 x 64, black and white blocks: corners
DIST = np.array([-0.2, 0.05, 0.001, -0.001, 0.0])
XN = np.random.default_rng(6).uniform(-0.4, 0.4, (10, 2))
BV = synthetic_board_views(rng=np.random.default_rng(0), n_views=4, noise_px=0.0, board=(5, 4))
OBJ = [BV.X] * 4
R_RIG, T_RIG = lu.rotation_from_angle_axis([0.0, 0.05, 0.0]), np.array([-0.1, 0.0, 0.0])
X_RIG = [project_points(BV.X, BV.K, BV.dist, R_RIG @ R, R_RIG @ t + T_RIG) for R, t in zip(BV.R, BV.t)]
CAL1 = lu.calibrate_camera(OBJ, BV.x_true, BV.image_size)
CAL2 = lu.calibrate_camera(OBJ, X_RIG, BV.image_size)
HS = np.stack([lu.board_homography(BV.X, x) for x in BV.x_true])
IMG = np.full((40, 40, 3), (40, 60, 200), np.uint8)
IMG[15:25, 15:25] = (230, 120, 20)
BG = lu.background_model([IMG, IMG])
BALL = np.array([[np.cos(a) * np.sin(b), np.sin(a) * np.sin(b), np.cos(b)]            # points on a unit sphere
                 for a in np.linspace(0, 2 * np.pi, 8, endpoint=False) for b in np.linspace(0.3, 2.8, 6)])
MESH = lu.delaunay_mesh(BALL, max_edge=10.0)
RB = np.stack([lu.rotation_from_angle_axis([0.0, a, 0.0]) for a in (0.0, 2.1, 4.2)])
TB = np.array([[0.0, 0.0, 4.0]] * 3)                                      # three cameras around the ball
KB = np.array([[30.0, 0, 20], [0, 30, 20], [0, 0, 1]])
VV = lu.vertex_views(MESH.vertices, MESH.faces, KB, RB, TB, [IMG] * 3)


def rng():
    return np.random.default_rng(3)


K_NEG = np.diag([-1.0, -1.0, 1.0]) @ S.K                     # what an RQ split gives before the signs are fixed


# name -> (positional args, keyword args); arrays are copied before every mutation
VALID = {
    "KRt_from_P": ((S.P[0],), {}),
    "P_from_KRt": ((S.K, S.R[0], S.t[0]), {}),
    "Rt_from_camera_params": ((CP,), {}),
    "align_cameras": ((S.R, S.t, S.R, S.t), {}),
    "align_similarity": ((S.X, 2 * S.X + 1), {}),
    "aligned_pose_covariance": ((T.R, T.t, T.X, CIT, PIT, T.K), {}),
    "angle_axis_from_rotation": ((S.R[0],), {}),
    "angle_between_deg": ((np.array([1.0, 0, 0]), np.array([1.0, 1, 0])), {}),
    "bearings": ((X1, S.K), {}),
    "bundle_adjust": ((S.R, S.t, S.X, CI, PI, XY, S.K), {}),
    "bundle_adjust_params": ((CP, S.X, CI, PI, XY, S.K), {}),
    "bundle_from_cameras": ((T.tracks, T.K, T.R, T.t), {}),
    "camera_center": ((S.R, S.t), {}),
    "camera_errors": ((REC, T.R, T.t), {}),
    "camera_params_from_Rt": ((S.R, S.t), {}),
    "cheirality_counts": ((E, X1, X2, S.K, S.K), {}),
    "decompose_essential": ((E,), {}),
    "dehomogeneous": ((np.hstack([X1, np.ones((len(X1), 1))]),), {}),
    "essential_from_fundamental": ((F, S.K, S.K), {}),
    "fundamental_7point": ((X1[:7], X2[:7]), {}),
    "fundamental_8point": ((X1, X2), {}),
    "fundamental_from_pose": ((S.K, S.K, R01, T01), {}),
    "fundamental_gold_standard": ((X1, X2), {}),
    "fundamental_ransac": ((X1, X2), {"rng": "RNG"}),
    "fundamental_residual": ((F, X1, X2), {}),
    "gauge_basis": ((S.R, S.t, S.X), {}),
    "homogeneous": ((X1,), {}),
    "incremental_sfm": ((T.tracks, T.K), {"rng": "RNG"}),
    "jacobian_sparsity": ((4, 40, CI, PI), {}),
    "left_jacobian_so3": ((np.array([0.1, 0.2, 0.3]),), {}),
    "make_scene": ((30, 3), {"rng": "RNG"}),
    "ml_residual_bound": ((1.0, 200, 150), {}),
    "observations": ((S.x_meas,), {}),
    "p3p": ((P3, x3, S.K), {}),
    "p3p_bearings": ((P3, lu.bearings(x3, S.K)), {}),
    "perturb_cameras": ((S.R, S.t), {"rng": "RNG"}),
    "pnp_ransac": ((S.X, S.x_meas[0], S.K), {"rng": "RNG"}),
    "pose_errors": ((S.R, S.t, S.R, S.t), {}),
    "pose_from_essential": ((E, X1, X2, S.K, S.K), {}),
    "predict_pose_errors": ((T.R, T.t, T.X, CIT, PIT, T.K), {}),
    "project": ((S.P[0], S.X), {}),
    "refine_pose": ((S.X, S.x_meas[0], S.K, S.R[0], S.t[0]), {}),
    "relative_pose": ((S.R[0], S.t[0], S.R[1], S.t[1]), {}),
    "reprojection_errors": ((S.X, S.x_meas[0], S.K, S.R[0], S.t[0]), {}),
    "reprojection_jacobian": ((CP, S.X, CI, PI, S.K), {}),
    "reprojection_residuals": ((CP, S.X, CI, PI, XY, S.K), {}),
    "right_jacobian_so3": ((np.array([0.1, 0.2, 0.3]),), {}),
    "rotation_error_deg": ((S.R[0], S.R[1]), {}),
    "rotation_from_angle_axis": ((np.array([0.1, 0.2, 0.3]),), {}),
    "sampson_distance": ((F, X1, X2), {}),
    "skew": ((np.array([1.0, 2.0, 3.0]),), {}),
    "triangulate": ((S.P[0], S.P[1], X1, X2), {}),
    "triangulate_multiview": ((S.P, S.x_meas), {}),
    "triangulate_optimal": ((F, X1, X2), {}),
    "triangulate_tracks": ((S.x_meas, np.stack([S.K] * 4), S.R, S.t, np.arange(4), S.visible),
                           {"threshold_px": 4.0, "min_angle_deg": 1.0}),
    "up_to_sign_scale": ((F, -2 * F), {}),
    # the extensions
    "gric_model_selection": ((X1, X2), {"sigma_px": 0.5}),
    "homography_dlt": ((X1, X2), {}),
    "hartley_normalisation": ((X1,), {}),
    "schur_step": ((CP, S.X, CI, PI, XY, S.K), {"mu": 1e-3}),
    "choose_initial_pair": ((T.tracks, T.K), {"rng": "RNG"}),
    "covisibility": ((T.tracks,), {}),
    "pyramid_score": ((X1, np.array([720.0, 576.0])), {"levels": 4}),
    "pose_covariance": ((S.X, S.K, S.R[0], S.t[0]), {"sigma": 0.5}),
    "chordal_rotation_averaging": ((PAIRS, R_REL, 4), {}),
    "ransac_iterations": ((0.5, 8, 0.99), {}),
    "match_descriptors": ((DESC, FEATS[1].descriptors), {"ratio": 0.8}),
    "match_views": ((FEATS, VIEW_PAIRS), {"rng": "RNG", "K": S.K}),
    "tracks_from_matches": ((FEATS, MATCHED), {"verify_px": 2.0}),
    "detect_features": ((TEXTURE,), {"scale": 0.5, "n_features": 50, "contrast_threshold": 0.04}),
    "distort": ((XN, DIST), {}),
    "undistort_points": ((lu.project(S.P[0], S.X), S.K, DIST), {}),
    "board_homography": ((BV.X, BV.x_true[0]), {}),
    "intrinsics_from_homographies": ((HS,), {}),
    "calibrate_camera": ((OBJ, BV.x_true, BV.image_size), {}),
    "calibrate_stereo": ((OBJ, BV.x_true, X_RIG, CAL1, CAL2), {}),
    "rectify_fusiello": ((S.K, S.K, R_RIG, T_RIG), {"image_size": (720, 576)}),
    "background_model": (([IMG, IMG],), {"border_px": 4}),
    "silhouette": ((IMG, BG), {"threshold": 2.5}),
    "estimate_normals": ((BALL,), {"k": 8}),
    "oriented_point_cloud": ((T.X, T.K, T.R, T.t, T.visible), {"k": 8}),
    "delaunay_mesh": ((BALL,), {"edge_factor": 8.0}),
    "vertex_views": ((MESH.vertices, MESH.faces, KB, RB, TB, [IMG] * 3), {}),
    "texture_vertices": ((VV,), {"fill": (128, 128, 128)}),
}

# The helpers the notebooks import from the stage packages (issue 21), as "module:function"
C_S = lu.camera_center(S.R, S.t)
MASK_A = np.zeros((40, 40), bool)
MASK_A[5:25, 5:25] = True
MASK_B = np.zeros((40, 40), bool)
MASK_B[12:30, 10:28] = True
TETRA = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
PATCH = np.random.default_rng(8).uniform(0, 255, (5, 5))
STEREO_R = np.random.default_rng(9).uniform(0, 255, (20, 40))
STEREO_L = np.roll(STEREO_R, 3, axis=1)
PB = np.stack([lu.P_from_KRt(KB, R, t) for R, t in zip(RB, TB)])
Y1 = lu.dehomogeneous(lu.homogeneous(X1) @ np.linalg.inv(S.K).T)          # normalised points of the pair
Y2 = lu.dehomogeneous(lu.homogeneous(X2) @ np.linalg.inv(S.K).T)
GS_P2 = np.hstack([np.eye(3), np.array([[0.1], [0.0], [1.0]])])            # a second camera [M | e']
GS_POINTS = np.column_stack([X1, np.full(len(X1), 0.01)])                 # (u, v, ρ): on the rays of view 1
VIS_B = np.ones((3, len(BALL)), bool)
DEPTH_MAP = importlib.import_module("labutils.model").DepthMap(np.full((4, 6), 2.0), np.array(
    [[10.0, 0, 2.5], [0, 10, 1.5], [0, 0, 1]]), np.eye(3), np.zeros(3))
KS = np.array([[200.0, 0, 79.5], [0, 200, 59.5], [0, 0, 1]])
STEREO_IMG = np.zeros((120, 160), np.uint8)
(RS1, TS1), (RS2, TS2) = lu.core.look_at([0.2, -3, 0], [0, 0, 0]), lu.core.look_at([-0.2, -3, 0], [0, 0, 0])
RECT_PAIR = importlib.import_module("labutils.model").rectify_pair(STEREO_IMG, STEREO_IMG, KS, RS1, TS1, KS, RS2, TS2)
SNOW = importlib.import_module("labutils.model").make_snowman(4, rng=np.random.default_rng(0), image_size=(64, 48),
                                                               f=84.0)
GRID = importlib.import_module("labutils.model").VoxelGrid(np.array([-0.64, -0.64, -0.62]), 0.11, (12, 12, 17))
CARVING = importlib.import_module("labutils.model").carve(SNOW.masks, SNOW.P, GRID)
SNOW_DIST = [np.abs(np.random.default_rng(k).normal(size=(48, 64))) * 3 for k in range(4)]
T_PAIRS = np.stack([lu.relative_pose(S.R[i], S.t[i], S.R[j], S.t[j])[1] for i, j in PAIRS])
REC_T = lu.incremental_sfm(T.tracks, T.K, rng=np.random.default_rng(0))
HELPERS = {
    "labutils.core:depths": ((S.R[0], S.t[0], S.X), {}),
    "labutils.core:look_at": ((np.array([0.0, -5.0, 1.0]), np.zeros(3)), {}),
    "labutils.core:rms": ((np.array([1.0, -2.0, 2.0]),), {}),
    "labutils.core.scene:tracks_from_observations": ((CI, PI, XY, 4, 40), {}),
    "labutils.core.scene:nan_tracks": ((np.nan_to_num(S.x_meas, nan=-1.0),), {}),
    "labutils.twoview:design_matrix": ((X1, X2), {}),
    "labutils.twoview:ray_angles_deg": ((C_S, S.X, S.visible), {}),
    "labutils.twoview.epipolar:transform_points": ((np.diag([2.0, 2.0, 1.0]), X1), {}),
    "labutils.twoview.epipolar:canonical_sign": ((F,), {}),
    "labutils.pose:pose_residuals": ((np.r_[0.0, 0.0, 0.0, S.t[0]], S.X, S.x_meas[0], S.K, S.R[0]), {}),
    "labutils.pose:pose_jacobian": ((np.r_[0.0, 0.0, 0.0, S.t[0]], S.X, S.x_meas[0], S.K, S.R[0]), {}),
    "labutils.pose:aligned_rotation_errors_deg": ((S.R, S.R), {}),
    "labutils.pose:largest_component": ((PAIRS, 4), {}),
    "labutils.pose:rotation_averaging": ((PAIRS, R_REL, 4), {}),
    "labutils.sfm:masked_reprojection_errors": ((S.K, S.R, S.t, S.X, S.x_meas, S.visible), {}),
    "labutils.sfm:align_reconstruction": ((REC_T, T.R, T.t), {}),
    "labutils.sfm:nees": ((np.array([[1.0, 0.0], [0.0, 2.0]]), np.diag([1.0, 4.0])), {}),
    "labutils.sfm:loglog_slope": ((np.array([0.5, 1.0, 2.0]), np.array([0.1, 0.2, 0.4])), {}),
    "labutils.sfm:noisy_observations": ((S.x_true, 0.5), {"rng": "RNG"}),
    "labutils.sfm:two_view_reconstruction": ((X1, X2, S.K, S.K), {"rng": "RNG"}),
    "labutils.sfm:observation_extent": ((T.tracks,), {}),
    "labutils.bundle:pose_error_map": ((S.R, S.t), {}),
    "labutils.bundle:gauge_pose_covariance": ((T.R, T.t, T.X, CIT, PIT, T.K), {}),
    "labutils.calibrate:pose_from_homography": ((HS[0], BV.K), {}),
    "labutils.data.formats:ply_text": ((S.X[:5],), {}),
    "labutils.sfm:ba_from_truth": ((S, S.x_meas), {}),
    "labutils.sfm:next_view": ((np.array([5, 9, 7, 3]), np.array([False, True, False, False])), {"min_points": 2}),
    "labutils.sfm:one_camera_trials": ((S.X, S.x_true[0], S.K, S.R[0], S.t[0], np.array([0.5, 1.0]), 2),
                                       {"rng": "RNG"}),
    "labutils.sfm:rms_errors": ((np.array([0.1, 0.2, np.nan]), np.array([0.01, 0.02, np.nan])), {}),
    "labutils.sfm:most_points_scores": ((T.tracks, T.visible, REC_T.registered), {}),
    "labutils.sfm:sequential_scores": ((T.tracks, T.visible, REC_T.registered), {}),
    "labutils.sfm:pyramid_scores": ((T.tracks, T.visible, REC_T.registered), {"levels": 3}),
    "labutils.sfm:candidate_pairs": ((T.tracks,), {"min_shared": 10, "n_partners": 3}),
    "labutils.sfm:reconstruct_without_ba": ((T.tracks, T.K, np.arange(len(T.R))), {"rng": "RNG"}),
    "labutils.sfm:refine_reconstruction": ((REC_T, T.tracks, T.K), {"max_iter": 5}),
    "labutils.pose:pair_directions": ((S.R, PAIRS, T_PAIRS), {}),
    "labutils.pose:centres_from_directions": ((PAIRS, C_S[PAIRS[:, 1]] - C_S[PAIRS[:, 0]], 4), {}),
    "labutils.pose:refine_rotations": ((S.R, PAIRS, R_REL), {"max_iter": 5}),
    "labutils.pose:robust_centres_from_points": ((T.tracks, T.K, T.R), {"n_iter": 2}),
    "labutils.bundle:effective_terms": ((np.diag([1.0, 2.0, 3.0]),), {}),
    "labutils.bundle:camera_information": ((lu.reprojection_jacobian(CP, S.X, CI, PI, S.K), 4, 40), {}),
    "labutils.calibrate:grid_line_residuals": ((BV.x_true[0],), {"board": (5, 4)}),
    "labutils.calibrate:rectify_points": ((BV.x_true[0], BV.K, BV.dist, HS[0]), {}),
    "labutils.calibrate:calibration_problem": ((OBJ, BV.x_true, BV.image_size), {}),
    "labutils.calibrate:undistort_image": ((IMG, KB, DIST), {}),
    "labutils.calibrate:rectify_image": ((IMG, KB, DIST, np.eye(3)), {}),
    "labutils.calibrate:synthetic_board_views": ((3, 0.1), {"rng": "RNG", "board": (5, 4)}),
    # the model stage: meshes, masks, colours, stereo
    "labutils.model:mask_iou": ((MASK_A, MASK_B), {}),
    "labutils.model:clean_mask": ((MASK_A,), {"max_hole": 0.01}),
    "labutils.model:mesh_volume": ((TETRA, TETRA_F), {}),
    "labutils.model:vertex_normals": ((TETRA, TETRA_F), {}),
    "labutils.model:edge_contrast": ((np.array([[0.0, 0, 0], [255, 255, 255], [0, 0, 0], [9, 9, 9]]), TETRA_F), {}),
    "labutils.model:scale_intrinsics": ((KB, 0.5), {}),
    "labutils.model:sample_image": ((IMG, np.array([[5.5, 6.0], [20.0, 30.0], [1.0, 2.0]])), {}),
    "labutils.model:zncc": ((PATCH, 3 * PATCH + 7), {}),
    "labutils.model:zncc_volume": ((STEREO_L, STEREO_R, np.array([2, 3, 4])), {"window": 5}),
    "labutils.model:disparity_plane_sweep": ((STEREO_L, STEREO_R, 0, 6), {"window": 5}),
    "labutils.model:left_right_check": ((np.array([[2.0, 2.0, 2.0, 2.0, 2.0]]), np.array([[2.0, 2.0, 5.0, 2.0, 2.0]])),
                                        {}),
    "labutils.model:local_pca": ((BALL,), {"k": 8}),
    "labutils.model:inside_silhouette": ((BALL, PB[0], MASK_B), {}),
    "labutils.model:render_silhouette": ((MESH.vertices, MESH.faces, PB[0], (40, 40)), {}),
    "labutils.model:silhouette_ious": ((MESH.vertices, MESH.faces, np.stack([MASK_B] * 3), PB), {}),
    "labutils.model:facing_fractions": ((BALL, BALL, RB, TB, VIS_B), {}),
    "labutils.model:orient_normals": ((BALL, BALL, RB, TB, VIS_B), {}),
    "labutils.model:most_frontal_view": ((BALL, BALL, lu.camera_center(RB, TB), VIS_B), {}),
    "labutils.model:point_colors": ((BALL, [IMG] * 3, KB, RB, TB, VIS_B), {}),
    "labutils.model:ring_pairs": ((RB, TB, np.zeros(3)), {"min_angle_deg": 1.0, "max_angle_deg": 150.0}),
    "labutils.model:colour_distance": ((IMG, BG), {}),
    "labutils.model:cloud_from_reconstruction": ((REC_T,), {"k": 8}),
    "labutils.model:depth_in_map": ((np.array([[0.0, 0.0, 2.1], [0.5, 0.0, 1.0]]), DEPTH_MAP), {}),
    "labutils.model:rectify_pair": ((STEREO_IMG, STEREO_IMG, KS, RS1, TS1, KS, RS2, TS2), {}),
    "labutils.model:disparity_range": ((RECT_PAIR, np.array([[0.0, -0.5, 0.0], [0.0, 0.5, 0.0]])), {}),
    "labutils.model:make_snowman": ((3,), {"rng": "RNG", "image_size": (64, 48), "f": 84.0}),
    "labutils.model:make_textured_scene": ((3,), {"rng": "RNG", "image_size": (64, 48), "f": 84.0}),
    "labutils.model:make_textured_spheres": ((3,), {"rng": "RNG", "image_size": (64, 48), "f": 84.0}),
    "labutils.model:make_layered_pair": ((), {"rng": "RNG", "image_size": (64, 48), "d_background": 2,
                                              "d_layers": (5, 8)}),
    "labutils.model:bounding_box_from_silhouettes": ((SNOW.masks, SNOW.P), {"n": 10}),
    "labutils.model:carve": ((SNOW.masks, SNOW.P, GRID), {}),
    "labutils.model:surface_mesh": ((CARVING,), {}),
    "labutils.model:held_out_error": ((VV, [0]), {}),
    "labutils.model:choose_threshold": ((SNOW_DIST, SNOW.P), {"candidates": (1.5, 2.5), "n": 10}),
    "labutils.model:depth_map_from_disparity": ((np.full(RECT_PAIR.image1.shape[:2], 30.0), RECT_PAIR), {}),
    "labutils.calibrate:view_influence": ((CAL1,), {}),
    "labutils.match:render_corner": ((3, (160, 120)), {"rng": "RNG", "texture_px": 256}),
    "labutils.model:segment_views": ((SNOW.images, SNOW.P), {"n": 10, "n_check": 12}),
    "labutils.twoview:cheirality_choice": ((lu.decompose_essential(E), Y1, Y2), {}),
    "labutils.twoview:gold_standard_residuals": ((GS_P2, GS_POINTS, X1, X2), {}),
    "labutils.bundle:levenberg_marquardt": ((CP, S.X, CI, PI, XY, S.K), {"max_iter": 3}),
}
VALID.update(HELPERS)

# Functions the notebooks import that are not swept, and why (by "module:function", or "module:*" for a package)
NOT_SWEPT_HELPERS = {
    "labutils.plotting:*": "figures; their arguments come from swept functions (tested in test_plotting*)",
    "labutils.exercises:*": "self-checks that run a student's function on the workbook's own cases "
                            "(tested in test_exercises_*)",
    "labutils.tools:*": "benchmark harnesses of callables (tested in test_bench)",
    "labutils.calibrate:main": "a command line (tested in test_command_lines)",
    "labutils.match:main": "a command line (tested in test_command_lines)",
    "labutils.sfm:main": "a command line (tested in test_command_lines)",
    "labutils.data:read_calibration": "files: tested in test_calibration",
    "labutils.data:read_model": "files: tested in test_ply", "labutils.data:read_result_json": "files",
    "labutils.data:read_tracks": "files", "labutils.data:write_tracks": "files",
    "labutils.data:validate_ply": "files: tested in test_ply",
    "labutils.core:ransac": "a harness of callables (tested in test_ransac)",
}
# Not yet swept (issue 21 left these for later): each needs a valid call of its own.
NOT_SWEPT_HELPERS.update({
    "labutils.reconstruct:focal_from_exif": "a file reader (the photo's EXIF header; tested in test_reconstruct)",
    "labutils.reconstruct:reconstruct_photos": "the photo pipeline over image files; its pieces are swept, the whole "
                                               "is tested in test_reconstruct and by its command line",
    "labutils.reconstruct:render_photo_folder": "writes rendered photos into a folder (tested in test_reconstruct)",
})
NOT_YET_SWEPT = {
    "labutils.sfm": "global_sfm view_graph",                           # ~1 s a call: ~25 mutations each
    "labutils.calibrate": "detect_corners load_stereo_chessboard render_board_views",     # images rendered, seconds
    "labutils.model": "fuse_depth_maps stereo_depth_map",              # need a textured rectified pair with depth
}


def _fn(name):
    """The function swept under ``name``: ``labutils.name``, or ``module:function``."""
    if ":" in name:
        module, attr = name.split(":")
        return getattr(importlib.import_module(module), attr)
    return getattr(lu, name)


# Public names not swept here, and why.
NOT_SWEPT = {
    "BundleResult": "a result record", "GoldStandardResult": "a result record", "PnPResult": "a result record",
    "Reconstruction": "a result record", "Scene": "a record", "Views": "a record",
    "DataNotFoundError": "an exception", "data_dirs": "no arguments", "load_dino": "no arguments",
    "load_fountain": "no arguments", "load_temple": "no arguments",
    "find_data": "a path; tested in test_data_and_synthetic", "has_data": "a path",
    "load_scene": "passes its keywords to make_scene (swept)", "read_bal": "files: tested in test_bal",
    "write_bal": "files: tested in test_bal (write_bal checks the problem first)",
    "run_noise_study": "a harness of callables; its checks are tested in test_uncertainty",
    "ModelSelection": "a result record", "SchurStep": "a result record", "RotationAveragingResult": "a result record",
    "CalibrationResult": "a result record", "PointCloud": "a record", "VoxelGrid": "a record",
    "Carving": "a result record",
    "read_ply": "files: tested in test_ply", "write_points": "files: tested in test_ply (test_write_points_bad_input)",
    "write_mesh": "files: tested in test_ply (test_write_mesh_bad_faces)",
}

# (function, argument, mutation) -> why a successful call is right there.
ACCEPTED = {
    ("Rt_from_camera_params", "camera_params", "one_row"): "one camera is a valid set of cameras",
    ("Rt_from_camera_params", "camera_params", "empty"): "no cameras in, no poses out",
    ("bearings", "x", "one_row"): "one pixel has one ray",
    ("project", "X", "one_row"): "one point projects to one pixel",
    ("homogeneous", "x", "one_row"): "one point",
    ("homogeneous", "x", "empty"): "no points in, no points out",
    ("dehomogeneous", "x_h", "one_row"): "one point",
    ("dehomogeneous", "x_h", "empty"): "no points in, no points out",
    ("observations", "x", "one_row"): "one view of tracks is a valid (1, T, 2) array",
    ("gauge_basis", "X", "one_row"): "the gauge of cameras and one point is still 7-dimensional",
    ("ml_residual_bound", "sigma", "zero"): "no noise, no residual: the bound is 0",
    ("ml_residual_bound", "n_params", "zero"): "a problem with no free parameter: the bound is sigma",
    ("triangulate_tracks", "min_angle_deg", "zero"): "accept every triangulation angle",
    ("triangulate_tracks", "views", "drop_column"): "triangulating from 3 of the 4 views is valid",
    ("camera_center", "R", "nan"): "NaN marks a camera that is not there (an unregistered view): its centre is NaN",
    ("camera_center", "t", "nan"): "NaN marks a camera that is not there (an unregistered view): its centre is NaN",
    ("bundle_from_cameras", "R", "nan"): "a NaN row leaves that camera out (documented)",
    ("bundle_from_cameras", "t", "nan"): "a NaN row leaves that camera out (documented)",
    ("bundle_from_cameras", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("incremental_sfm", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("choose_initial_pair", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("covisibility", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("covisibility", "tracks", "one_row"): "one view: the 1 x 1 count of the tracks it sees",
    ("pyramid_score", "x", "one_row"): "one point fills one cell per level (the docstring's example)",
    ("pyramid_score", "x", "empty"): "no points score 0 (documented: N may be 0)",
    ("ransac_iterations", "inlier_ratio", "zero"): "no inliers: no number of trials is enough; the largest int64 "
                                                   "(documented) lets a RANSAC loop run on to max_iter",
    ("detect_features", "image", "transposed"): "a transposed image is an image (of the scene turned)",
    ("detect_features", "image", "drop_column"): "an image one column narrower is an image",
    ("detect_features", "image", "one_row"): "an image one pixel high is an image (without keypoints)",
    ("detect_features", "n_features", "zero"): "0 keeps every keypoint (documented)",
    ("detect_features", "contrast_threshold", "zero"): "0 keeps every extremum (the weakest threshold, as in OpenCV)",
    ("match_descriptors", "d1", "one_row"): "one descriptor has one nearest neighbour: at most one match",
    ("match_descriptors", "d1", "empty"): "no descriptors (a blank image, detect_features' example): no matches",
    ("match_descriptors", "d2", "one_row"): "one candidate has no second neighbour to refuse a match by ratio; the "
                                            "mutual check keeps at most one match",
    ("match_descriptors", "d2", "empty"): "no descriptors in image 2: no matches",
    ("match_views", "pairs", "one_row"): "one pair of views is a valid list of pairs",
    ("match_views", "pairs", "empty"): "no pairs to match: an empty MatchResult (no row in its table)",
    ("distort", "xn", "one_row"): "one point",
    ("distort", "xn", "empty"): "no points in, no points out",
    ("pose_covariance", "sigma", "zero"): "σ = 0: no pixel noise, the zero covariance (documented)",
    ("distort", "dist", "drop_column"): "4 coefficients mean k3 = 0 (documented, as in OpenCV)",
    ("undistort_points", "x", "one_row"): "one point",
    ("undistort_points", "x", "empty"): "no points in, no points out",
    ("undistort_points", "dist", "drop_column"): "4 coefficients mean k3 = 0 (documented, as in OpenCV)",
    ("background_model", "images", "one_row"): "one image is enough to learn the colours at its border",
    ("silhouette", "image", "one_row"): "an image one pixel high is an image",
    ("silhouette", "threshold", "zero"): "0 is the strictest threshold: every colour not seen at the border is object",
    ("vertex_views", "faces", "one_row"): "one triangle is a mesh (the vertices on no face face no camera)",
}
ACCEPTED.update({
    ("texture_vertices", "fill", "float"): "a fill colour may be fractional (it is rounded like every colour)",
    ("labutils.core:depths", "X", "one_row"): "one point has one depth",
    ("labutils.core:rms", "r", "drop_column"): "the RMS of two numbers",
    ("labutils.core:rms", "r", "one_row"): "the RMS of one number",
    ("labutils.core.scene:nan_tracks", "raw", "one_row"): "one view of tracks",
    ("labutils.core.scene:nan_tracks", "raw", "empty"): "no views in, no views out",
    ("labutils.twoview.epipolar:transform_points", "x", "one_row"): "one point",
    ("labutils.twoview.epipolar:transform_points", "x", "empty"): "no points in, no points out",
    ("labutils.twoview.epipolar:canonical_sign", "F", "rank3"): "any non-zero matrix is scaled and signed (notebook "
                                                                 "01 normalises the raw 8-point solution with it)",
    ("labutils.twoview.epipolar:canonical_sign", "F", "drop_column"): "any non-zero matrix (the docstring's 2 × 2)",
    ("labutils.twoview.epipolar:canonical_sign", "F", "one_row"): "any non-zero matrix (the docstring's 2 × 2)",
    ("labutils.pose:aligned_rotation_errors_deg", "R_est", "nan"): "NaN marks a view without an estimate: its "
                                                                   "error is NaN (documented)",
    ("labutils.pose:largest_component", "pairs", "one_row"): "one edge: its two views are the largest part",
    ("labutils.pose:largest_component", "pairs", "empty"): "no edges: every view is its own part (documented)",
    ("labutils.sfm:nees", "errors", "one_row"): "one error vector has one NEES",
    ("labutils.sfm:noisy_observations", "x_true", "one_row"): "one view of tracks",
    ("labutils.sfm:noisy_observations", "sigma", "zero"): "σ = 0: no noise, the true pixels",
    ("labutils.sfm:observation_extent", "tracks", "nan"): "NaN marks an unseen observation (here a second NaN in an "
                                                          "unseen one)",
    ("labutils.sfm:observation_extent", "tracks", "one_row"): "one view has one box",
    ("labutils.data.formats:ply_text", "X", "one_row"): "a PLY file of one point",
    ("labutils.data.formats:ply_text", "X", "empty"): "a PLY file of no points (element vertex 0)",
    ("labutils.sfm:one_camera_trials", "sigmas", "drop_column"): "one noise level is a study of one level",
    ("labutils.sfm:one_camera_trials", "sigmas", "one_row"): "one noise level is a study of one level",
    ("labutils.sfm:most_points_scores", "tracks", "nan"):
        "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("labutils.sfm:sequential_scores", "tracks", "nan"):
        "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("labutils.sfm:pyramid_scores", "tracks", "nan"):
        "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("labutils.sfm:candidate_pairs", "tracks", "nan"):
        "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("labutils.sfm:reconstruct_without_ba", "tracks", "nan"):
        "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("labutils.sfm:refine_reconstruction", "tracks", "nan"):
        "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("labutils.pose:robust_centres_from_points", "tracks", "nan"):
        "NaN marks an unseen observation (here a second NaN in an unseen one)",
    ("labutils.sfm:reconstruct_without_ba", "order", "drop_column"): "an order of 7 of the 8 views reconstructs those",
    ("labutils.pose:robust_centres_from_points", "n_iter", "zero"): "no reweighting: the first, unweighted solution",
    ("labutils.calibrate:rectify_points", "x", "one_row"): "one point",
    ("labutils.calibrate:rectify_points", "x", "empty"): "no points in, no points out",
    ("labutils.calibrate:rectify_points", "dist", "drop_column"):
        "4 coefficients mean k3 = 0 (documented, as in OpenCV)",
    ("labutils.calibrate:undistort_image", "dist", "drop_column"):
        "4 coefficients mean k3 = 0 (documented, as in OpenCV)",
    ("labutils.calibrate:rectify_image", "dist", "drop_column"):
        "4 coefficients mean k3 = 0 (documented, as in OpenCV)",
    ("labutils.calibrate:synthetic_board_views", "noise_px", "zero"): "noise-free views (as in the docstring)",
    ("labutils.model:clean_mask", "mask", "drop_column"): "a mask of another size is a mask",
    ("labutils.model:clean_mask", "mask", "one_row"): "a mask one pixel high is a mask",
    ("labutils.model:clean_mask", "max_hole", "zero"): "0 fills no hole (the strictest setting)",
    ("labutils.model:mesh_volume", "faces", "one_row"):
        "the signed volume of the cone over one triangle from the origin: the formula, summed over a closed "
        "mesh, is its volume",
    ("labutils.model:vertex_normals", "faces", "one_row"):
        "one triangle is a mesh (the vertices on no face get the zero normal)",
    ("labutils.model:edge_contrast", "faces", "one_row"): "one triangle is a mesh",
    ("labutils.model:sample_image", "x", "one_row"): "one point",
    ("labutils.model:sample_image", "x", "empty"): "no points in, no samples out",
    ("labutils.model:zncc_volume", "disparities", "drop_column"): "fewer disparities to try",
    ("labutils.model:zncc_volume", "disparities", "one_row"): "one disparity to try",
    ("labutils.model:disparity_plane_sweep", "d_min", "zero"): "disparities from 0 (the docstring's example)",
    ("labutils.model:disparity_plane_sweep", "d_min", "negative"):
        "negative disparities are valid (points beyond the convergence of a rectified pair)",
    ("labutils.model:left_right_check", "d_left", "nan"): "NaN marks a pixel without a disparity (documented)",
    ("labutils.model:left_right_check", "d_right", "nan"): "NaN marks a pixel without a disparity (documented)",
    ("labutils.model:inside_silhouette", "X", "one_row"): "one point",
    ("labutils.model:inside_silhouette", "X", "empty"): "no points in, no answers out",
    ("labutils.model:inside_silhouette", "mask", "drop_column"):
        "a mask of another size is a mask (points outside it are outside)",
    ("labutils.model:inside_silhouette", "mask", "one_row"): "a mask one pixel high is a mask",
    ("labutils.model:render_silhouette", "faces", "one_row"): "one triangle is a mesh",
    ("labutils.model:render_silhouette", "faces", "empty"): "no triangles: an empty silhouette",
    ("labutils.model:silhouette_ious", "faces", "one_row"): "one triangle is a mesh",
    ("labutils.model:silhouette_ious", "faces", "empty"): "no triangles: empty silhouettes, IoU 0",
    ("labutils.model:silhouette_ious", "masks", "drop_column"):
        "masks of another size: the silhouettes are rendered at their size",
    ("labutils.model:ring_pairs", "min_angle_deg", "zero"): "no lower bound on the angle between two views",
    ("labutils.model:colour_distance", "image", "one_row"): "an image one pixel high is an image",
    ("labutils.model:depth_in_map", "X", "one_row"): "one point",
    ("labutils.model:depth_in_map", "X", "empty"): "no points in, no depths out",
    ("labutils.model:disparity_range", "X", "one_row"): "one point bounds the disparities too (with the margin)",
    ("labutils.model:make_layered_pair", "d_background", "zero"): "a background at infinity (disparity 0)",
    ("labutils.model:make_layered_pair", "d_layers", "drop_column"): "one layer in front of the background",
    ("labutils.model:make_layered_pair", "d_layers", "one_row"): "one layer in front of the background",
    ("labutils.model:make_layered_pair", "d_layers", "empty"): "no layers: the background alone",
    ("labutils.model:bounding_box_from_silhouettes", "masks", "drop_column"):
        "P carries no image size: a mask of any size is read as the image",
    ("labutils.model:carve", "masks", "drop_column"):
        "P carries no image size: a mask of any size is read as the image",
    ("labutils.model:choose_threshold", "distances", "drop_column"):
        "P carries no image size: a map of any size is read as the image",
    ("labutils.model:choose_threshold", "candidates", "drop_column"): "one threshold to choose from",
    ("labutils.model:choose_threshold", "candidates", "one_row"): "one threshold to choose from",
    ("labutils.model:depth_map_from_disparity", "disparity", "nan"): "NaN marks a pixel without a disparity: no depth",
})
NAN_IS_DOCUMENTED = {("camera_center", "R", "nan"), ("camera_center", "t", "nan"),
                     ("labutils.pose:aligned_rotation_errors_deg", "R_est", "nan"),
                     ("labutils.core.scene:nan_tracks", "raw", "one_row"),
                     ("labutils.sfm:reconstruct_without_ba", "tracks", "nan"),            # NaN: views not registered
                     ("labutils.sfm:reconstruct_without_ba", "order", "drop_column"),
                     ("labutils.sfm:refine_reconstruction", "tracks", "nan"),
                     # NaN where the window does not fit or no disparity is found (documented)
                     ("labutils.model:zncc_volume", "disparities", "drop_column"),
                     ("labutils.model:zncc_volume", "disparities", "one_row"),
                     ("labutils.model:disparity_plane_sweep", "d_min", "negative"),
                     ("labutils.model:disparity_plane_sweep", "d_min", "zero"),
                     ("labutils.model:depth_map_from_disparity", "disparity", "nan")}

# where a message rightly names the argument through the one it must agree with
ALIASES = {"bundle_adjust": {"X": "point_indices"},
           "labutils.model:mask_iou": {"a": r"\bb has shape .*; expected"},                # b must match a
           "labutils.model:edge_contrast": {"colors": r"\bvertices\b"},                   # one colour per vertex
           "labutils.model:render_silhouette": {"vertices": "faces hold vertex indices"},
           "labutils.model:silhouette_ious": {"vertices": "faces hold vertex indices",
                                              "P": r"masks has \d+ silhouettes for \d+ cameras"},
           "labutils.model:bounding_box_from_silhouettes": {"P": r"masks has \d+ silhouettes for \d+ cameras"},
           "labutils.model:carve": {"P": r"masks has \d+ silhouettes for \d+ cameras"},
           "labutils.model:choose_threshold": {"P": r"distances has \d+ maps for \d+ cameras"}}


K_ARGS = {"K", "K1", "K2", "Ks", "K_init", "K_new"}
ROTATION_ARGS = {"R", "R0", "R1", "R2", "R_est", "R_true", "R_rel", "R_rig"}
P_ARGS = {"P", "P1", "P2", "Ps"}


def _meaning_mutations(value, param):
    """The mistakes that depend on what an argument means (issue 21)."""
    a = np.asarray(value)
    out = []
    if param in K_ARGS and a.shape[-2:] == (3, 3):
        out.append(("negative_focal", np.diag([-1.0, -1.0, 1.0]) @ a))           # RQ without fixing the signs
        out.append(("zeros", np.zeros_like(a, dtype=float)))
    if param in ROTATION_ARGS and a.shape[-2:] == (3, 3):
        out.append(("scaled", 2.0 * a))
    if param == "F" and a.shape == (3, 3):
        out.append(("zeros", np.zeros((3, 3))))
        out.append(("rank3", np.eye(3)))
    if param == "E" and a.shape == (3, 3):
        out.append(("identity", np.eye(3)))
    if param in P_ARGS and a.shape[-2:] == (3, 4):
        rank1 = np.outer([1.0, 2.0, 3.0], [0.1, 0.2, 0.3, 1.0])
        out.append(("rank1", np.broadcast_to(rank1, a.shape).copy()))
    return out


def _mutations(value, param=None):
    """(kind, bad value) pairs for one argument's valid value."""
    out = []
    if isinstance(value, (bool, np.bool_)) or value is None or isinstance(value, (str, lu.Reconstruction)):
        return out
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool):
        out = [("negative", -abs(value) - 1), ("nan", float("nan")), ("string", "three"), ("zero", 0),
               ("bool", True), ("complex", complex(value, 1.0))]
        if isinstance(value, (int, np.integer)):
            out.append(("fraction", value + 0.5))
        return out
    try:
        a = np.asarray(value)
    except ValueError:                 # a ragged structure (a list of (R, t) poses): its parts are swept elsewhere
        return out
    if a.dtype.kind not in "fiub":
        return out
    out += _meaning_mutations(value, param)
    if a.dtype.kind == "f":
        b = a.astype(float).copy()
        b.flat[min(1, b.size - 1)] = np.nan
        out.append(("nan", b))
        b = a.astype(float).copy()
        b.flat[min(1, b.size - 1)] = np.inf
        out.append(("inf", b))
        out.append(("complex", a.astype(complex)))
    if a.dtype.kind in "iu" and a.ndim == 1 and a.size > 1:
        out.append(("bool", a % 2 == 1))                  # a mask where indices are expected
        out.append(("float", a.astype(float) + 0.5))
    if a.ndim == 2 and a.shape[0] != a.shape[1]:
        out.append(("transposed", a.T.copy()))
    if a.ndim >= 1 and a.shape[-1] > 1:
        out.append(("drop_column", a[..., :-1].copy()))
    if a.ndim >= 1 and a.shape[0] > 1:
        out.append(("one_row", a[:1].copy()))
        out.append(("empty", a[:0].copy()))
    if a.ndim == 2:
        out.append(("ragged", [list(r) for r in a[:2]] + [list(a[2][:-1])] if len(a) > 2 else [[1.0], [1.0, 2.0]]))
    out.append(("string", "not an array"))
    return out


def _is_rng(v):
    return isinstance(v, str) and v == "RNG"


def _calls():
    for name, (args, kwargs) in VALID.items():
        fn = _fn(name)
        params = list(inspect.signature(fn).parameters)
        for k, v in enumerate(args):
            for kind, bad in _mutations(v, params[k]):
                yield name, params[k], kind, (args[:k] + (bad,) + args[k + 1:]), kwargs
        for key, v in kwargs.items():
            if _is_rng(v):
                for kind, bad in (("none", None), ("int", 42)):
                    yield name, key, kind, args, {**kwargs, key: bad}
            else:
                for kind, bad in _mutations(v, key):
                    yield name, key, kind, args, {**kwargs, key: bad}


CALLS = list(_calls())


def _run(name, args, kwargs):
    kwargs = {k: (rng() if _is_rng(v) else v) for k, v in kwargs.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)     # a complex number cast to float: foreign
        return _fn(name)(*args, **kwargs)


def _short(name):
    return name.split(":")[-1]


def test_every_public_function_is_swept():
    missing = sorted(set(lu.__all__) - set(VALID) - set(NOT_SWEPT))
    assert not missing, f"public names neither swept nor excused in NOT_SWEPT: {missing}"


NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


def _notebook_imports():
    """(module, name) of every function the notebooks import from labutils."""
    out = set()
    for nb in sorted(NOTEBOOKS.glob("*.ipynb")):
        src = "\n".join("".join(c["source"]) for c in json.loads(nb.read_text())["cells"] if c["cell_type"] == "code")
        for m in re.finditer(r"from (labutils[\w.]*) import (\([^)]*\)|[^\n]*)", src):
            for n in m.group(2).strip("()").replace("\n", " ").split(","):
                n = n.split("#")[0].strip().split(" as ")[0].strip()
                if n and inspect.isfunction(getattr(importlib.import_module(m.group(1)), n, None)):
                    out.add((m.group(1), n))
    return out


def test_every_function_a_notebook_imports_is_swept():
    """Issue 21: the sweep covers what the notebooks use, not only ``labutils.__all__``."""
    swept = {_fn(name) for name in VALID}
    assert len(_notebook_imports()) > 100
    missing = []
    for module, name in sorted(_notebook_imports()):
        fn = getattr(importlib.import_module(module), name)
        if fn in swept or name in NOT_SWEPT or f"{module}:{name}" in NOT_SWEPT_HELPERS \
                or f"{module}:*" in NOT_SWEPT_HELPERS or name in NOT_YET_SWEPT.get(module, "").split():
            continue
        missing.append(f"{module}:{name}")
    assert not missing, f"functions the notebooks import, neither swept nor excused: {missing}"


def test_no_public_name_is_a_module_name():
    """Importing ``labutils.x`` sets the package's attribute ``x`` to the module, so a public name ``x`` that is also a
    module's (``ransac``, ``rotation_averaging``, ``global_sfm``, ``carve``) would be the function or the module
    depending on what was imported first; and ``import labutils.x as m`` would give the function once it is loaded."""
    modules = {m.name for m in pkgutil.iter_modules(lu.__path__)}
    both = sorted(set(lu.__all__) & modules)
    assert not both, f"public names that are also module names: {both}"


@pytest.mark.parametrize("name", sorted(VALID), ids=_short)
def test_valid_call_works(name):
    _run(name, *VALID[name])


def _nonfinite(out):
    """Whether a result holds NaN/inf where nothing says it may."""
    arrays = out if isinstance(out, tuple) else (out,)
    return any(isinstance(a, np.ndarray) and a.dtype.kind == "f" and not np.all(np.isfinite(a)) for a in arrays)


@pytest.mark.parametrize("name, arg, kind, args, kwargs", CALLS, ids=[f"{_short(c[0])}-{c[1]}-{c[2]}" for c in CALLS])
def test_bad_input_is_refused_by_name(name, arg, kind, args, kwargs):
    if (name, arg, kind) in ACCEPTED:
        out = _run(name, args, kwargs)
        assert (name, arg, kind) in NAN_IS_DOCUMENTED or not _nonfinite(out), \
            f"{name}({arg}={kind}) is accepted ({ACCEPTED[name, arg, kind]}) but returns NaN"
        return
    try:
        out = _run(name, args, kwargs)
    except ValueError as exc:
        msg = str(exc)
        assert re.search(rf"\b{re.escape(arg)}\b", msg) or arg in ALIASES.get(name, {}) and \
            re.search(ALIASES[name][arg], msg), f"{name}({arg}={kind}): the message does not name {arg!r}: {msg}"
        return
    except Exception as exc:            # noqa: BLE001 - the point is to catch foreign exception types
        pytest.fail(f"{name}({arg}={kind}) raised {type(exc).__name__}: {exc}")
    pytest.fail(f"{name}({arg}={kind}) returned a result instead of refusing"
                + (" (with NaN/inf in it)" if _nonfinite(out) else ""))


# ---------------------------------------------------------------------------------------------------------------
# Degenerate geometry and out-of-range settings: each must be refused by name, or flagged in the result
# ---------------------------------------------------------------------------------------------------------------
def _pure_rotation():
    """Two cameras at the same centre (a pure rotation) and their images of random points."""
    R2 = lu.rotation_from_angle_axis([0.0, 0.2, 0.05])
    P1 = lu.P_from_KRt(S.K, np.eye(3), np.zeros(3))
    P2 = lu.P_from_KRt(S.K, R2, np.zeros(3))
    Xw = np.random.default_rng(0).uniform(-1, 1, (20, 3)) + [0, 0, 6]
    return P1, P2, lu.project(P1, Xw), lu.project(P2, Xw)


def _behind_start():
    """The scene's points mirrored through the first camera's centre: every point starts behind camera 0."""
    X = S.X.copy()
    C0 = lu.camera_center(S.R[0], S.t[0])
    return 2 * C0 - X


DEGENERATE = [
    ("triangulate with a pure rotation", lambda: lu.triangulate(*_pure_rotation()), "same centre"),
    ("triangulate_multiview with identical cameras",
     lambda: lu.triangulate_multiview(np.stack([S.P[0], 3 * S.P[0]]), np.stack([X1, X1])), "same centre"),
    ("fundamental_from_pose with t = 0", lambda: lu.fundamental_from_pose(S.K, S.K, R01, np.zeros(3)), "t is zero"),
    ("angle_axis_from_rotation of 2 I", lambda: lu.angle_axis_from_rotation(2 * np.eye(3)), "not a rotation"),
    ("angle_axis_from_rotation of a reflection", lambda: lu.angle_axis_from_rotation(np.diag([1.0, 1, -1])),
     "not a rotation"),
    ("angle_axis_from_rotation of zeros", lambda: lu.angle_axis_from_rotation(np.zeros((3, 3))), "not a rotation"),
    ("rotation_error_deg with an inf entry",
     lambda: lu.rotation_error_deg(np.where(np.eye(3) > 0, np.inf, 0.0), np.eye(3)), "R_est"),
    ("rotation_error_deg of the zero matrix", lambda: lu.rotation_error_deg(np.zeros((3, 3)), np.eye(3)),
     "not a rotation"),
    ("angle_between_deg with a zero vector", lambda: lu.angle_between_deg([0, 0, 0], [1, 0, 0]), "zero vector"),
    ("bundle_adjust with the points behind the cameras",
     lambda: lu.bundle_adjust(S.R, S.t, _behind_start(), CI, PI, XY, S.K), "behind"),
    ("bundle_adjust with a singular K",
     lambda: lu.bundle_adjust(S.R, S.t, S.X, CI, PI, XY, np.diag([800.0, 0.0, 1.0])), "singular"),
    ("bundle_adjust with a point at a camera centre",
     lambda: lu.bundle_adjust(S.R, S.t, np.vstack([lu.camera_center(S.R[0], S.t[0]), S.X[1:]]), CI, PI, XY, S.K),
     "centre|behind"),
    ("bundle_adjust with t transposed (V = 4)", lambda: lu.bundle_adjust(S.R, S.t.T, S.X, CI, PI, XY, S.K),
     "transposed"),
    ("camera_params_from_Rt with t transposed", lambda: lu.camera_params_from_Rt(S.R, S.t.T), "transposed"),
    ("triangulate_tracks with t transposed (V = 4)",
     lambda: lu.triangulate_tracks(S.x_meas, np.stack([S.K] * 4), S.R, S.t.T, np.arange(4), S.visible,
                                   threshold_px=2.0, min_angle_deg=1.0),
     "transposed"),
    ("project with X transposed", lambda: lu.project(S.P[0], S.X.T), "transposed"),
    ("project with pixels instead of points", lambda: lu.project(S.P[0], X1), r"shape \(N, 3\)"),
    ("make_scene with negative noise", lambda: lu.make_scene(20, 2, noise_px=-1, rng=rng()), "noise_px"),
    ("make_scene with outlier_ratio 1.5", lambda: lu.make_scene(20, 2, outlier_ratio=1.5, rng=rng()),
     "outlier_ratio"),
    ("make_scene with a singular K", lambda: lu.make_scene(20, 2, K=np.diag([1.0, 0, 1]), rng=rng()), "singular"),
    ("make_scene with min_views above n_views",
     lambda: lu.make_scene(20, 3, layout="turntable", min_views=5, rng=rng()), "min_views"),
    ("pnp_ransac with confidence 1", lambda: lu.pnp_ransac(S.X, S.x_meas[0], S.K, rng=rng(), confidence=1.0),
     "confidence"),
    ("incremental_sfm with -1 markers", lambda: lu.incremental_sfm(np.nan_to_num(T.tracks, nan=-1.0), T.K,
                                                                 rng=rng()), "-1"),
    ("bundle_from_cameras with identical cameras",
     lambda: lu.bundle_from_cameras(T.tracks, T.K, np.stack([T.R[0]] * len(T.R)), np.stack([T.t[0]] * len(T.R))),
     "no track could be triangulated|same centre"),
    ("bundle_from_cameras with mirrored cameras",
     lambda: lu.bundle_from_cameras(T.tracks, T.K, T.R, -T.t), "no track could be triangulated"),
    ("write_bal with a NaN point", lambda: lu.write_bal("/tmp/never.txt", BALProblem(
        np.zeros((1, 9)), np.array([[np.nan, 0, 1]]), np.zeros(1, int), np.zeros(1, int), np.zeros((1, 2)))),
     "points_3d"),
    ("write_bal with a point index out of range", lambda: lu.write_bal("/tmp/never.txt", BALProblem(
        np.zeros((1, 9)), np.zeros((1, 3)), np.zeros(1, int), np.array([3]), np.zeros((1, 2)))), "point_indices"),
    ("write_bal with 6-column cameras", lambda: lu.write_bal("/tmp/never.txt", BALProblem(
        np.zeros((1, 6)), np.zeros((1, 3)), np.zeros(1, int), np.zeros(1, int), np.zeros((1, 2)))),
     "camera_params"),
    # issue 21: the mistakes that used to give a confident wrong answer
    ("pnp_ransac with the K of an RQ split whose signs were not fixed",
     lambda: lu.pnp_ransac(S.X, S.x_meas[0], K_NEG, rng=rng()), "positive focal lengths"),
    ("bundle_adjust with negative focal lengths", lambda: lu.bundle_adjust(S.R, S.t, S.X, CI, PI, XY, K_NEG),
     "positive focal lengths"),
    ("incremental_sfm with negative focal lengths", lambda: lu.incremental_sfm(T.tracks, K_NEG, rng=rng()),
     "positive focal lengths"),
    ("sampson_distance with F = 0", lambda: lu.sampson_distance(np.zeros((3, 3)), X1, X2), "F has rank < 2"),
    ("sampson_distance with a rank-3 F", lambda: lu.sampson_distance(np.eye(3), X1, X2), "rank 2"),
    ("decompose_essential of E = I", lambda: lu.decompose_essential(np.eye(3)), "not an essential matrix"),
    ("pose_from_essential with unequal singular values",
     lambda: lu.pose_from_essential(np.diag([1.0, 0.5, 0.0]), X1, X2, S.K, S.K), "not an essential matrix"),
    ("camera_center of 2 R", lambda: lu.camera_center(2 * S.R[0], S.t[0]), "not a rotation"),
    ("P_from_KRt with a singular K", lambda: lu.P_from_KRt(np.diag([800.0, 0.0, 1.0]), S.R[0], S.t[0]), "singular"),
    ("P_from_KRt with K = 0", lambda: lu.P_from_KRt(np.zeros((3, 3)), S.R[0], S.t[0]), "all zeros"),
    ("triangulate with a rank-1 P", lambda: lu.triangulate(np.outer([1.0, 2, 3], [0.1, 0.2, 0.3, 1]), S.P[1], X1, X2),
     "P1 has rank 1"),
    ("reprojection_residuals with boolean camera_indices",
     lambda: lu.reprojection_residuals(CP, S.X, CI % 2 == 1, PI, XY, S.K), "camera_indices.*boolean"),
    ("reprojection_jacobian with boolean camera_indices",
     lambda: lu.reprojection_jacobian(CP, S.X, CI % 2 == 1, PI, S.K), "camera_indices.*boolean"),
    ("jacobian_sparsity with boolean camera_indices", lambda: lu.jacobian_sparsity(4, 40, CI % 2 == 1, PI),
     "camera_indices.*boolean"),
    ("schur_step with boolean camera_indices",
     lambda: lu.schur_step(CP, S.X, CI % 2 == 1, PI, XY, S.K, mu=1e-3), "camera_indices.*boolean"),
    ("ply_text of a (3, 4) array", lambda: _fn("labutils.data.formats:ply_text")(np.zeros((3, 4))), r"\(N, 3\)"),
    ("ply_text with a NaN", lambda: _fn("labutils.data.formats:ply_text")([[0.0, np.nan, 1.0]]), "non-finite"),
    ("sampson_distance with complex pixels", lambda: lu.sampson_distance(F, X1 + 0j, X2), "x1 must be real"),
    ("make_scene with True points", lambda: lu.make_scene(True, 3, rng=rng()), "n_points"),
    ("make_scene with 5.5 views", lambda: lu.make_scene(30, 5.5, rng=rng()), "n_views"),
    ("a rotation 1e-3 off is refused", lambda: lu.camera_center(S.R[0] + 1e-3 * np.eye(3), S.t[0]),
     "not a rotation"),
]


@pytest.mark.parametrize("what, call, message", DEGENERATE, ids=[d[0] for d in DEGENERATE])
def test_degenerate_geometry(what, call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_bundle_adjust_flags_points_that_end_behind():
    """What cannot be checked at the start is reported in the result: success is False when points end behind."""
    res = lu.bundle_adjust(S.R, S.t, S.X, CI, PI, XY, S.K)
    assert res.success and res.n_behind == 0


# ---------------------------------------------------------------------------------------------------------------
# Rotations printed to 6 digits are read (issue 20): projected to SO(3), the correction reported in one line
# ---------------------------------------------------------------------------------------------------------------
ROUNDED = [(name, arg) for name, (args, kwargs) in VALID.items()
           for arg, v in list(zip(inspect.signature(_fn(name)).parameters, args)) + list(kwargs.items())
           if arg in ROTATION_ARGS and not isinstance(v, str) and np.shape(v)[-2:] == (3, 3)]


@pytest.mark.parametrize("name, arg", ROUNDED, ids=[f"{_short(n)}-{a}" for n, a in ROUNDED])
def test_rounded_rotations_are_accepted(name, arg):
    """Every function that takes a rotation reads one rounded to 1e-6 (with the one-line warning)."""
    args, kwargs = VALID[name]
    params = list(inspect.signature(_fn(name)).parameters)
    if arg in kwargs:
        kwargs = {**kwargs, arg: np.round(kwargs[arg], 6)}
    else:
        k = params.index(arg)
        args = args[:k] + (np.round(args[k], 6),) + args[k + 1:]
    with pytest.warns(RotationProjectedWarning, match=rf"^{re.escape(arg)}\b.* off a rotation .*largest correction"):
        _run(name, args, kwargs)


def test_bundle_from_cameras_reads_rounded_rotations():
    """EPFL's ground truth rotations are 1e-6 off SO(3): bundle_from_cameras accepts them, and refuses 1e-3 off."""
    with pytest.warns(RotationProjectedWarning) as caught:
        rec = lu.bundle_from_cameras(T.tracks, T.K, np.round(T.R, 6), T.t)
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    assert np.abs(rec.R[0] @ rec.R[0].T - np.eye(3)).max() < 1e-12
    R_bad = T.R.copy()
    R_bad[2] = R_bad[2] @ np.diag([1.0 + 1e-3, 1.0, 1.0])
    with pytest.raises(ValueError, match=r"R\[2\] is not a rotation"):
        lu.bundle_from_cameras(T.tracks, T.K, R_bad, T.t)


def test_middlebury_par_file_with_rounded_rotations(tmp_path):
    """A Middlebury parameter file printed to 6 digits is read (the carve command line reads it so); 1e-3 is not."""
    from labutils.data.middlebury import read_par

    def write(R, name):
        p = tmp_path / name
        rows = [f"v{k}.png " + " ".join(f"{v:.6f}" for v in np.r_[S.K.ravel(), R[k].ravel(), S.t[k]])
                for k in range(len(R))]
        p.write_text(f"{len(R)}\n" + "\n".join(rows) + "\n")
        return p
    with pytest.warns(RotationProjectedWarning, match=r"rounded_par.txt: 4 of 4 rotations .*largest correction") \
            as caught:
        views = read_par(write(S.R, "rounded_par.txt"), check_images=False)
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    assert np.abs(views.R @ np.swapaxes(views.R, 1, 2) - np.eye(3)).max() < 1e-12
    assert np.abs(views.R - S.R).max() < 2e-6
    R_bad = S.R.copy()
    R_bad[1] = R_bad[1] * (1 + 1e-3)
    with pytest.raises(ValueError, match=r"line 3: R is not a rotation"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RotationProjectedWarning)
        read_par(write(R_bad, "bad_par.txt"), check_images=False)


# ---------------------------------------------------------------------------------------------------------------
# Properties of the checks (hypothesis): what they accept, what they refuse
# ---------------------------------------------------------------------------------------------------------------
unit = st.floats(-1.0, 1.0, allow_nan=False)
axis3 = st.tuples(unit, unit, unit).filter(lambda v: np.linalg.norm(v) > 1e-3)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(axis3, st.floats(0.0, np.pi - 1e-7))
def test_angle_axis_round_trip(axis, angle):
    """log(exp(w)) = w for every angle in [0, π): the stable branch keeps 1e-9 also just below 180° (issue 21)."""
    w = angle * np.asarray(axis) / np.linalg.norm(axis)
    assert np.abs(lu.angle_axis_from_rotation(lu.rotation_from_angle_axis(w)) - w).max() < 1e-9


def test_angle_axis_just_below_pi():
    """The case of the issue: π − 9e-5 lost 6.4e-5 per entry; now round-off."""
    w = (np.pi - 9e-5) * np.array([0.48, -0.6, 0.64])
    assert np.abs(lu.angle_axis_from_rotation(lu.rotation_from_angle_axis(w)) - w).max() < 1e-12


@settings(max_examples=60, deadline=None, derandomize=True)
@given(axis3, st.floats(0.0, np.pi), st.floats(1e-8, 5e-5), st.integers(0, 8))
def test_near_rotations_are_projected(axis, angle, eps, entry):
    """A rotation with an entry off by up to 5e-5 is read as the nearest rotation, never moved by more than 2ε."""
    R = lu.rotation_from_angle_axis(angle * np.asarray(axis) / np.linalg.norm(axis))
    M = R.copy()
    M.flat[entry] += eps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RotationProjectedWarning)
        Rp = as_rotations(M[None])[0]
    assert np.abs(Rp @ Rp.T - np.eye(3)).max() < 1e-12 and np.linalg.det(Rp) > 0
    assert np.abs(Rp - M).max() <= 2 * eps


@settings(max_examples=60, deadline=None, derandomize=True)
@given(axis3, st.floats(0.0, np.pi), st.floats(1e-3, 0.5), st.integers(0, 8))
def test_far_from_rotations_are_refused(axis, angle, eps, entry):
    R = lu.rotation_from_angle_axis(angle * np.asarray(axis) / np.linalg.norm(axis))
    R.flat[entry] += eps
    with pytest.raises(ValueError, match="not a rotation"):
        as_rotations(R[None])


focal = st.floats(1.0, 1e4)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(focal, focal, st.floats(-50, 50), st.floats(0, 2000), st.floats(0, 2000), st.sampled_from([1, 2, 3]))
def test_calibration_sign_rule(fx, fy, skew, cx, cy, flip):
    """K with positive focal lengths is accepted at any scale (also a negative one); a flipped fx or fy is not."""
    K = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    assert np.allclose(as_calibration(-3.0 * K), K)
    D = np.diag([-1.0 if flip & 1 else 1.0, -1.0 if flip & 2 else 1.0, 1.0])
    with pytest.raises(ValueError, match="positive focal lengths"):
        as_calibration(D @ K)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.integers(0, 9), min_size=1, max_size=30))
def test_indices_rule(idx):
    """Integers in range pass; the same as booleans, floats or out of range do not."""
    assert as_indices(np.array(idx), "camera_indices", 10).tolist() == idx
    for bad in (np.array(idx) % 2 == 0, np.array(idx, float), np.array(idx) + 10, np.array(idx) - 10):
        with pytest.raises(ValueError, match="camera_indices"):
            as_indices(bad, "camera_indices", 10)


matrix3 = st.lists(st.floats(-10, 10, allow_nan=False), min_size=9, max_size=9).map(lambda v: np.reshape(v, (3, 3)))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(matrix3)
def test_fundamental_and_essential_rules(M):
    """A matrix is read as F only with rank 2 and as E only with singular values (s, s, 0), within tolerance."""
    U, s, Vt = np.linalg.svd(M)
    assume(s[0] > 1e-3 and s[2] > 1e-3 * s[0] and s[0] - s[1] > 1e-3 * s[0])   # away from the boundaries
    for check in (as_fundamental, as_essential):
        with pytest.raises(ValueError):
            check(M)
    F = (U[:, :2] * s[:2]) @ Vt[:2]
    as_fundamental(F)
    with pytest.raises(ValueError, match="not an essential matrix"):
        as_essential(F)
    as_essential(U @ np.diag([s[0], s[0], 0.0]) @ Vt)
