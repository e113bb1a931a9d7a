"""Two-view geometry: F (8-point, 7-point, RANSAC, gold standard), E, and the relative pose."""
import numpy as np
import pytest

from labutils.core.geometry import (
    P_from_KRt,
    dehomogeneous,
    homogeneous,
    project,
    relative_pose,
    rotation_from_angle_axis,
    skew,
)
from labutils.core.metrics import angle_between_deg, rotation_error_deg
from labutils.core.synthetic import DEFAULT_K, make_scene
from labutils.twoview.epipolar import (
    epipole_search,
    fundamental_8point,
    gric_model_selection,
    hartley_normalisation,
    homography_dlt,
    sampson_distance,
)
from labutils.twoview.essential import (
    check_parallax,
    cheirality_counts,
    decompose_essential,
    essential_from_fundamental,
    fundamental_from_pose,
    pose_from_essential,
    pure_rotation,
)
from labutils.twoview.gold_standard import GoldStandardProblem, fundamental_gold_standard
from labutils.twoview.seven_point import fundamental_7point, fundamental_ransac
from labutils.twoview.triangulation import fundamental_residual, triangulate_optimal


def truth(s, i=0, j=1):
    R, t = relative_pose(s.R[i], s.t[i], s.R[j], s.t[j])
    return R, t, fundamental_from_pose(s.K, s.K, R, t)


def same_up_to_sign(A, B):
    A, B = A / np.linalg.norm(A), B / np.linalg.norm(B)
    return min(np.abs(A - B).max(), np.abs(A + B).max())


def rotation_only(rng, n=60, noise_px=0.0, w=(0.02, -0.05, 0.03)):
    """Two views from one centre: x2 = K R K⁻¹ x1 (zero baseline)."""
    s = make_scene(n, 2, noise_px=0.0, rng=rng)
    x1 = s.pair(0, 1, which="true")[0]
    H = s.K @ rotation_from_angle_axis(w) @ np.linalg.inv(s.K)
    x2 = dehomogeneous(homogeneous(x1) @ H.T)
    return x1 + rng.normal(scale=noise_px, size=x1.shape), x2 + rng.normal(scale=noise_px, size=x2.shape)


def forward_pair(rng, n=100, noise_px=0.5, K=DEFAULT_K):
    """Camera 2 a step of 0.5-1 ahead of camera 1, turned by 1-5°; n points in a cloud of ±1 at depth 4-10.

    The epipole is inside the image; with the cloud far (depth 10) and the step short the parallax is
    close to the noise. Returns x1, x2 (noisy) and the true F.
    """
    X = rng.uniform(-1, 1, (n, 3)) + [0.0, 0.0, rng.uniform(4, 10)]
    axis = rng.normal(size=3)
    R = rotation_from_angle_axis(np.radians(rng.uniform(1, 5)) * axis / np.linalg.norm(axis))
    t = -R @ [0.0, 0.0, rng.uniform(0.5, 1.0)]
    x1 = project(P_from_KRt(K, np.eye(3), np.zeros(3)), X)
    x2 = project(P_from_KRt(K, R, t), X)
    return (x1 + rng.normal(scale=noise_px, size=x1.shape), x2 + rng.normal(scale=noise_px, size=x2.shape),
            fundamental_from_pose(K, K, R, t))


# ---------------------------------------------------------------- shapes and bad input

def test_bad_input(rng):
    s = make_scene(20, 2, noise_px=0.0, rng=rng)
    x1, x2, _ = s.pair(0, 1, which="true")
    with pytest.raises(ValueError, match="at least 8"):
        fundamental_8point(x1[:7], x2[:7])
    with pytest.raises(ValueError, match="row by row"):
        fundamental_8point(x1, x2[:-1])
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        fundamental_8point(homogeneous(x1), x2)
    for bad in (np.nan, np.inf):
        y = x1.copy()
        y[4, 0] = bad
        with pytest.raises(ValueError, match="non-finite"):
            fundamental_8point(y, x2)
        with pytest.raises(ValueError, match="non-finite"):
            fundamental_gold_standard(y, x2)
    with pytest.raises(ValueError, match="coincide"):
        fundamental_8point(np.ones((10, 2)), x2[:10])
    with pytest.raises(ValueError, match="exactly 7"):
        fundamental_7point(x1[:8], x2[:8])
    with pytest.raises(ValueError, match="rng"):
        fundamental_ransac(x1, x2, rng=None)
    with pytest.raises(ValueError, match="threshold"):
        fundamental_ransac(x1, x2, threshold_px=0.0, rng=rng)
    with pytest.raises(ValueError, match="singular"):
        essential_from_fundamental(np.eye(3), np.zeros((3, 3)), s.K)
    with pytest.raises(ValueError, match="rank < 2"):
        decompose_essential(np.outer([1.0, 0, 0], [0, 1.0, 0]))
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        pose_from_essential(np.eye(2), x1, x2, s.K, s.K)
    with pytest.raises(ValueError, match="rank 2"):
        fundamental_gold_standard(x1, x2, F0=np.eye(3))


@pytest.mark.parametrize("case", ["plane", "rotation"])
def test_noise_free_degenerate_raises(case, rng):
    if case == "plane":
        s = make_scene(40, 2, noise_px=0.0, planar=True, rng=rng)
        x1, x2, _ = s.pair(0, 1, which="true")
    else:
        x1, x2 = rotation_only(rng, n=40)
    for n in (8, 9, 40):                    # the rank test works from the minimal 8 points on
        with pytest.raises(ValueError, match="degenerate.*plane.*baseline"):
            fundamental_8point(x1[:n], x2[:n])
    with pytest.raises(ValueError, match="degenerate"):
        fundamental_gold_standard(x1, x2)
    with pytest.raises(ValueError, match="degenerate"):
        fundamental_ransac(x1, x2, rng=rng, max_iter=200)
    assert fundamental_7point(x1[:7], x2[:7]) == []        # a degenerate minimal sample gives no model


# Rates of the noisy-degeneracy test (GRIC, module docstring of labutils.twoview.epipolar): at N = 300, σ = 1 px, 82-87
# %
# of planar and pure-rotation scenes are refused (two runs of 300 scenes each). Of 20 scenes we ask for at least 12:
# with p = 0.82 the count is Binomial(20, 0.82), mean 16.4, s.d. 1.7, and P(count < 12) ≈ 0.3 %. Given the true
# σ, GRIC refuses 99.7-100 % of them (at N = 200 already 98-99 %), so we ask for 19 of 20.
@pytest.mark.parametrize("case", ["plane", "rotation"])
def test_noisy_degenerate_refused_at_the_measured_rate(case):
    rng = np.random.default_rng(7)
    refused = refused_known_sigma = 0
    for _ in range(20):
        if case == "plane":
            x1, x2, _ = make_scene(300, 2, noise_px=1.0, planar=True, rng=rng).pair(0, 1)
        else:
            x1, x2 = rotation_only(rng, n=300, noise_px=1.0, w=np.radians(rng.uniform(1, 5)) * rng.normal(size=3))
        try:
            fundamental_8point(x1, x2)
        except ValueError as exc:
            assert "homography explains them at least as well as F" in str(exc) and "GRIC" in str(exc)
            refused += 1
        refused_known_sigma += gric_model_selection(x1, x2, sigma_px=1.0).degenerate
    assert refused >= 12 and refused_known_sigma >= 19, (refused, refused_known_sigma)
    assert fundamental_8point(x1, x2, degeneracy=None).shape == (3, 3)         # the test can be turned off ...
    with pytest.raises(ValueError, match="degeneracy must be"):
        fundamental_8point(x1, x2, degeneracy="ratio")


def test_forward_motion_pairs_are_not_refused():
    """30 forward pairs (epipole in the image, some with parallax near the noise): none refused, and the
    gold standard fits them at least as well as the true F (pooled squared residuals).

    The old test (the 8-point F against H at a fixed ratio of 1.25) refused some of these very pairs: the
    8-point F is far from the best F in forward motion, so H looked as good as F.
    """
    rng = np.random.default_rng(2024)
    sq_gs = sq_true = 0.0
    old_refused = 0
    for _ in range(30):
        x1, x2, F_true = forward_pair(rng)
        n = len(x1)
        sq_gs += fundamental_residual(fundamental_gold_standard(x1, x2).F, x1, x2) ** 2     # raises if refused
        sq_true += fundamental_residual(F_true, x1, x2) ** 2
        F8 = fundamental_8point(x1, x2, degeneracy=None)
        s2_H = np.sum(homography_dlt(x1, x2)[1] ** 2) / (2 * n - 8)
        old_refused += s2_H < 1.25 * np.sum(sampson_distance(F8, x1, x2) ** 2) / (n - 7)
    assert sq_gs <= sq_true
    assert old_refused >= 1


def test_gric_model_selection_record():
    rng = np.random.default_rng(3)
    x1, x2, F_true = forward_pair(rng, n=80)
    ms = gric_model_selection(x1, x2)
    n = len(x1)
    assert ms.n == n and ms.F.shape == ms.H.shape == (3, 3) and abs(np.linalg.norm(ms.F) - 1) < 1e-12
    assert np.linalg.svd(ms.F, compute_uv=False)[2] < 1e-12                        # rank 2
    assert ms.e_F == pytest.approx(np.sum(sampson_distance(ms.F, x1, x2) ** 2))
    assert ms.e_H == pytest.approx(np.sum(homography_dlt(x1, x2)[1] ** 2))
    # near maximum likelihood: below the 8-point (one of its starts) and the true F, within 1 % of the gold standard
    assert ms.e_F <= np.sum(sampson_distance(fundamental_8point(x1, x2, degeneracy=None), x1, x2) ** 2)
    assert ms.e_F <= np.sum(sampson_distance(F_true, x1, x2) ** 2)
    F_gs = fundamental_gold_standard(x1, x2).F
    assert ms.e_F <= 1.01 * np.sum(sampson_distance(F_gs, x1, x2) ** 2)
    assert ms.sigma == pytest.approx(np.sqrt(ms.e_F / (n - 7)))
    assert ms.gric_F == pytest.approx(n - 7 + 3 * n * np.log(4) + 7 * np.log(4 * n))
    assert ms.gric_H == pytest.approx(ms.e_H / ms.sigma ** 2 + 2 * n * np.log(4) + 8 * np.log(4 * n))
    assert ms.degenerate == (ms.gric_H <= ms.gric_F)
    assert f"{ms.gric_F:.1f}" in ms.text() and f"N = {n}" in ms.text()
    known = gric_model_selection(x1, x2, sigma_px=0.5)
    assert known.sigma == 0.5
    assert known.gric_F == pytest.approx(known.e_F / 0.25 + 3 * n * np.log(4) + 7 * np.log(4 * n))
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="sigma_px"):
            gric_model_selection(x1, x2, sigma_px=bad)
    with pytest.raises(ValueError, match="at least 9"):
        gric_model_selection(x1[:8], x2[:8])


# ---------------------------------------------------------------- invariants

def test_invariants(rng):
    s = make_scene(60, 2, noise_px=1.0, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    for F in (fundamental_8point(x1, x2), fundamental_gold_standard(x1, x2).F,
              fundamental_ransac(x1, x2, rng=rng)[0], *fundamental_7point(x1[:7], x2[:7])):
        sv = np.linalg.svd(F, compute_uv=False)
        assert abs(np.linalg.norm(F) - 1) < 1e-12 and sv[2] < 1e-12 * sv[0]
        assert F.flat[np.argmax(np.abs(F))] > 0
    E = essential_from_fundamental(fundamental_8point(x1, x2), s.K, s.K)
    assert np.allclose(np.linalg.svd(E, compute_uv=False), [1, 1, 0], atol=1e-12)
    poses = decompose_essential(E)
    assert len(poses) == 4
    for R, t in poses:
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and abs(np.linalg.det(R) - 1) < 1e-12
        assert abs(np.linalg.norm(t) - 1) < 1e-12
        assert same_up_to_sign(skew(t) @ R, E) < 1e-12       # each of the four explains E
    T = hartley_normalisation(x1)
    y = dehomogeneous(homogeneous(x1) @ T.T)
    assert np.allclose(y.mean(0), 0, atol=1e-12) and np.isclose(np.linalg.norm(y, axis=1).mean(), np.sqrt(2))


# ---------------------------------------------------------------- recovery on noise-free data

@pytest.mark.parametrize("layout", ["general", "forward", "turntable"])
def test_noise_free_recovery(layout, rng):
    s = make_scene(100, 3 if layout != "turntable" else 36, layout=layout, noise_px=0.0, rng=rng)
    x1, x2, _ = s.pair(0, 1, which="true")
    R_true, t_true, F_true = truth(s)
    F = fundamental_8point(x1, x2)
    assert same_up_to_sign(F, F_true) < 1e-8
    assert sampson_distance(F, x1, x2).max() < 1e-8
    assert same_up_to_sign(fundamental_gold_standard(x1, x2).F, F_true) < 1e-8
    E = essential_from_fundamental(F, s.K, s.K)
    assert same_up_to_sign(E, skew(t_true) @ R_true) < 1e-8
    R, t = pose_from_essential(E, x1, x2, s.K, s.K)
    counts = cheirality_counts(E, x1, x2, s.K, s.K)
    assert rotation_error_deg(R, R_true) < 1e-6 and angle_between_deg(t, t_true) < 1e-6
    assert sorted(counts)[-1] == len(x1) and sorted(counts)[-2] < len(x1)    # cheirality picks one
    Fs = fundamental_7point(x1[:7], x2[:7])
    assert min(same_up_to_sign(F7, F_true) for F7 in Fs) < 1e-6


def test_dino_noise_free_pairs(dino):
    """Every pair of views sharing >= 8 noise-free points: pose to better than 1e-6 degrees."""
    worst_R = worst_t = 0.0
    n_pairs = 0
    for i in range(dino.n_views):
        for j in range(i + 1, dino.n_views):
            x1, x2, _ = dino.pair(i, j, which="true")
            if len(x1) < 8:
                continue
            R_true, t_true = relative_pose(dino.R[i], dino.t[i], dino.R[j], dino.t[j])
            E = essential_from_fundamental(fundamental_8point(x1, x2), dino.K, dino.K)
            R, t = pose_from_essential(E, x1, x2, dino.K, dino.K)
            worst_R = max(worst_R, rotation_error_deg(R, R_true))
            worst_t = max(worst_t, angle_between_deg(t, t_true))
            n_pairs += 1
    assert n_pairs > 150
    assert worst_R < 1e-6 and worst_t < 1e-6


# ---------------------------------------------------------------- Sampson distance, RANSAC

def test_sampson_is_first_order_geometric_distance(rng):
    s = make_scene(100, 2, noise_px=0.01, rng=rng)             # tiny noise: first order is exact enough
    x1, x2, _ = s.pair(0, 1)
    F = truth(s)[2]
    d = sampson_distance(F, x1, x2)
    x1_hat, x2_hat = triangulate_optimal(F, x1, x2)
    d_opt = np.sqrt(((x1 - x1_hat) ** 2).sum(1) + ((x2 - x2_hat) ** 2).sum(1))
    assert np.allclose(d, d_opt, rtol=1e-3, atol=1e-9)
    assert np.allclose(sampson_distance(-7.0 * F, x1, x2), d)          # scale-free


def test_ransac_finds_inliers(rng):
    s = make_scene(200, 2, noise_px=0.5, outlier_ratio=0.3, rng=rng)
    x1, x2, idx = s.pair(0, 1)
    outlier = s.outliers[0, idx] | s.outliers[1, idx]
    F, inl = fundamental_ransac(x1, x2, threshold_px=1.5, rng=rng)
    R_true, t_true, F_true = truth(s)
    assert inl.dtype == bool and inl.shape == (len(x1),)
    assert np.all(inl[~outlier].mean() > 0.97)                           # keeps the good ones ...
    assert sampson_distance(F_true, x1[inl], x2[inl]).max() < 1.5 + 4 * 0.5     # ... and only near-consistent ones
    # the inliers' 8-point F explains them at the noise level: the Sampson distance is the distance to the
    # constraint surface (codimension 1) in 4D, so its RMS is ≈ σ (a little less: fitted, and cut at 3σ)
    assert 0.75 * 0.5 < np.sqrt(np.mean(sampson_distance(F, x1[inl], x2[inl]) ** 2)) < 1.1 * 0.5


def test_ransac_real_tracks(dino):
    x1, x2, _ = dino.pair(10, 11, which="tracks")
    F, inl = fundamental_ransac(x1, x2, threshold_px=1.0, rng=np.random.default_rng(0))
    assert inl.mean() > 0.9
    assert fundamental_residual(F, x1[inl], x2[inl]) < 0.5


# ---------------------------------------------------------------- the gold standard

def test_jacobian_matches_finite_differences(rng):
    s = make_scene(6 + 8, 2, noise_px=1.0, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    problem = GoldStandardProblem(x1, x2, fundamental_8point(x1, x2))
    p = problem.p0 + 1e-3 * rng.normal(size=problem.n_params)
    J = problem.jacobian(p).toarray()
    h = 1e-6
    J_fd = np.column_stack([(problem.residuals(p + h * e) - problem.residuals(p - h * e)) / (2 * h)
                            for e in np.eye(problem.n_params)])
    assert np.abs(J - J_fd).max() < 1e-6 * max(1.0, np.abs(J).max())
    mask = problem.sparsity().toarray() > 0
    assert not np.any(J_fd[~mask])                                  # the mask covers every non-zero
    assert J.shape == (4 * len(x1), 12 + 3 * len(x1))


def test_initial_cost_is_the_residual_of_F0(rng):
    s = make_scene(40, 2, noise_px=1.0, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    F0 = fundamental_8point(x1, x2)
    problem = GoldStandardProblem(x1, x2, F0)
    r = problem.residuals(problem.p0)
    assert np.sqrt(np.mean(r ** 2)) == pytest.approx(fundamental_residual(F0, x1, x2), rel=1e-9)
    assert same_up_to_sign(problem.F(problem.p0), F0) < 1e-9


def test_our_lm_reaches_the_scipy_optimum(rng):
    from scipy.optimize import least_squares

    s = make_scene(30, 2, noise_px=1.0, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    problem = GoldStandardProblem(x1, x2, fundamental_8point(x1, x2))
    p, info = problem.solve()
    ref = least_squares(problem.residuals, problem.p0, jac=problem.jacobian, method="trf", tr_solver="lsmr",
                        x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=2000)
    assert info["converged"] and info["cost"][-1] <= ref.cost * (1 + 1e-6)
    assert np.all(np.diff(info["cost"]) < 0)                        # every accepted step lowers the cost


def test_gold_standard_returns_points(rng):
    s = make_scene(50, 2, noise_px=1.0, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    gs = fundamental_gold_standard(x1, x2)
    F, x1_hat, x2_hat = gs.F, gs.x1_hat, gs.x2_hat
    a, b = homogeneous(x1_hat), homogeneous(x2_hat)
    assert np.abs(np.einsum("ni,ij,nj->n", b, F, a)).max() < 1e-10 * np.abs(a).max() * np.abs(b).max()
    rms = np.sqrt((((x1 - x1_hat) ** 2).sum() + ((x2 - x2_hat) ** 2).sum()) / (4 * len(x1)))
    assert rms == pytest.approx(fundamental_residual(F, x1, x2), rel=1e-6)
    assert gs.residual == pytest.approx(rms, rel=1e-9)


# Trial counts for the ML bound: per trial 4N r² / σ² ~ χ²(N - 7) (H&Z Result 5.2), so the pooled mean of r²
# over T trials has relative s.d. sqrt(2 / (T (N - 7))) and its square root half that, 1 / sqrt(2 T (N - 7)).
# T (N - 7) >= 9000 puts that s.d. at <= 0.75 %, so the 3 % band is >= 4 s.d. wide: chance does not decide it.
@pytest.mark.parametrize("n, trials", [(50, 210), (200, 47)])
def test_gold_standard_reaches_the_ml_bound(n, trials):
    rng = np.random.default_rng(n)
    sq, expected, worse_than_8pt = [], [], 0
    for _ in range(trials):
        s = make_scene(n, 2, layout="general", noise_px=1.0, rng=rng)
        x1, x2, _ = s.pair(0, 1)
        F8 = fundamental_8point(x1, x2)
        r = fundamental_residual(fundamental_gold_standard(x1, x2, F0=F8).F, x1, x2)
        worse_than_8pt += r > fundamental_residual(F8, x1, x2)
        sq.append(r ** 2)
        expected.append((len(x1) - 7) / (4 * len(x1)))             # σ = 1
    ratio = np.sqrt(np.mean(sq) / np.mean(expected))
    assert abs(ratio - 1) < 0.03, ratio
    assert worse_than_8pt == 0


@pytest.mark.parametrize("n, trials", [(50, 30), (200, 8)])
def test_gold_standard_forward_motion(n, trials):
    """Epipole inside the image: GS below the true F's residual and below the 8-point's, every trial."""
    rng = np.random.default_rng(100 + n)
    for _ in range(trials):
        s = make_scene(n, 2, layout="forward", noise_px=1.0, rng=rng)
        x1, x2, _ = s.pair(0, 1)
        # we compare estimators on every scene, so the (tested above) near-degeneracy screen is off here
        F8 = fundamental_8point(x1, x2, degeneracy=None)
        r = fundamental_residual(fundamental_gold_standard(x1, x2, F0=F8).F, x1, x2)
        assert r <= fundamental_residual(F8, x1, x2)
        assert r <= fundamental_residual(truth(s)[2], x1, x2)


def test_epipole_search_finds_the_forward_basin():
    s = make_scene(60, 2, layout="forward", noise_px=0.0, rng=np.random.default_rng(3))
    x1, x2, _ = s.pair(0, 1, which="true")
    F_true = truth(s)[2]
    e_true = np.linalg.svd(F_true)[2][2]
    e_found = np.linalg.svd(epipole_search(x1, x2)[0])[2][2]
    T = hartley_normalisation(x1)                                  # compare the directions where they were searched
    a, b = T @ e_true, T @ e_found
    assert angle_between_deg(a, b) < 5 or angle_between_deg(a, -b) < 5


def test_homography_dlt_on_a_plane(rng):
    s = make_scene(30, 2, noise_px=0.0, planar=True, rng=rng)
    x1, x2, _ = s.pair(0, 1, which="true")
    H, d = homography_dlt(x1, x2)
    assert d.max() < 1e-8
    assert np.abs(dehomogeneous(homogeneous(x1) @ H.T) - x2).max() < 1e-8


# ---------------------------------------------------------------- noisy pose

def test_pose_error_scales_with_noise():
    """Pose error from the gold-standard F grows linearly with the pixel noise (ratio 4 for σ x4)."""
    errs = []
    for sigma in (0.25, 1.0):
        rng = np.random.default_rng(11)
        e = []
        for _ in range(12):
            s = make_scene(100, 2, noise_px=sigma, rng=rng)
            x1, x2, _ = s.pair(0, 1)
            R_true, t_true, _ = truth(s)
            E = essential_from_fundamental(fundamental_gold_standard(x1, x2).F, s.K, s.K)
            R, t = pose_from_essential(E, x1, x2, s.K, s.K)
            e.append(rotation_error_deg(R, R_true))
        errs.append(np.median(e))
    assert 2.5 < errs[1] / errs[0] < 6.0, errs


# ---------------------------------------------------------------- OpenCV as the reference

def test_opencv_agrees_noise_free(rng):
    cv2 = pytest.importorskip("cv2")
    s = make_scene(80, 2, noise_px=0.0, rng=rng)
    x1, x2, _ = s.pair(0, 1, which="true")
    F_cv, _ = cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)
    F = fundamental_8point(x1, x2)
    assert same_up_to_sign(F_cv, F) < 1e-6
    E = essential_from_fundamental(F, s.K, s.K)
    _, R_cv, t_cv, _ = cv2.recoverPose(E, x1, x2, s.K)
    R, t = pose_from_essential(E, x1, x2, s.K, s.K)
    assert rotation_error_deg(R, R_cv) < 1e-6 and angle_between_deg(t, t_cv.ravel()) < 1e-6


def test_opencv_agrees_on_dino(dino):
    cv2 = pytest.importorskip("cv2")
    for i, j in [(0, 1), (10, 11), (24, 25)]:
        x1, x2, _ = dino.pair(i, j, which="true")
        F_cv, _ = cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)
        F = fundamental_8point(x1, x2)
        assert same_up_to_sign(F_cv, F) < 1e-6
        E = essential_from_fundamental(F, dino.K, dino.K)
        _, R_cv, t_cv, _ = cv2.recoverPose(E, x1, x2, dino.K)
        R, t = pose_from_essential(E, x1, x2, dino.K, dino.K)
        assert rotation_error_deg(R, R_cv) < 1e-6 and angle_between_deg(t, t_cv.ravel()) < 1e-6


# ---------------------------------------------------------------- degenerate data, pure noise, chance (issue 21)

def pair_with_outliers(rng, n, sigma, ratio, layout="general"):
    """A pair of views with exactly ``ratio`` of the correspondences replaced by uniform pixels in view 2."""
    s = make_scene(n, 2, layout=layout, noise_px=sigma, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    x2 = x2.copy()
    bad = rng.choice(len(x1), int(round(ratio * len(x1))), replace=False)
    x2[bad] = rng.uniform([0, 0], s.image_size, (len(bad), 2))
    return s, x1, x2, bad


def test_coincident_pixels_and_no_motion_are_refused(rng):
    from labutils.sfm import two_view_reconstruction
    s = make_scene(40, 2, noise_px=0.5, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    with pytest.raises(ValueError, match="pixels x2 coincide"):
        fundamental_ransac(x1, np.tile(x2[:1], (40, 1)), rng=rng)
    with pytest.raises(ValueError, match="no motion"):
        fundamental_ransac(x1, x1 + rng.normal(scale=0.2, size=x1.shape), rng=rng)
    with pytest.raises(ValueError, match="no motion"):
        two_view_reconstruction(x1, x1, s.K, s.K, rng=rng)
    R, t, F = truth(s)
    with pytest.raises(ValueError, match="no parallax"):          # was a pose
        pose_from_essential(essential_from_fundamental(F, s.K, s.K), x1, x1, s.K, s.K)


def test_no_parallax_is_refused_through_outliers():
    """x2 = x1 + noise (no motion) or a pure rotation of ~2°, 0.5 px noise, 30 % outliers, N = 40: the F RANSAC
    finds (any F with an epipole fits no motion), then :func:`check_parallax`'s GRIC prefers the rotation, which
    leaves the noise, against F's over-fit: by about 0.39 N ≈ 16 (module text), several standard deviations of
    the difference (≈ √(2 N) ≈ 9 in σ² units, robustly capped). Measured: 11 of these 12 refused; asserted ≥ 9."""
    from labutils.sfm import two_view_reconstruction
    refused = 0
    for seed in range(6):
        rng = np.random.default_rng(seed)
        s = make_scene(40, 2, noise_px=0.5, rng=rng)
        x1 = s.x_meas[0]
        for still in (True, False):
            H = s.K @ rotation_from_angle_axis(rng.normal(size=3) * 0.03) @ np.linalg.inv(s.K)
            u = np.c_[x1, np.ones(40)] @ (np.eye(3) if still else H).T
            x2 = u[:, :2] / u[:, 2:] + rng.normal(scale=0.5, size=x1.shape)
            out = rng.random(40) < 0.3
            x2[out] = rng.uniform([0, 0], s.image_size, (out.sum(), 2))
            try:
                two_view_reconstruction(x1, x2, s.K, s.K, rng=rng, threshold_px=1.5, refine=False)
            except ValueError as exc:
                refused += "no parallax" in str(exc) or "cheirality" in str(exc)
    assert refused >= 9


@pytest.mark.parametrize("n", [40, 200])
def test_fundamental_ransac_refuses_pure_noise(n):
    """Unrelated pixels: the best of the F tried has the binomial tail of its extra inliers near 1 (measured on
    48 runs, N = 12-200, τ = 1-12 px: p_chance was 1 in every one), far above the 0.05 bar."""
    for seed, thr in enumerate((1.0, 4.0)):
        rng = np.random.default_rng(seed)
        x1, x2 = rng.uniform([0, 0], [720, 576], (2, n, 2))
        with pytest.raises(ValueError, match="no better than chance"):
            fundamental_ransac(x1, x2, rng=rng, threshold_px=thr, max_iter=300)


def test_valid_pairs_are_not_refused():
    """0.3-4 px noise, 0-50 % outliers, N = 40, threshold 3σ (at least 1 px): the F RANSAC with its chance test,
    and the parallax test on its inliers, refuse none (the cheirality step after them may still fail on a poor F).
    Theory, at the worst (4 px, 50 %): an unrelated pair, uniform in the boxes (~650 × 520 px), is within 12 px of
    an F with p ≈ 2 · 12 · 500 / 3.4e5 ≈ 0.035 (band of the mean chord), at most twice that for the Sampson
    distance (module text); 13 extra inliers of 33 have a tail ≈ C(33, 13) 0.07¹³ ≈ 1e-7, times ~2600 models:
    p_chance ≲ 3e-4, under 0.05."""
    for sigma in (0.3, 1.0, 4.0):
        for ratio in (0.0, 0.3, 0.5):
            for layout in ("general", "forward"):
                rng = np.random.default_rng(int(10 * sigma) + int(100 * ratio))
                s, x1, x2, bad = pair_with_outliers(rng, 40, sigma, ratio, layout)
                F, inl = fundamental_ransac(x1, x2, rng=rng, threshold_px=max(1.0, 3 * sigma))
                assert inl.sum() >= 0.8 * (len(x1) - len(bad))
                check_parallax(F, x1[inl], x2[inl], s.K, s.K)


def test_pure_rotation_and_the_parallax_test(rng):
    s = make_scene(60, 2, noise_px=0.5, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    R, t, F = truth(s)
    g_R, g_F = check_parallax(F, x1, x2, s.K, s.K)
    assert g_F < g_R
    R0 = rotation_from_angle_axis([0.02, -0.03, 0.01])
    u = np.c_[x1, np.ones(60)] @ (s.K @ R0 @ np.linalg.inv(s.K)).T
    R1, d = pure_rotation(x1, u[:, :2] / u[:, 2:], s.K, s.K)
    assert rotation_error_deg(R1, R0) < 1e-9 and d.max() < 1e-9


def test_fundamental_ransac_says_whether_it_reached_its_confidence():
    """Issue 21: the result unpacks as (F, inliers) and carries the search's converged flag and chance bound; a
    search cut off at max_iter says so instead of passing for a confident answer."""
    s = make_scene(80, 2, noise_px=0.5, outlier_ratio=0.2, rng=np.random.default_rng(3))
    x1, x2, _ = s.pair(0, 1)
    r = fundamental_ransac(x1, x2, threshold_px=1.5, rng=np.random.default_rng(0))
    F, inliers = r
    assert r.converged and r.p_chance < 1e-6 and F is r.F and inliers is r.inliers and r.n_iter >= 1
    cut = fundamental_ransac(x1, x2, threshold_px=1.5, rng=np.random.default_rng(0), max_iter=30)   # needs ~385
    assert not cut.converged and cut.n_iter == 30 and cut.p_chance < 1e-6
