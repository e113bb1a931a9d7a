"""Camera calibration (notebook 13): the lens model, chessboard views (real and rendered), Zhang's closed form, the
refinement of K and distortion by Levenberg–Marquardt, stereo calibration, undistortion and rectification.

Modules: :mod:`~labutils.calibrate.lens` (OpenCV's distortion model and its inverse),
:mod:`~labutils.calibrate.chessboard` (the board, its corners, rendered views with exact truth),
:mod:`~labutils.calibrate.zhang` (homographies and K from the image of the absolute conic),
:mod:`~labutils.calibrate.camera` (:func:`calibrate_camera`, :func:`calibrate_stereo`, the views that matter),
:mod:`~labutils.calibrate.rectification` (undistortion, Fusiello's rectification) and
:mod:`~labutils.calibrate.cli` (``python -m labutils.calibrate``).
"""
from .camera import (
    CalibrationResult,
    StereoCalibration,
    calibrate_camera,
    calibrate_stereo,
    calibration_problem,
    view_influence,
)
from .chessboard import (
    board_points,
    detect_corners,
    grid_line_residuals,
    load_chessboard,
    load_stereo_chessboard,
    render_board,
    render_board_views,
    synthetic_board_views,
)
from .cli import main
from .lens import distort, project_points, undistort_points
from .rectification import Rectification, rectify_fusiello, rectify_image, rectify_points, undistort_image
from .zhang import board_homography, intrinsics_from_homographies, pose_from_homography

__all__ = ["CalibrationResult", "StereoCalibration", "calibrate_camera", "calibrate_stereo", "calibration_problem",
           "view_influence", "board_points", "detect_corners", "grid_line_residuals", "load_chessboard",
           "load_stereo_chessboard", "render_board", "render_board_views", "synthetic_board_views", "main",
           "distort", "project_points", "undistort_points", "Rectification", "rectify_fusiello", "rectify_image",
           "rectify_points", "undistort_image", "board_homography", "intrinsics_from_homographies",
           "pose_from_homography"]
