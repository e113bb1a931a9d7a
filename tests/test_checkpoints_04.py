"""Notebook 04's checkpoints on the algorithm's own steps fail for plausibly wrong exercise answers (issues 9, 19).

The test runs the notebook's cells tagged ``checkpoint-04`` (setup, the residual, the small problem, the Jacobian
against finite differences, the turntable and its mask, one Schur step against the damped normal equations) in a
namespace where the exercise functions the checkpoints use (``projection_jacobian``, ``sparsity_mask``,
``schur_step``: the student's from exercise 1-3 on) are the library's references, or one is replaced by a wrong
one, runs each top-level ``assert`` on its own, and
checks that the checkpoint made for that step is among the failing ones — and that nothing fails with the library.
"""
import ast
from pathlib import Path

import matplotlib
import numpy as np
import scipy.sparse as sp
from _checkpoints import tagged_cells

from labutils.bundle.reprojection import jacobian_sparsity, reprojection_blocks
from labutils.bundle.schur import schur_step_dense
from labutils.core.geometry import left_jacobian_so3

matplotlib.use("Agg")
NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "04_bundle_adjustment.ipynb"
JACOBIAN = "assert jac_rel_err < 1e-6"
MASK = "assert missed == 0 and per_row.max() == 9"
SCHUR = "assert schur_err < 1e-8"


def _cells():
    return tagged_cells(NOTEBOOK, "checkpoint-04")


def _failing_asserts(replace=None):
    """Run the tagged cells (with ``replace`` bound in the namespace after the setup); the asserts that fail."""
    cells = _cells()
    assert "rng = np.random.default_rng(" in cells[0]
    for check in (JACOBIAN, MASK, SCHUR):
        assert any(check in src for src in cells), f"the notebook no longer has the checkpoint {check!r}"
    ns = {"__name__": "checkpoint_04"}
    exec(cells[0], ns)
    ns.update(projection_jacobian=reprojection_blocks, sparsity_mask=jacobian_sparsity, schur_step=schur_step_dense)
    ns.update(replace or {})
    failing = []
    for src in cells[1:]:
        for node in ast.parse(src).body:
            code = compile(ast.Module([node], []), "<cell>", "exec")
            if isinstance(node, ast.Assert):
                try:
                    exec(code, ns)
                except AssertionError:
                    failing.append(ast.get_source_segment(src, node))
            else:
                exec(code, ns)
    return failing


def test_checkpoints_hold_for_the_library(capsys):
    assert _failing_asserts() == []


def _jacobian_without_left_jacobian(camera_params, points_3d, camera_indices, point_indices, K):
    """Notebook 03's -[RX]× used at ω ≠ 0: the rotation columns of each camera times J_l(ω)⁻¹."""
    Jc, Jp = reprojection_blocks(camera_params, points_3d, camera_indices, point_indices, K)
    w = np.asarray(camera_params)[np.asarray(camera_indices), :3]
    Jc[:, :, :3] = Jc[:, :, :3] @ np.linalg.inv(left_jacobian_so3(w))
    return Jc, Jp


def test_finite_differences_catch_a_jacobian_without_J_l(capsys):
    assert JACOBIAN in _failing_asserts({"projection_jacobian": _jacobian_without_left_jacobian})


def test_the_mask_checkpoint_catches_a_mask_without_points(capsys):
    def cameras_only(n_cameras, n_points, camera_indices, point_indices):
        A = jacobian_sparsity(n_cameras, n_points, camera_indices, point_indices).tolil()
        A[:, 6 * n_cameras:] = 0
        return A.tocsr()
    assert MASK in _failing_asserts({"sparsity_mask": cameras_only})


def test_the_mask_checkpoint_catches_a_full_mask(capsys):
    def everything(n_cameras, n_points, camera_indices, point_indices):
        return sp.csr_matrix(np.ones((2 * len(camera_indices), 6 * n_cameras + 3 * n_points), np.int8))
    assert MASK in _failing_asserts({"sparsity_mask": everything})


def _dense_step(damp):
    """A wrong exercise step: the damped normal equations with ``damp(A, mu, n_cam_cols)`` added."""
    def step(J, r, n_cam_cols, mu):
        J = J.toarray() if sp.issparse(J) else np.asarray(J)
        A = J.T @ J
        delta = np.linalg.solve(A + damp(A, mu, n_cam_cols), -J.T @ r)
        return delta[:n_cam_cols], delta[n_cam_cols:]
    return step


def _damp_cameras_only(A, mu, c):
    D = np.zeros_like(A)
    D[:c, :c] = mu * np.diag(np.diag(A[:c, :c]))
    return D + 1e-12 * np.eye(len(A)) * np.abs(A).max()        # just enough to be solvable


def test_the_schur_checkpoint_catches_wrong_damping(capsys):
    for damp in (_damp_cameras_only, lambda A, mu, c: mu * np.eye(len(A))):
        assert SCHUR in _failing_asserts({"schur_step": _dense_step(damp)})
