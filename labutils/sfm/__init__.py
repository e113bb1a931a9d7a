"""Structure from motion (notebooks 05–09): the calibrated two-view start, which view next, incremental and global
SfM, the result record, and the noise study that holds the result against the Cramér–Rao prediction.

Modules: :mod:`~labutils.sfm.initial_pair` (the relative pose and points of the first two views),
:mod:`~labutils.sfm.view_selection` (the initial pair and the next-best-view strategies),
:mod:`~labutils.sfm.reconstruction` (the :class:`Reconstruction` record and its errors against truth),
:mod:`~labutils.sfm.incremental` (:func:`incremental_sfm`, :func:`bundle_from_cameras`, ``python -m labutils.sfm``),
:mod:`~labutils.sfm.global_sfm` (rotation averaging, positions, BA) and :mod:`~labutils.sfm.noise_study`.
"""
from .global_sfm import ViewGraph, candidate_pairs, global_sfm, view_graph
from .incremental import bundle_from_cameras, incremental_sfm, main
from .initial_pair import two_view_reconstruction
from .noise_study import (
    NoiseStudy,
    Progress,
    ba_from_truth,
    loglog_slope,
    nees,
    noisy_observations,
    one_camera_trials,
    pose_error_vectors,
    reconstruct_without_ba,
    refine_reconstruction,
    rms_errors,
    run_noise_study,
)
from .reconstruction import Reconstruction, align_reconstruction, camera_errors, masked_reprojection_errors
from .view_selection import (
    STRATEGIES,
    choose_initial_pair,
    covisibility,
    most_points_scores,
    next_view,
    observation_extent,
    pyramid_score,
    pyramid_scores,
    sequential_scores,
)

__all__ = ["ViewGraph", "candidate_pairs", "global_sfm", "view_graph", "bundle_from_cameras", "incremental_sfm",
           "main", "two_view_reconstruction", "NoiseStudy", "Progress", "ba_from_truth", "loglog_slope", "nees",
           "noisy_observations", "one_camera_trials", "pose_error_vectors", "reconstruct_without_ba",
           "refine_reconstruction", "rms_errors", "run_noise_study", "Reconstruction", "align_reconstruction",
           "camera_errors", "masked_reprojection_errors", "STRATEGIES", "choose_initial_pair", "covisibility",
           "most_points_scores", "next_view", "observation_extent", "pyramid_score", "pyramid_scores",
           "sequential_scores"]
