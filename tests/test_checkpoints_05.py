"""Notebook 05's checkpoints can fail.

Each test runs a checkpoint's own code — the cells tagged ``checkpoint-<name>`` in the notebook, read from it, not a
copy — once with the library and once with a library function replaced by a plausible wrong one, on a small synthetic
turntable (12 views, so that each run takes a second or two). With the right function the checkpoint passes; with the
wrong one it raises ``AssertionError``.
"""
import functools
import os
from pathlib import Path

import numpy as np
import pytest
from _checkpoints import run_cells, tagged_cells

from labutils import make_scene
from labutils.sfm import noise_study as NS
from labutils.sfm.incremental import choose_initial_pair, incremental_sfm
from labutils.sfm.initial_pair import two_view_reconstruction
from labutils.sfm.reconstruction import Reconstruction
from labutils.twoview.triangulation import triangulate_multiview

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "05_incremental_sfm.ipynb"


tagged = functools.partial(tagged_cells, NOTEBOOK)
run = functools.partial(run_cells, NOTEBOOK)


def small_scene():
    # seed 3: the pair with the most points is not the pair with the largest points × angle (see the first test)
    return make_scene(200, 12, layout="turntable", noise_px=1.0, track_noise_px=0.3, track_outlier_ratio=0.05,
                      rng=np.random.default_rng(3))


@pytest.fixture
def ns(monkeypatch):
    """The notebook's setup cells, with a small synthetic scene in place of the dinosaur."""
    monkeypatch.setenv("LABUTILS_DATA", "none")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    setup = tagged("setup")
    ns = {}
    exec(setup[0], ns)
    scene = small_scene()
    ns.update(scene=scene, tracks=scene.tracks, K=scene.K, V=scene.n_views, T=scene.tracks.shape[1])
    for src in setup[1:]:
        exec(src, ns)
    ns["accept_points"] = ns["accept_points_reference"]      # the exercise's function: the reference body stands in
    return ns


def by_points_alone(tracks, K, *, rng, threshold_px):
    """A wrong initial pair: the candidate with the most accepted points, whatever its angle."""
    _, table = choose_initial_pair(tracks, K, rng=rng, threshold_px=threshold_px)
    row = max(table, key=lambda r: r["points"])
    a, b = row["i"], row["j"]
    idx = np.flatnonzero(np.isfinite(tracks[a, :, 0]) & np.isfinite(tracks[b, :, 0]))
    R, t, X, med = two_view_reconstruction(tracks[a, idx], tracks[b, idx], K, K, rng=rng, threshold_px=threshold_px)
    ok = np.isfinite(X[:, 0])
    return dict(i=a, j=b, R=R, t=t, track=idx[ok], X=X[ok], median_angle=med), table


def test_initial_pair_checkpoint(ns):
    run("checkpoint-initial-pair", dict(ns))
    ns["choose_initial_pair"] = by_points_alone
    with pytest.raises(AssertionError):
        run("checkpoint-initial-pair", ns)


def with_initial_pair(ns):
    run("checkpoint-initial-pair", ns)
    return ns


def test_next_view_checkpoint(ns):
    with_initial_pair(ns)
    run("checkpoint-next-view", dict(ns))

    def keeps_registered(counts, registered, skip=()):
        """A wrong next view: the view that sees the most points, registered or not."""
        return int(np.argmax(counts))
    ns["next_view"] = keeps_registered
    with pytest.raises(AssertionError):
        run("checkpoint-next-view", ns)


def no_filter(tracks, K, R, t, views, mask, *, threshold_px, min_angle_deg):
    """A wrong triangulation: DLT from every observation, every point accepted."""
    use = np.zeros(mask.shape, bool)
    use[views] = mask[views]
    Ps = np.einsum("vij,vjk->vik", K, np.concatenate([np.nan_to_num(R), np.nan_to_num(t)[:, :, None]], axis=2))
    X = triangulate_multiview(Ps[views], np.where(use[views, :, None], tracks[views], np.nan))
    use[:, ~np.isfinite(X[:, 0])] = False
    return X, use


def test_new_points_checkpoint(ns):
    with_initial_pair(ns)
    run("checkpoint-next-view", ns)
    run("checkpoint-new-points", dict(ns))
    ns["triangulate_tracks"] = no_filter
    with pytest.raises(AssertionError):
        run("checkpoint-new-points", ns)


def without_bundle_adjustment(tracks, K, *, rng, threshold_px):
    """A wrong pipeline: the same steps (pair, PnP, triangulation, in the same order) without any bundle adjustment."""
    order = incremental_sfm(tracks, K, rng=rng, threshold_px=threshold_px).order
    R, t, X = NS.reconstruct_without_ba(tracks, K, order, rng=rng, threshold_px=threshold_px)
    reg = np.isfinite(t[:, 0])
    inliers = np.isfinite(tracks[..., 0]) & reg[:, None] & np.isfinite(X[:, 0])[None]
    return Reconstruction(R=R, t=t, registered=reg, X=X, inliers=inliers, order=order,
                          K=np.repeat(np.asarray(K)[None], len(R), axis=0), timings={"total": 0.0}, log=[])


def test_optimum_checkpoint(ns):
    run("checkpoint-optimum", dict(ns))
    ns["incremental_sfm"] = without_bundle_adjustment
    with pytest.raises(AssertionError):
        run("checkpoint-optimum", ns)
