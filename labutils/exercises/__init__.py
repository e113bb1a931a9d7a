"""Exercises: the self-checks a student runs after writing a function, and the student edition.

The house convention for an exercise (every core notebook has at least two; every new notebook follows it
from its first commit):

1. **A solution cell** (nbgrader metadata ``solution: true``, a ``grade_id`` unique in the notebook) holds one
   function with a numpydoc docstring giving shapes and the convention, and the reference body between
   ``### BEGIN SOLUTION`` and ``### END SOLUTION``. The student edition (``python -m labutils.exercises
   release OUTDIR``, made by nbgrader's own preprocessors) replaces the body by a stub that raises
   ``NotImplementedError``.
2. **A visible self-check cell** right after it calls a check from this package, e.g.
   ``check_eight_point(eight_point)``: several cases (noise-free exactness, a random scene, an edge case),
   each printed as ``pass`` or a *specific hint* naming the likely mistake. A stub that is not written yet is
   reported as such; the cell never raises, so the student edition runs from top to bottom.
3. **An autograded test cell** (``grade: true``, ``locked: true``, with ``points``) whose only code is between
   ``### BEGIN HIDDEN TESTS`` and ``### END HIDDEN TESTS`` (plus a comment saying what is tested); hidden
   from the student edition, run by nbgrader's autograder and by nbval on the instructor notebooks.
4. **The notebook goes on with the student's function** (issue 19): the self-check cell ends with
   ``eight_point = yours.pick(eight_point)`` (:mod:`~labutils.exercises.yours`), which prints whose function the
   later cells use — the student's, or the library's while it is a stub, so a student who is stuck is never
   blocked — and the markdown after the tests says so in a sentence. Later notebooks read it with
   ``yours.load("eight_point")``. The setup imports none of the references the exercises reproduce, and the hidden
   tests run the function through ``yours.assert_own`` first (a body calling the library's version earns nothing);
   a hidden test may import a reference under a private name (``from labutils.twoview import fundamental_8point
   as _reference``).

At least one written question per notebook is a markdown cell with ``solution: true, grade: true`` and
``points`` (manually graded), whose model answer sits between ``### BEGIN SOLUTION`` / ``### END SOLUTION``.
Section headings say **(core)** or **(optional)**; the introduction gives a time estimate for the core.

The runner the checks share is :mod:`~labutils.exercises.runner` (:func:`run_checks`); each notebook's checks
live in a module of its own (``labutils.exercises.ex01_fundamental`` ...), so that a wrong answer can be tested against
its hint by the unit tests, without running the notebook.
"""
from . import yours
from .ex01_fundamental import (
    check_eight_point,
    check_gold_standard_residuals,
    check_normalisation_matrix,
    check_sampson,
)
from .ex02_essential import (
    check_choose_pose,
    check_four_poses,
    check_triangulate_linear,
)
from .ex03_pnp import (
    check_adaptive_ransac,
    check_pose_from_depths,
    p3p_ransac_inliers,
)
from .ex04_bundle import (
    check_projection_jacobian,
    check_schur_step,
    check_sparsity_mask,
)
from .ex05_sfm import (
    accept_points_reference,
    check_accept_points,
    check_choose_next_view,
    next_view_reference,
)
from .ex06_noise import (
    check_cramer_rao_pose,
    check_nees,
    cramer_rao_reference,
    nees_reference,
)
from .ex07_matching import (
    check_build_tracks,
    check_mutual_check,
    check_ratio_test,
)
from .ex08_views import (
    check_pose_covariance,
    check_pyramid_score,
)
from .ex09_global import (
    check_centres_from_directions,
    check_chordal_rotations,
)
from .ex10_model import (
    check_most_frontal_view,
    check_orient_normal,
    check_pca_normal,
)
from .ex11_carving import (
    check_carve_step,
    check_mask_iou,
    check_silhouette_from_colour,
)
from .ex12_stereo import (
    check_left_right_consistent,
    check_points_from_disparity,
    check_zncc_patch,
)
from .ex13_calibration import (
    check_distort_points,
    check_rectifying_rotation,
    check_zhang_intrinsics,
)
from .runner import CaseResult, CheckReport, run_checks

__all__ = ["CaseResult", "CheckReport", "run_checks", "yours", "check_eight_point", "check_gold_standard_residuals",
           "check_normalisation_matrix", "check_sampson", "check_choose_pose", "check_four_poses",
           "check_triangulate_linear",
           "check_adaptive_ransac", "check_pose_from_depths", "p3p_ransac_inliers", "check_projection_jacobian",
           "check_schur_step", "check_sparsity_mask", "accept_points_reference", "check_accept_points",
           "check_choose_next_view", "next_view_reference", "check_cramer_rao_pose", "check_nees",
           "cramer_rao_reference", "nees_reference", "check_build_tracks", "check_mutual_check", "check_ratio_test",
           "check_pose_covariance", "check_pyramid_score", "check_centres_from_directions", "check_chordal_rotations",
           "check_most_frontal_view", "check_orient_normal", "check_pca_normal", "check_carve_step", "check_mask_iou",
           "check_silhouette_from_colour", "check_left_right_consistent", "check_points_from_disparity",
           "check_zncc_patch", "check_distort_points", "check_rectifying_rotation", "check_zhang_intrinsics"]
