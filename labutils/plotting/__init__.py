"""Plot helpers: each takes an ``ax`` and returns it, and none calls ``plt.show()`` or changes global style;
the interactive 3D views (:func:`show_reconstruction`, :func:`show_mesh`) are plotly figures.

Modules: :mod:`~labutils.plotting.common` (cameras, points, images, epipolar lines, sparsity, the noise study,
the 3D views), :mod:`~labutils.plotting.matches` (07), :mod:`~labutils.plotting.views` (08–09),
:mod:`~labutils.plotting.carving` (11), :mod:`~labutils.plotting.stereo` (12) and
:mod:`~labutils.plotting.calibration` (13).
"""
from .calibration import (
    plot_board_poses,
    plot_corners,
    plot_distortion_field,
    plot_line_fits,
    plot_rectified_pair,
    plot_reprojection_errors,
    plot_view_influence,
)
from .carving import (
    plot_mask,
    plot_mesh,
    plot_silhouette_agreement,
)
from .common import (
    camera_frusta,
    few_ticks,
    image_frame,
    plot_cameras,
    plot_cameras_and_points,
    plot_epipolar_lines,
    plot_image_points,
    plot_inliers,
    plot_matches,
    plot_noise_study,
    plot_points,
    plot_pose_errors_topview,
    plot_sparsity,
    plot_two_view_from_above,
    plot_view_errors,
    set_axes_equal,
    show_mesh,
    show_reconstruction,
)
from .matches import (
    plot_match_lines,
    plot_track_lengths,
    side_by_side,
)
from .stereo import (
    plot_check_outcome,
    plot_disparity,
    plot_score_curve,
)
from .views import (
    plot_error_growth,
    plot_errors_per_view,
    plot_pyramid,
    plot_registration_order,
    plot_self_calibration,
    plot_view_graph,
)

__all__ = ["camera_frusta", "few_ticks", "image_frame", "plot_cameras", "plot_cameras_and_points",
           "plot_epipolar_lines", "plot_image_points", "plot_inliers", "plot_matches", "plot_noise_study",
           "plot_points", "plot_pose_errors_topview", "plot_sparsity", "plot_two_view_from_above", "plot_view_errors",
           "set_axes_equal", "show_mesh", "show_reconstruction", "plot_board_poses", "plot_corners",
           "plot_distortion_field", "plot_line_fits", "plot_rectified_pair", "plot_reprojection_errors",
           "plot_view_influence", "plot_mask", "plot_mesh", "plot_silhouette_agreement", "plot_match_lines",
           "plot_track_lengths", "side_by_side", "plot_check_outcome", "plot_disparity", "plot_score_curve",
           "plot_error_growth", "plot_errors_per_view", "plot_pyramid", "plot_registration_order",
           "plot_self_calibration",
           "plot_view_graph"]
