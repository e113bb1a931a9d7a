"""labutils.match and python -m labutils.match: shapes and bad input, invariants, recovery on rendered images with
exact correspondences, OpenCV as the reference, the real data, and the command line."""
import os
import stat
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from labutils import match as ft
from labutils.core.geometry import relative_pose
from labutils.core.metrics import rotation_error_deg
from labutils.core.synthetic import make_scene
from labutils.data.formats import read_tracks
from labutils.match.synthetic import render_corner
from labutils.sfm.incremental import bundle_from_cameras, incremental_sfm
from labutils.twoview.epipolar import sampson_distance
from labutils.twoview.essential import fundamental_from_pose

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def corner():
    """Six views of the textured corner (320×240), their features and verified matches of all pairs."""
    s = render_corner(6, (320, 240), rng=np.random.default_rng(0), arc_deg=40)
    f = [ft.detect_features(im) for im in s.images]
    res = ft.match_views(f, ft.select_pairs(6), rng=np.random.default_rng(1), K=s.K)
    return s, f, res


def _true_error(s, f, i, j, m):
    """Distance in view j between the matched keypoint and the true position of the keypoint of view i."""
    return np.linalg.norm(s.transfer(i, j, f[i].xy[m[:, 0]]) - f[j].xy[m[:, 1]], axis=1)


# --- shapes and bad input -------------------------------------------------------------------------------------


def test_nearest_neighbours_bad_input():
    with pytest.raises(ValueError, match="same descriptor length"):
        ft.nearest_neighbours(np.zeros((3, 4)), np.zeros((3, 5)))
    with pytest.raises(ValueError, match="non-finite"):
        ft.nearest_neighbours(np.full((2, 4), np.nan), np.zeros((3, 4)))
    with pytest.raises(ValueError, match="k must be 1 or 2"):
        ft.nearest_neighbours(np.zeros((2, 4)), np.zeros((3, 4)), k=3)
    with pytest.raises(ValueError, match=r"d1 must have shape \(N, D\)"):
        ft.nearest_neighbours(np.zeros(4), np.zeros((3, 4)))
    idx, dist = ft.nearest_neighbours(np.zeros((2, 4)), np.zeros((1, 4)))       # no second neighbour
    assert idx.tolist() == [[0, -1], [0, -1]] and np.isinf(dist[:, 1]).all()
    idx, dist = ft.nearest_neighbours(np.zeros((0, 4)), np.zeros((3, 4)))
    assert idx.shape == (0, 2) and dist.shape == (0, 2)


def test_ratio_and_mutual_bad_input():
    with pytest.raises(ValueError, match=r"dist must have shape \(N, 2\)"):
        ft.ratio_test(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no NaN"):
        ft.ratio_test([[np.nan, 1.0]])
    with pytest.raises(ValueError, match="ratio must be in"):
        ft.ratio_test([[1.0, 2.0]], ratio=1.5)
    with pytest.raises(ValueError, match="below -1"):
        ft.mutual_check([0, -2], [0])
    with pytest.raises(ValueError, match="m12 points to feature 5"):
        ft.mutual_check([5], [0])
    with pytest.raises(ValueError, match="1-D integer array"):
        ft.mutual_check([0.5], [0])
    assert ft.mutual_check([-1, -1], [-1]).shape == (0, 2)


def test_build_tracks_bad_input():
    with pytest.raises(ValueError, match=r"pair \(1, 1\) is not two different views"):
        ft.build_tracks({(1, 1): np.array([[0, 0]])}, [2, 2])
    with pytest.raises(ValueError, match="index features outside"):
        ft.build_tracks({(0, 1): np.array([[0, 2]])}, [2, 2])
    with pytest.raises(ValueError, match=r"\(M, 2\) integer array"):
        ft.build_tracks({(0, 1): np.array([[0.0, 1.0]])}, [2, 2])
    with pytest.raises(ValueError, match="pairs of view indices"):
        ft.build_tracks({"ab": np.array([[0, 1]])}, [2, 2])
    assert ft.build_tracks({}, [3, 4]).shape == (2, 0)


def test_images_pairs_and_thresholds_bad_input():
    """What the API sweep (test_api_sweep) cannot reach: a float image, a view index that is not an integer, and
    verify_tracks' own threshold."""
    with pytest.raises(ValueError, match="image must be uint8"):         # cast to uint8, [0, 1] would be black
        ft.detect_features(np.random.default_rng(0).uniform(size=(32, 32)))
    f = [ft.Features(np.zeros((0, 2)), np.zeros((0, 8), np.float32))] * 3
    with pytest.raises(ValueError, match=r"row 1 is \[1.0, 1.5\]"):
        ft.match_views(f, [[0, 1], [1, 1.5]], rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"row 0 is \[2.0, 2.0\]"):
        ft.match_views(f, [[2, 2]], rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match="threshold_px must be a positive number"):
        ft.verify_tracks(np.zeros((2, 1, 2)), {}, 0.0)


def test_rng_checks_name_what_they_got():
    """One check (_validation.as_rng) for every function of the matching chapter that draws random numbers."""
    from labutils.match.synthetic import blob_texture

    f = [ft.Features(np.zeros((0, 2)), np.zeros((0, 8), np.float32))] * 2
    calls = [lambda r: ft.match_views(f, [[0, 1]], rng=r), lambda r: blob_texture(16, rng=r),
             lambda r: render_corner(2, rng=r), lambda r: ft.retrieval_pairs([np.zeros((4, 8))] * 2, 1, rng=r)]
    for call in calls:
        with pytest.raises(ValueError, match=r"rng must be a numpy.random.Generator, .*; got 0"):
            call(0)


def test_select_pairs():
    assert len(ft.select_pairs(36)) == 630
    assert len(ft.select_pairs(36, "ring", 2)) == 72 and len(ft.select_pairs(36, "sequence", 2)) == 69
    p = ft.select_pairs(10, "sequence", 3)
    assert (p[:, 0] < p[:, 1]).all() and (p[:, 1] - p[:, 0] <= 3).all() and len(p) == 9 + 8 + 7
    for kwargs, words in [(dict(n_views=1), "n_views must be an integer >= 2"),
                          (dict(n_views=5, strategy="ring"), "needs a window"),
                          (dict(n_views=5, strategy="sequence", window=1.5), "window must be an integer >= 1; got 1.5"),
                          (dict(n_views=5, strategy="ring", window=0), "window must be an integer >= 1"),
                          (dict(n_views=4.5), "n_views must be an integer"),
                          (dict(n_views=5, strategy="random"), "'all', 'sequence' or 'ring'")]:
        with pytest.raises(ValueError, match=words):
            ft.select_pairs(**kwargs)


def test_epipolar_filter_bad_input(rng):
    s = make_scene(30, 2, noise_px=0.5, rng=rng)
    x1, x2, _ = s.pair(0, 1)
    with pytest.raises(ValueError, match="both K1 and K2"):
        ft.epipolar_filter(x1, x2, rng=rng, K1=s.K)
    with pytest.raises(ValueError, match="at least 8"):
        ft.epipolar_filter(x1[:7], x2[:7], rng=rng)
    with pytest.raises(ValueError, match="threshold_px must be positive"):
        ft.epipolar_filter(x1, x2, rng=rng, threshold_px=0)
    with pytest.raises(ValueError, match="rng must be"):
        ft.epipolar_filter(x1, x2, rng=None)
    with pytest.raises(ValueError, match="ranking must have one value per match"):
        ft.epipolar_filter(np.tile(x1, (3, 1)), np.tile(x2, (3, 1)), rng=rng, ranking=np.zeros(5))
    with pytest.raises(ValueError, match=r"ranking must have one value per match \(30\); got shape \(5,\)"):
        ft.epipolar_filter(x1, x2, rng=rng, ranking=np.zeros(5))        # N < 40: once not checked at all
    with pytest.raises(ValueError, match=r"ranking must have one value per match \(30\); got shape \(30, 1\)"):
        ft.epipolar_filter(x1, x2, rng=rng, ranking=np.zeros((30, 1)))  # no silent reshape


def test_match_views_refuses_arrays_for_features():
    f = ft.Features(np.zeros((0, 2)), np.zeros((0, 8), np.float32))
    with pytest.raises(ValueError, match=r"features must be a sequence of Features .*features\[1\] is a ndarray"):
        ft.match_views([f, np.zeros((5, 8))], [[0, 1]], rng=np.random.default_rng(0))   # was an AttributeError
    with pytest.raises(ValueError, match="features must be a sequence of Features .*got a Features"):
        ft.match_views(f, [[0, 1]], rng=np.random.default_rng(0))
    res = ft.match_views([f, f], [[0, 1]], rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"features\[0\] is a ndarray"):
        ft.tracks_from_matches([np.zeros((0, 2))] * 2, res)


def test_pixel_scaling_round_trip_and_bad_input():
    x = np.array([[0.0, 0.0], [319.0, 239.0], [np.nan, np.nan]])
    for s in (0.25, 1 / 3, 0.5, 2.0):
        back = ft.to_original_pixels(ft.to_working_pixels(x, s), s)
        assert np.allclose(back[:2], x[:2]) and np.isnan(back[2]).all()
    # the corner of the image stays the corner: pixel (-0.5, -0.5) is the outer edge in both
    assert np.allclose(ft.to_working_pixels([[-0.5, -0.5]], 0.3), -0.5)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 2\)"):
        ft.to_original_pixels(np.zeros((3, 3)), 0.5)
    with pytest.raises(ValueError, match="scale must be a positive number"):
        ft.scale_calibration(np.eye(3), 0.0)
    for bad in (0.0, -1.0, np.nan, np.inf, "0.5", None):   # 0 gave inf pixels, -1 plausible wrong ones
        for fn in (ft.to_original_pixels, ft.to_working_pixels):
            with pytest.raises(ValueError, match="scale must be a positive number"):
                fn(x, bad)
    with pytest.raises(ValueError, match="scale must be a positive number"):   # was a TypeError
        ft.scale_calibration(np.eye(3), "0.5")


def test_read_gray_errors_name_the_file(tmp_path):
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(ValueError, match="broken.png: cannot read the image"):
        ft.read_gray(bad)
    jpg = tmp_path / "broken.jpg"
    jpg.write_bytes(b"\xff\xd8 not really")
    with pytest.raises(ValueError, match="broken.jpg: cannot read the image"):
        ft.read_gray(jpg, max_size=100)


# --- invariants -----------------------------------------------------------------------------------------------


def test_nearest_neighbours_is_brute_force(rng):
    import scipy.spatial

    d1, d2 = rng.random((300, 32)).astype(np.float32), rng.random((250, 32)).astype(np.float32)
    idx, dist = ft.nearest_neighbours(d1, d2, chunk=64)                       # several chunks
    D = scipy.spatial.distance.cdist(d1, d2)
    order = np.argsort(D, axis=1)[:, :2]
    assert np.array_equal(idx, order)
    assert np.allclose(dist, np.take_along_axis(D, order, 1), atol=1e-4)


def test_mutual_check_is_symmetric(rng):
    m12, m21 = rng.integers(-1, 50, 60), rng.integers(-1, 60, 50)
    m12[:20] = rng.permutation(50)[:20]
    m21[m12[:20]] = np.arange(20)
    a = ft.mutual_check(m12, m21)
    b = ft.mutual_check(m21, m12)
    assert len(a) >= 20 and {tuple(r) for r in a.tolist()} == {tuple(r) for r in b[:, ::-1].tolist()}


def test_ratio_test_is_monotone(rng):
    dist = np.sort(rng.random((500, 2)), axis=1)
    prev = np.zeros(500, bool)
    for r in (0.3, 0.5, 0.7, 0.9, 1.0):
        keep = ft.ratio_test(dist, r)
        assert (keep | ~prev).all()            # a stricter ratio keeps a subset
        prev = keep


def test_build_tracks_invariants(rng):
    V, n = 6, 80
    ids = [rng.permutation(n) for _ in range(V)]
    seen = rng.random((V, n)) < 0.7
    pm = {}
    for i in range(V):
        for j in range(i + 1, V):
            both = np.flatnonzero(seen[i] & seen[j] & (rng.random(n) < 0.6))
            pm[(i, j)] = np.column_stack([ids[i][both], ids[j][both]])
    pm[(0, 1)] = np.vstack([pm[(0, 1)], [[ids[0][0], ids[1][1]]]])          # one wrong match makes a conflict?
    tracks, n_conf = ft.build_tracks(pm, [n] * V, return_conflicts=True)
    seen_t = tracks >= 0
    assert (seen_t.sum(0) >= 2).all()
    for v in range(V):                                                      # no feature in two tracks
        f = tracks[v][seen_t[v]]
        assert len(np.unique(f)) == len(f)
    # every match lies within one track, unless its track was rejected as a conflict
    where = {(v, int(a)): k for v in range(V) for k, a in enumerate(tracks[v]) if a >= 0}
    missing = 0
    for (i, j), m in pm.items():
        for a, b in m:
            ka, kb = where.get((i, int(a))), where.get((j, int(b)))
            assert ka == kb
            missing += ka is None
    assert (missing > 0) == (n_conf > 0)
    # the order of the pairs does not matter
    shuffled = dict(reversed(list(pm.items())))
    t2 = ft.build_tracks(shuffled, [n] * V)
    assert {tuple(c) for c in t2.T.tolist()} == {tuple(c) for c in tracks.T.tolist()}


def test_track_pixels_statistics_and_verify_bad_input():
    xy = [np.zeros((3, 2)), np.zeros((2, 2))]
    with pytest.raises(ValueError, match=r"tracks\[1\] holds feature index 2, but xy\[1\] has only 2"):
        ft.track_pixels([[0, 1], [1, 2]], xy)                   # was a bare IndexError
    with pytest.raises(ValueError, match="integer feature indices"):
        ft.track_pixels([[0, 1], [1, 0.5]], xy)
    with pytest.raises(ValueError, match=r"xy\[0\] must have shape \(N, 2\)"):
        ft.track_pixels([[0, 1], [1, 0]], [np.zeros((3, 3)), np.zeros((2, 2))])
    with pytest.raises(ValueError, match=r"geometry keys must be pairs of views .* 0 <= i, j < 2"):
        ft.verify_tracks(np.zeros((2, 1, 2)), {(0, 2): np.eye(3)}, 1.0)   # was a bare IndexError
    with pytest.raises(ValueError, match="geometry keys"):
        ft.verify_tracks(np.zeros((2, 1, 2)), {(-1, 1): np.eye(3)}, 1.0)  # -1 would silently be the last view
    x = np.full((3, 5, 2), 1.0)
    with pytest.raises(ValueError, match=r"x must have shape \(V, T, 2\)"):
        ft.track_statistics(x.transpose(0, 2, 1))               # (V, 2, T): once 2 tracks of length 3
    empty = ft.track_statistics(np.zeros((3, 0, 2)))            # the CLI's case: no track survived
    assert empty["tracks"] == 0 and empty["mean_length"] == 0.0 and empty["length_counts"].tolist() == [0] * 4


def test_union_find_labels():
    uf = ft.UnionFind(6)
    for a, b in [(5, 4), (4, 0), (2, 3)]:
        uf.union(a, b)
    assert uf.labels().tolist() == [0, 1, 2, 2, 0, 0]


def test_verify_tracks_rejects_a_transitive_mismatch(rng):
    s = make_scene(40, 3, noise_px=0.0, rng=rng)
    x = s.x_true.copy()
    x[2, 5] = x[2, 6]                           # track 5: a wrong observation in view 2, reached through view 1
    F = {(i, j): fundamental_from_pose(s.K, s.K, *relative_pose(s.R[i], s.t[i], s.R[j], s.t[j]))
         for i, j in [(0, 1), (1, 2), (0, 2)]}
    keep = ft.verify_tracks(x, F, 1.0)
    assert not keep[5] and keep.sum() >= 38
    assert ft.verify_tracks(x, {(0, 1): F[(0, 1)]}, 1.0).all()     # no F for (., 2): nothing to check it against


# --- recovery on rendered images ------------------------------------------------------------------------------


def test_matches_on_rendered_images_are_correct(corner):
    """Every stage removes wrong matches; the survivors lie where the geometry puts them.

    SIFT localises a blob to about 0.2-0.3 px here (the RMS transfer error of the verified matches), so a
    correct match is within 1.5 px (> 5σ) of its true position; a wrong one is almost always far off.
    """
    s, f, res = corner
    n_wrong_mutual = n_mutual = n_wrong = n_kept = 0
    for (i, j), m in res.matches.items():
        raw = ft.match_descriptors(f[i].descriptors, f[j].descriptors).matches
        e_raw = _true_error(s, f, i, j, raw)
        e = _true_error(s, f, i, j, m)
        n_mutual, n_wrong_mutual = n_mutual + len(raw), n_wrong_mutual + int((~(e_raw < 1.5)).sum())
        n_kept, n_wrong = n_kept + len(m), n_wrong + int((~(e < 1.5)).sum())
    assert len(res.matches) >= 14 and n_kept > 3000            # the pair 40° apart may have too few
    assert n_wrong / n_kept < 0.02 < n_wrong_mutual / n_mutual     # the epipolar filter removes most wrong ones
    assert n_wrong < 0.5 * n_wrong_mutual
    t = res.totals()
    assert t["ratio"] >= t["mutual"] >= t["epipolar"] == n_kept


def test_epipolar_filter_recovers_inliers_and_rejects_points_behind(rng):
    s = make_scene(120, 2, noise_px=0.3, outlier_ratio=0.2, layout="forward", rng=rng)
    x1, x2, idx = s.pair(0, 1)
    correct = ~(s.outliers[0, idx] | s.outliers[1, idx])
    g = ft.epipolar_filter(x1, x2, rng=np.random.default_rng(0), threshold_px=1.5)
    # a wrong match passes only when it happens to fall near its epipolar line: within ±1.5 px of a line
    # crossing a 720-px image, about 2 % of them (0.02 × 40 ≈ 1 expected)
    assert (g.inliers & correct).sum() == correct.sum() and (g.inliers & ~correct).sum() <= 3
    # Wrong matches on the right epipolar line but across the epipole (forward motion puts it near the image):
    # x2ᵀ F x1 = 0 holds, but the two rays meet behind the cameras. No F can tell; E (with K) can. We build them
    # on the epipolar lines of the F estimated from the correct matches, 3 of ~80 (a few per cent, as in real data).
    F = ft.epipolar_filter(x1[correct], x2[correct], rng=np.random.default_rng(0), threshold_px=1.5).F
    e2 = np.linalg.svd(F.T)[2][-1]
    e2 = e2[:2] / e2[2]
    k = np.flatnonzero(correct)[np.argsort(np.linalg.norm(x2[correct] - e2, axis=1))][:3]
    xb = e2 - 0.5 * (x2[k] - e2)                      # across the epipole ...
    line = np.hstack([x1[k], np.ones((3, 1))]) @ F.T  # ... then onto the epipolar line of x1
    xb -= (np.sum(line[:, :2] * xb, 1) + line[:, 2])[:, None] * line[:, :2] / np.sum(line[:, :2] ** 2, 1)[:, None]
    X1, X2 = np.vstack([x1[correct], x1[k]]), np.vstack([x2[correct], xb])
    g_F = ft.epipolar_filter(X1, X2, rng=np.random.default_rng(0), threshold_px=1.5)
    g_E = ft.epipolar_filter(X1, X2, rng=np.random.default_rng(0), threshold_px=1.5, K1=s.K, K2=s.K)
    behind = np.arange(len(X1)) >= correct.sum()
    assert g_F.inliers[behind].all()
    assert not g_E.inliers[behind].any() and g_E.inliers[~behind].all() and g_E.n_behind == behind.sum()
    R_true, _ = relative_pose(s.R[0], s.t[0], s.R[1], s.t[1])
    assert g_E.pose_reliable and rotation_error_deg(g_E.R, R_true) < 0.5


def test_guided_sampling_finds_the_same_inliers(rng):
    """Half the matches wrong; ranked like the ratio test ranks them (correct ones mostly lower). With 60 samples
    plain RANSAC has a 1 - (1 - 0.5⁷)⁶⁰ ≈ 37 % chance of drawing one clean sample; among the best third
    almost every match is correct, so the guided run finds the model."""
    s = make_scene(300, 2, noise_px=0.3, outlier_ratio=0.3, rng=rng)
    x1, x2, idx = s.pair(0, 1)
    correct = ~(s.outliers[0, idx] | s.outliers[1, idx])
    ranking = np.where(correct, rng.uniform(0.0, 0.7, len(x1)), rng.uniform(0.45, 1.0, len(x1)))
    g = ft.epipolar_filter(x1, x2, rng=np.random.default_rng(0), threshold_px=1.5, ranking=ranking, max_iter=60)
    assert (g.inliers & correct).sum() == correct.sum() and (g.inliers & ~correct).sum() <= 0.05 * (~correct).sum()


def test_tracks_and_sfm_on_rendered_images(corner):
    """All six views register; the cameras are as good as bundle adjustment started from the truth.

    The bar is the pipeline's own optimum on these tracks, not zero: SIFT keypoints on slanted planes are
    biased by the perspective distortion of each blob, so even BA from the true cameras lands ~0.1° away.
    """
    s, f, res = corner
    tr = ft.tracks_from_matches(f, res)
    stats = ft.track_statistics(tr.x)
    assert stats["tracks"] > 800 and stats["max_length"] == 6 and tr.n_conflicts < 0.05 * stats["tracks"]
    rec = incremental_sfm(tr.x, s.K, rng=np.random.default_rng(0))
    assert rec.registered.all()
    ref = bundle_from_cameras(tr.x, s.K, s.R, s.t)
    rel = np.array([rotation_error_deg(rec.R[v] @ rec.R[0].T, s.R[v] @ s.R[0].T) for v in range(1, 6)])
    rel_ref = np.array([rotation_error_deg(ref.R[v] @ ref.R[0].T, s.R[v] @ s.R[0].T) for v in range(1, 6)])
    gap = np.array([rotation_error_deg(rec.R[v] @ rec.R[0].T, ref.R[v] @ ref.R[0].T) for v in range(1, 6)])
    assert rel.max() < 0.3 and gap.max() < 0.1 * max(rel_ref.max(), 0.05)


def test_retrieval_pairs_find_neighbours():
    """Eight 'places' on a ring; image v sees places v and v+1: neighbours share words, others none."""
    rng = np.random.default_rng(3)
    V, per = 8, 150
    centres = rng.normal(0, 1, (V, 40, 16)) * 10                   # 40 words per place
    D = []
    for v in range(V):
        w = np.concatenate([centres[v], centres[(v + 1) % V]])
        D.append((w[rng.integers(0, len(w), per)] + rng.normal(0, 0.3, (per, 16))).astype(np.float32))
    pairs, S = ft.retrieval_pairs(D, 2, rng=np.random.default_rng(0), vocabulary_size=256, sample=2000)
    ring = {tuple(sorted((v, (v + 1) % V))) for v in range(V)}
    assert ring <= {tuple(p) for p in pairs.tolist()}
    assert np.allclose(np.diag(S), 1.0) and S.shape == (V, V)
    for kwargs, words in [(dict(n_neighbours=0), "n_neighbours must be an integer >= 1; got 0"),
                          (dict(n_neighbours=-1), "n_neighbours must be an integer >= 1"),  # once almost all pairs
                          (dict(n_neighbours=1.5), "n_neighbours must be an integer"),
                          (dict(n_neighbours=2, vocabulary_size=0), "vocabulary_size must be an integer >= 1"),
                          (dict(n_neighbours=2, sample=100), "sample must be >= vocabulary_size = 256"),
                          (dict(n_neighbours=2, sample=0), "sample must be an integer >= 1")]:
        with pytest.raises(ValueError, match=words):
            ft.retrieval_pairs(D, rng=np.random.default_rng(0), **kwargs)


def test_retrieval_similarity_of_an_image_with_only_common_words():
    """An image whose words all appear in every image has idf 0 everywhere: a zero row, also on the diagonal."""
    rng = np.random.default_rng(0)
    common, own1, own2 = (rng.normal(0, 1, (1, 8)) * 100 for _ in range(3))
    blob = lambda c, n: (c + rng.normal(0, 0.1, (n, 8))).astype(np.float32)  # noqa: E731
    D = [blob(common, 30), np.vstack([blob(common, 30), blob(own1, 30)]), np.vstack([blob(common, 30), blob(own2, 30)])]
    _, S = ft.retrieval_pairs(D, 1, rng=np.random.default_rng(0), vocabulary_size=3, sample=200)
    assert np.all(S[0] == 0) and np.all(S[:, 0] == 0) and np.allclose(S[1, 1], 1.0) and np.allclose(S[2, 2], 1.0)


# --- OpenCV as the reference ----------------------------------------------------------------------------------


def test_matching_agrees_with_opencv(corner):
    _, f, _ = corner
    d1, d2 = f[0].descriptors, f[1].descriptors
    idx, dist = ft.nearest_neighbours(d1, d2)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d1, d2, k=2)
    cv_idx = np.array([[a.trainIdx, b.trainIdx] for a, b in knn])
    cv_dist = np.array([[a.distance, b.distance] for a, b in knn])
    same = (idx == cv_idx).all(1)
    assert same.mean() > 0.995                                    # ties in float32 may order differently
    assert np.allclose(dist[same], cv_dist[same], rtol=1e-4, atol=1e-2)
    ours = ft.match_descriptors(d1, d2, ratio=None, cross_check=True).matches
    cross = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(d1, d2)
    theirs = {(m.queryIdx, m.trainIdx) for m in cross}
    assert len({tuple(r) for r in ours.tolist()} ^ theirs) <= 0.005 * len(theirs)


def test_epipolar_filter_agrees_with_opencv(corner):
    s, f, _ = corner
    m = ft.match_descriptors(f[1].descriptors, f[2].descriptors).matches
    x1, x2 = f[1].xy[m[:, 0]], f[2].xy[m[:, 1]]
    g = ft.epipolar_filter(x1, x2, rng=np.random.default_rng(0), threshold_px=1.0)
    _, mask = cv2.findFundamentalMat(x1, x2, cv2.FM_RANSAC, 1.0, 0.999)
    cv_inl = mask.ravel() > 0
    assert (g.inliers != cv_inl).sum() <= 0.03 * len(m)


def test_sift_precise_upscale_removes_the_quarter_pixel():
    """A Gaussian blob drawn at a known position: OpenCV's default SIFT reports it a quarter pixel off."""
    yy, xx = np.mgrid[0:160, 0:160].astype(float)
    x0, y0 = 80.3, 77.6
    img = (60 + 160 * np.exp(-((xx - x0) ** 2 + (yy - y0) ** 2) / (2 * 3.0 ** 2))).astype(np.uint8)
    for precise, offset in ((True, 0.0), (False, 0.25)):
        xy = ft.detect_features(img, precise_upscale=precise, contrast_threshold=0.01).xy
        near = xy[np.argmin(np.linalg.norm(xy - [x0, y0], axis=1))]
        assert np.allclose(near - [x0, y0], offset, atol=0.05)


# --- real data ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("i, j", [(24, 25), (32, 34)])
def test_dino_pair_matches_agree_with_the_cameras(dino, i, j):
    """Dinosaur pairs: the verified matches lie on the epipolar lines of the given cameras, and none that does is lost.

    (32, 34) is 20° apart and nearly affine: E from the RANSAC F is ~12° off there, and refined from it alone the
    pose lands where every point is behind the cameras; the filter must not reject the matches for that.
    """
    if not dino.image_paths:
        pytest.skip("the dinosaur's images are missing")
    f = [ft.detect_features(dino.image(k)) for k in (i, j)]
    dm = ft.match_descriptors(f[0].descriptors, f[1].descriptors)
    m = dm.matches
    x1, x2 = f[0].xy[m[:, 0]], f[1].xy[m[:, 1]]
    g = ft.epipolar_filter(x1, x2, rng=np.random.default_rng(0), K1=dino.K, K2=dino.K, ranking=dm.distance_ratio)
    F_true = fundamental_from_pose(dino.K, dino.K, *relative_pose(dino.R[i], dino.t[i], dino.R[j], dino.t[j]))
    d = sampson_distance(F_true, x1, x2)
    # the provided tracks reproject with a median of 0.2 px (data README): ours must be as consistent
    assert g.inliers.sum() > 100 and np.median(d[g.inliers]) < 0.3 and np.mean(d[g.inliers] > 2.0) < 0.01
    assert g.inliers.sum() >= 0.95 * (d < 1.0).sum()


# --- the command line -----------------------------------------------------------------------------------------


def _cli(*args, cwd):
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "labutils.match", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, env=env)


@pytest.fixture(scope="module")
def image_dir(tmp_path_factory):
    """Five rendered 400×300 views as PNG files (and one JPEG), with K."""
    d = tmp_path_factory.mktemp("images")
    s = render_corner(5, (400, 300), rng=np.random.default_rng(5), arc_deg=32)
    for v, im in enumerate(s.images):
        cv2.imwrite(str(d / (f"view{v}.jpg" if v == 4 else f"view{v}.png")), im,
                    [cv2.IMWRITE_JPEG_QUALITY, 100])
    (d / "notes.txt").write_text("not an image\n")
    np.savetxt(d / "K.txt", s.K)
    return d, s


def test_cli_writes_tracks_in_original_pixels(image_dir, tmp_path):
    d, s = image_dir
    out = tmp_path / "tracks.txt"
    r = _cli(d, d / "K.txt", "--out", out, "--max-size", 300, "--seed", 2, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"wrote {out}") and "matching" in r.stderr and "tracks:" in r.stderr
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~_umask()
    x = read_tracks(out)
    assert x.shape[0] == 5 and x.shape[1] > 300
    # the tracks are in the pixels of the 400×300 originals (found at 300×225): check them against the truth
    seen = np.isfinite(x[..., 0])
    errs = []
    for k in np.flatnonzero(seen.sum(0) >= 2)[:300]:
        v = np.flatnonzero(seen[:, k])
        errs.append(np.linalg.norm(s.transfer(v[0], v[1], x[v[0], k][None]) - x[v[1], k]))
    errs = np.array(errs)
    assert np.nanmedian(errs) < 0.6 and np.mean(errs < 2.0) > 0.95
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tracks.txt"]       # no temporary file left


def _umask():
    u = os.umask(0)
    os.umask(u)
    return u


def test_cli_help():
    r = subprocess.run([sys.executable, "-m", "labutils.match", "--help"], capture_output=True, text=True,
                       env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0 and "IMAGE_DIR" in r.stdout.upper() and "--max-size" in r.stdout


@pytest.mark.parametrize("setup, message", [
    ("unreadable", r"broken\.png: cannot read the image"),
    ("one_image", r"1 image \(PNG, JPEG\); at least 2 are needed"),
    ("K_rows", r"K\.txt: 6 rows; expected 3 .* or 9 .* for the 3 images in"),
    ("K_text", r"K\.txt, line 2, column 1: 'x' is not a number"),
    ("no_folder", r"out/tracks\.txt: the folder out does not exist"),
    ("no_images_dir", r"nowhere: not a folder"),
])
def test_cli_rejects_bad_input(image_dir, tmp_path, setup, message):
    d, s = image_dir
    imgs = tmp_path / "imgs"
    imgs.mkdir()
    for v in range(3 if setup != "one_image" else 1):
        (imgs / f"v{v}.png").symlink_to(d / f"view{v}.png")
    K = tmp_path / "K.txt"
    K.write_text("100 0 50\n0 100 50\n0 0 1\n")
    out = "tracks.txt"
    folder = imgs
    if setup == "unreadable":
        (imgs / "broken.png").write_bytes(b"\x89PNG garbage")
    elif setup == "K_rows":
        K.write_text("100 0 50\n0 100 50\n0 0 1\n" * 2)
    elif setup == "K_text":
        K.write_text("100 0 50\nx 100 50\n0 0 1\n")
    elif setup == "no_folder":
        out = "out/tracks.txt"
    elif setup == "no_images_dir":
        folder = "nowhere"
    before = sorted(p.name for p in tmp_path.iterdir())
    r = _cli(folder, K, "--out", out, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in r.stderr, r.stderr
    assert pytest.importorskip("re").search(message, lines[0]), lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before                 # nothing written


def test_cli_write_failure_leaves_nothing(image_dir, tmp_path, monkeypatch, capsys):
    """A full disk while writing: one error line, status 2, and the temporary file is gone."""
    import labutils.match.cli as cli
    from labutils.core import cli as _cli

    d, _ = image_dir

    def full_disk(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    status = _cli.run(cli.main, [str(d), str(d / "K.txt"), "--out", str(tmp_path / "tracks.txt"), "--max-size",
                                 "200", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "No space left on device" in err[0] and "tracks.txt" in err[0]
    assert list(tmp_path.iterdir()) == []
