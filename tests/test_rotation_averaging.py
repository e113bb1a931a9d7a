"""Rotation averaging: the view graph checks, SO(3) projection, the chordal start, the robust IRLS refinement."""
import numpy as np
import pytest

from labutils.core.geometry import rotation_from_angle_axis
from labutils.core.metrics import rotation_error_deg
from labutils.pose.rotation_averaging import (
    aligned_rotation_errors_deg,
    as_view_graph,
    chordal_rotation_averaging,
    largest_component,
    project_to_so3,
    refine_rotations,
    relative_rotation_errors_deg,
    rotation_averaging,
)


def graph(seed, n_views=10, complete=True, noise_deg=0.0, n_wrong=0):
    """Random rotations; relative rotations R_j R_iᵀ on a complete graph (or a ring), noise, some edges wrong."""
    rng = np.random.default_rng(seed)
    R = rotation_from_angle_axis(rng.normal(size=(n_views, 3)))
    if complete:
        pairs = np.array([(i, j) for i in range(n_views) for j in range(i + 1, n_views)])
    else:
        pairs = np.array([(v, (v + 1) % n_views) for v in range(n_views)])
    R_rel = R[pairs[:, 1]] @ np.swapaxes(R[pairs[:, 0]], 1, 2)
    if noise_deg:
        noise = rng.normal(scale=np.radians(noise_deg) / np.sqrt(3), size=(len(pairs), 3))
        R_rel = rotation_from_angle_axis(noise) @ R_rel
    wrong = rng.choice(len(pairs), n_wrong, replace=False)
    R_rel[wrong] = rotation_from_angle_axis(rng.normal(size=(n_wrong, 3)))
    return pairs, R_rel, R, wrong


def aligned(R_est, R_true):
    """Per-view error (degrees) after the best global rotation R_i -> R_i Q."""
    Q = project_to_so3(np.einsum("vji,vjk->ik", R_est, R_true))
    return rotation_error_deg(R_est @ Q, R_true)


# --- bad input -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("pairs, message", [
    (np.zeros((3,)), r"pairs must have shape \(E, 2\)"),
    ([[0, 1, 2]], r"pairs must have shape \(E, 2\)"),
    ([[0, 5]], r"integers in 0..2"),
    ([[0, 1.5]], r"integers in 0..2"),
    ([[1, 1]], r"pairs\[0\] joins view 1 to itself"),
    ([[0, np.nan]], r"integers in 0..2"),
])
def test_bad_pairs(pairs, message):
    with pytest.raises(ValueError, match=message):
        as_view_graph(pairs, np.eye(3)[None], 3)


def test_bad_rotations_weights_and_graphs():
    with pytest.raises(ValueError, match=r"R_rel must have shape \(1, 3, 3\)"):
        as_view_graph([[0, 1]], np.eye(3), 2)
    with pytest.raises(ValueError, match="R_rel.* not a rotation"):
        as_view_graph([[0, 1]], [2 * np.eye(3)], 2)
    with pytest.raises(ValueError, match="weights must be positive"):
        as_view_graph([[0, 1]], [np.eye(3)], 2, weights=[-1.0])
    with pytest.raises(ValueError, match=r"weights must have shape \(1,\)"):
        as_view_graph([[0, 1]], [np.eye(3)], 2, weights=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"not connected: views \[2, 3\]"):
        chordal_rotation_averaging([[0, 1]], [np.eye(3)], 4)
    with pytest.raises(ValueError, match="anchor"):
        chordal_rotation_averaging([[0, 1]], [np.eye(3)], 2, anchor=2)
    with pytest.raises(ValueError, match="loss"):
        refine_rotations(np.stack([np.eye(3)] * 2), [[0, 1]], [np.eye(3)], loss="huber")
    with pytest.raises(ValueError, match="R0"):
        refine_rotations(np.ones((2, 3, 3)), [[0, 1]], [np.eye(3)])
    with pytest.raises(ValueError, match="rank < 2"):
        project_to_so3(np.outer([1.0, 0, 0], [0, 1.0, 0]))
    with pytest.raises(ValueError, match="non-finite"):
        project_to_so3(np.full((3, 3), np.nan))


def test_largest_component():
    assert largest_component([[0, 1], [2, 3], [3, 4]], 6).tolist() == [False, False, True, True, True, False]
    assert largest_component([], 3).tolist() == [True, False, False]
    assert largest_component(np.zeros((0, 2), int), 1).tolist() == [True]


def test_largest_component_refuses_bad_pairs():
    with pytest.raises(ValueError, match=r"pairs must have shape \(E, 2\)"):
        largest_component([[0, 1, 2], [1, 2, 3]], 4)  # (2, 3): once read as three edges
    with pytest.raises(ValueError, match="pairs must hold view indices"):
        largest_component([[0, 5]], 4)
    with pytest.raises(ValueError, match="pairs must hold view indices"):
        largest_component([[0, np.nan]], 4)
    with pytest.raises(ValueError, match="n_views must be an integer"):
        largest_component([[0, 1]], 0)


# --- SO(3) projection -------------------------------------------------------------------------------------------


def test_projection_is_the_nearest_rotation():
    rng = np.random.default_rng(0)
    for _ in range(20):
        M = rng.normal(size=(3, 3))
        R = project_to_so3(M)
        assert abs(np.linalg.det(R) - 1) < 1e-12 and np.allclose(R @ R.T, np.eye(3))
        others = project_to_so3(R @ rotation_from_angle_axis(rng.normal(scale=0.2, size=(50, 3))))
        assert np.linalg.norm(M - R) <= np.linalg.norm(M - others, axis=(1, 2)).min() + 1e-12
    R0 = rotation_from_angle_axis([0.3, -0.2, 1.0])
    assert np.allclose(project_to_so3(R0), R0, atol=1e-14) and np.allclose(project_to_so3(5 * R0), R0)


# --- the chordal start -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("complete", [True, False])
def test_chordal_noise_free_exact(complete):
    pairs, R_rel, R, _ = graph(1, complete=complete)
    R_est = chordal_rotation_averaging(pairs, R_rel, len(R), anchor=3)
    assert np.allclose(R_est[3], np.eye(3), atol=1e-12)                      # the gauge
    assert rotation_error_deg(R_est, R @ R[3].T).max() < 1e-9
    assert relative_rotation_errors_deg(R_est, pairs, R_rel).max() < 1e-9


def test_chordal_does_not_depend_on_the_edge_direction_or_order():
    pairs, R_rel, R, _ = graph(2, noise_deg=3.0)
    w = np.random.default_rng(0).uniform(10, 100, len(pairs))
    a = chordal_rotation_averaging(pairs, R_rel, len(R), w)
    flip = np.arange(len(pairs)) % 2 == 0                                    # (i, j, R_ij) -> (j, i, R_ijᵀ)
    p2, R2 = pairs.copy(), R_rel.copy()
    p2[flip], R2[flip] = pairs[flip][:, ::-1], np.swapaxes(R_rel[flip], 1, 2)
    perm = np.random.default_rng(1).permutation(len(pairs))
    b = chordal_rotation_averaging(p2[perm], R2[perm], len(R), w[perm])
    assert rotation_error_deg(a, b).max() < 1e-8


def test_least_squares_error_matches_the_graph_laplacian():
    """σ per edge on a complete graph of V views: the averaged rotations are off by RMS σ·√(V-1)/V per view.

    With edge noise n_ij ~ N(0, s² I₃) (s = σ/√3 per axis), the linearised least-squares estimate has covariance
    s² L⁺ ⊗ I₃ in the mean-zero gauge (the best-aligned one), L = V I - 11ᵀ the Laplacian of the complete graph,
    L⁺ = (I - 11ᵀ/V)/V: each view's squared error is 3 s² (V-1)/V² = σ² (V-1)/V². Over 20 graphs × 10 views × 3
    axes (540 degrees of freedom after the gauge) the RMS has a relative standard deviation of about 3 %: a ±15 %
    band is 5σ (200 graphs give 0.987).
    """
    V, sigma = 10, 2.0
    sq = []
    for seed in range(20):
        pairs, R_rel, R, _ = graph(10 + seed, n_views=V, noise_deg=sigma)
        R0 = chordal_rotation_averaging(pairs, R_rel, V)
        res = refine_rotations(R0, pairs, R_rel, loss="l2")
        assert res.converged
        sq.append(aligned(res.R, R) ** 2)
    rms = np.sqrt(np.mean(sq))
    assert abs(rms / (sigma * np.sqrt(V - 1) / V) - 1) < 0.15


# --- the robust refinement -------------------------------------------------------------------------------------


@pytest.mark.parametrize("loss", ["l1", "cauchy"])
def test_robust_refinement_ignores_wrong_edges(loss):
    """12 views, 66 edges, 13 of them replaced by random rotations: the chordal start is pulled off by degrees,
    the robust IRLS returns the truth and singles out the wrong edges.

    L1 ignores a wrong edge entirely at the optimum (exact, to the IRLS floor); Cauchy still feels it: its influence
    ρ'(r) ≈ c²/r is about 1e-3 rad for c = 2° and an edge ~1 rad off, against ~10 good edges per view — a bias of
    about 1e-4 rad (0.01°) per wrong edge at a view.
    """
    pairs, R_rel, R, wrong = graph(3, n_views=12, n_wrong=13)
    R0 = chordal_rotation_averaging(pairs, R_rel, 12)
    assert aligned(R0, R).max() > 2.0
    res = refine_rotations(R0, pairs, R_rel, loss=loss)
    assert aligned(res.R, R).max() < (1e-5 if loss == "l1" else 0.05)
    bad = res.residuals_deg > 1.0
    assert set(np.flatnonzero(bad)) == set(wrong)
    assert res.weights[wrong].max() < 0.05 * np.median(res.weights[~bad])
    plain = refine_rotations(R0, pairs, R_rel, loss="l2")
    assert aligned(plain.R, R).max() > 1.0                                   # least squares is not robust


def test_rotation_averaging_with_noise_and_outliers():
    pairs, R_rel, R, wrong = graph(4, n_views=15, noise_deg=1.0, n_wrong=15)
    res = rotation_averaging(pairs, R_rel, 15, loss="cauchy", scale_deg=2.0)
    assert np.allclose(res.R[0], np.eye(3), atol=1e-12)
    # the least-squares error of the 90 good edges is about 1·√14/15 = 0.25° per view: allow twice that
    assert np.sqrt(np.mean(aligned(res.R, R) ** 2)) < 0.5
    assert np.all(res.residuals_deg[wrong] > 10)


def test_aligned_rotation_errors():
    pairs, R_rel, R, _ = graph(5, n_views=6)
    Q = rotation_from_angle_axis([0.2, -1.0, 0.4])
    assert np.nanmax(aligned_rotation_errors_deg(R @ Q, R)) < 1e-9
    R_est = R @ Q
    R_est[2] = rotation_from_angle_axis([0.0, 0.0, np.radians(3.0)]) @ R_est[2]
    R_est[4] = np.nan
    err = aligned_rotation_errors_deg(R_est, R)
    assert np.isnan(err[4]) and 2.0 < err[2] < 3.0 and np.nanmax(np.delete(err, [2, 4])) < 1.0
    with pytest.raises(ValueError, match=r"R_est must have shape \(6, 3, 3\)"):
        aligned_rotation_errors_deg(R_est[:3], R)
