"""Two views (notebooks 01–02): the fundamental matrix, its maximum-likelihood estimate, the essential matrix and
the relative pose, and triangulation.

Modules: :mod:`~labutils.twoview.epipolar` (the 8-point algorithm, the Sampson distance, Torr's GRIC for degenerate
pairs, the homography DLT), :mod:`~labutils.twoview.seven_point` (the 7-point algorithm and RANSAC with its chance
test), :mod:`~labutils.twoview.gold_standard` (the ML F of H&Z Alg. 11.3),
:mod:`~labutils.twoview.essential` (E from F, its four poses and the cheirality test) and
:mod:`~labutils.twoview.triangulation` (DLT from two or more views, the optimal two-view correction, robust
triangulation of tracks).
"""
from .epipolar import (
    ModelSelection,
    design_matrix,
    fundamental_8point,
    gric_model_selection,
    hartley_normalisation,
    homography_dlt,
    sampson_distance,
)
from .essential import (
    check_parallax,
    cheirality_choice,
    cheirality_counts,
    decompose_essential,
    essential_from_fundamental,
    fundamental_from_pose,
    pose_from_essential,
    pure_rotation,
)
from .gold_standard import GoldStandardProblem, GoldStandardResult, fundamental_gold_standard, gold_standard_residuals
from .seven_point import FundamentalRansac, fundamental_7point, fundamental_ransac
from .triangulation import (
    fundamental_residual,
    ray_angles_deg,
    triangulate,
    triangulate_multiview,
    triangulate_optimal,
    triangulate_tracks,
)

__all__ = ["FundamentalRansac", "ModelSelection", "design_matrix", "fundamental_7point", "fundamental_8point",
           "fundamental_ransac",
           "gric_model_selection", "hartley_normalisation", "homography_dlt", "sampson_distance",
           "cheirality_choice", "cheirality_counts", "decompose_essential", "essential_from_fundamental",
           "fundamental_from_pose", "pose_from_essential", "GoldStandardProblem", "GoldStandardResult",
           "fundamental_gold_standard", "gold_standard_residuals", "fundamental_residual", "ray_angles_deg",
           "triangulate", "triangulate_multiview", "triangulate_optimal", "triangulate_tracks", "pure_rotation",
           "check_parallax"]
