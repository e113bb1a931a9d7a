"""The noise study of the whole reconstruction (notebook 06): run a pipeline on noisy copies of a scene many times
and measure its pose errors after the similarity alignment, to compare with :mod:`labutils.bundle.uncertainty`.

:func:`run_noise_study` runs any pipeline (the incremental SfM, bundle adjustment from the truth, ...) on noisy
observations and collects the errors in a :class:`NoiseStudy`; the helpers build the pipelines' pieces
(:func:`ba_from_truth`, :func:`reconstruct_without_ba`, :func:`refine_reconstruction`).
"""
import time
from dataclasses import dataclass

import numpy as np

from ...bundle.adjust import bundle_adjust
from ...core.metrics import pose_errors
from ...core.scene import observations
from ...core.validation import (
    as_array,
    as_calibration,
    as_count,
    as_fraction,
    as_indices,
    as_positive,
    as_rng,
    as_tracks,
)
from ...pose.pnp import pnp_ransac
from ...twoview.triangulation import triangulate_tracks
from ..initial_pair import two_view_reconstruction


def noisy_observations(x_true, sigma, *, rng, outlier_ratio=0.0, image_size=None):
    """Add Gaussian pixel noise (and optionally outliers) to noise-free projections.

    Parameters
    ----------
    x_true : (V, M, 2) array_like
        Noise-free pixels, NaN where unseen.
    sigma : float
        Standard deviation per coordinate (pixels).
    rng : numpy.random.Generator
    outlier_ratio : float
        Fraction (0 ≤ · < 1) of the visible observations replaced by uniform random pixels.
    image_size : (width, height), optional
        Required when ``outlier_ratio > 0``.

    Returns
    -------
    x_meas : (V, M, 2) ndarray
    outliers : (V, M) bool ndarray

    >>> x = np.zeros((2, 3, 2)); x[0, 0] = np.nan
    >>> xm, out = noisy_observations(x, 1.0, rng=np.random.default_rng(0))
    >>> xm.shape, bool(np.isnan(xm[0, 0, 0])), int(out.sum())
    ((2, 3, 2), True, 0)
    """
    as_rng(rng)
    x_true = as_tracks(x_true, "x_true")
    sigma = as_positive(sigma, "sigma", allow_zero=True)
    outlier_ratio = as_fraction(outlier_ratio, "outlier_ratio")
    seen = np.all(np.isfinite(x_true), axis=-1)
    x = x_true + rng.normal(scale=sigma, size=x_true.shape) if sigma > 0 else x_true.copy()
    outliers = np.zeros(seen.shape, bool)
    if outlier_ratio > 0:
        if image_size is None:
            raise ValueError("image_size is needed to draw outliers")
        vi, pi = np.nonzero(seen)
        pick = rng.random(vi.size) < outlier_ratio
        outliers[vi[pick], pi[pick]] = True
        x[vi[pick], pi[pick]] = rng.uniform([0, 0], image_size, size=(pick.sum(), 2))
    return x, outliers


def ba_from_truth(scene, x_meas, *, loss="linear", f_scale=1.0, threshold_px=None, final_loss="linear", max_iter=100,
                  tol=1e-10, R0=None, t0=None, X0=None):
    """Bundle adjustment of ``x_meas`` started from the true cameras and points (the ML estimate).

    A stand-in for the full pipeline when only the ML estimate's behaviour matters: with noise of
    a few pixels the optimum found from the truth is the one a good initialisation would reach.

    Parameters
    ----------
    scene : labutils.data.loaders.Scene
        Supplies ``K`` and the starting point (the truth) unless ``R0, t0, X0`` are given.
    x_meas : (V, M, 2) array_like
        Observations, NaN where unseen.
    loss, f_scale : passed to :func:`labutils.bundle.bundle_adjust` (``'huber'``, ``'cauchy'``... are robust).
    threshold_px : float, optional
        The outlier-removal step: after a first adjustment drop the observations whose
        reprojection error exceeds ``threshold_px`` pixels and adjust again with ``final_loss`` (default
        plain least squares: the ML estimate on the kept observations); a point left with fewer than
        two observations is dropped (NaN in ``X``).
    max_iter, tol :
        Passed to :func:`labutils.bundle.bundle_adjust`; the tight default ``tol`` matters: an
        adjustment started from the truth and stopped early is biased towards the truth.
    R0, t0, X0 : optional
        Another starting point than the truth.

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
    X : (M, 3) ndarray
    info : dict
        ``'seconds'``, ``'n_iter'``, ``'cost_final'``, ``'kept'`` ((n_obs,) bool), ``'n_obs'``.
    """
    R0 = scene.R if R0 is None else R0
    t0 = scene.t if t0 is None else t0
    X0 = scene.X if X0 is None else X0
    x_meas = as_tracks(x_meas, "x_meas")
    if x_meas.shape != np.shape(scene.x_true):
        raise ValueError(f"x_meas must have shape {np.shape(scene.x_true)} like scene.x_true; got {x_meas.shape}")
    ci, pi, x2d = observations(x_meas)
    tic = time.perf_counter()
    res = bundle_adjust(R0, t0, X0, ci, pi, x2d, scene.K, loss=loss, f_scale=f_scale, max_iter=max_iter, tol=tol)
    n_iter = res.n_iter
    kept = np.ones(ci.size, bool)
    info_X = res.X
    if threshold_px is not None:
        err = np.linalg.norm(np.asarray(res.residuals).reshape(-1, 2), axis=1)
        kept = err <= as_positive(threshold_px, "threshold_px")
        # a point left with fewer than 2 observations is dropped (its X becomes NaN)
        n_left = np.bincount(pi[kept], minlength=len(X0))
        kept &= n_left[pi] >= 2
        pts = np.flatnonzero(n_left >= 2)
        remap = np.full(len(X0), -1)
        remap[pts] = np.arange(pts.size)
        res2 = bundle_adjust(res.R, res.t, res.X[pts], ci[kept], remap[pi[kept]], x2d[kept], scene.K,
                             loss=final_loss, f_scale=f_scale, max_iter=max_iter, tol=tol)
        X = np.full((len(X0), 3), np.nan)
        X[pts] = res2.X
        res = res2
        n_iter += res.n_iter
        info_X = X
    info = dict(seconds=time.perf_counter() - tic, n_iter=n_iter, cost_final=float(res.cost_final),
                kept=kept, n_obs=int(ci.size))
    return res.R, res.t, info_X, info


def reconstruct_without_ba(tracks, K, order, *, rng, threshold_px=10.0, min_angle_deg=1.0, refine=True):
    """Incremental reconstruction *without* bundle adjustment: the "before BA" of the noise study.

    The same steps as :func:`labutils.sfm.incremental_sfm` minus every joint adjustment: the relative
    pose of the first two views of ``order`` (:func:`labutils.sfm.two_view_reconstruction`), then each
    further view in ``order`` by P3P-RANSAC on the points triangulated so far
    (:func:`labutils.pose.pnp_ransac`, with ``refine`` its own pose only), and the tracks it completes
    triangulated (:func:`labutils.sfm.incremental.triangulate_tracks`). Errors of early views propagate to later
    ones: that is the drift bundle adjustment removes.

    Parameters
    ----------
    tracks : (V, T, 2) array_like
        Pixels, NaN where unseen.
    K : (3, 3) array_like
    order : sequence of int
        The views in the order to add them, e.g. ``Reconstruction.order`` of an SfM run.
    rng : numpy.random.Generator
    threshold_px, min_angle_deg : float
        As in :func:`labutils.sfm.incremental_sfm`.
    refine : bool
        Refine each new pose on its inliers (still no joint adjustment).

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        NaN for views not registered.
    X : (T, 3) ndarray
        NaN for tracks not triangulated.
    """
    as_rng(rng)
    tracks = as_tracks(tracks, min_views=2)
    V, T = tracks.shape[:2]
    order = as_indices(list(order) if isinstance(order, (list, tuple, range)) else order, "order", V, what="view")
    order = order.tolist()
    if len(order) < 2 or len(set(order)) != len(order) or min(order) < 0 or max(order) >= V:
        raise ValueError(f"order must list at least two different views in 0..{V - 1}")
    Ks = as_calibration(K, "K", n_views=V)
    seen = np.all(np.isfinite(tracks), axis=-1)
    R, t, X = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan), np.full((T, 3), np.nan)
    i, j = order[:2]
    idx = np.flatnonzero(seen[i] & seen[j])
    R[j], t[j], X[idx], _ = two_view_reconstruction(tracks[i, idx], tracks[j, idx], Ks[i], Ks[j], rng=rng,
                                                    threshold_px=threshold_px, min_angle_deg=min_angle_deg)
    R[i], t[i] = np.eye(3), np.zeros(3)
    for v in order[2:]:
        idx = np.flatnonzero(seen[v] & np.isfinite(X[:, 0]))
        if idx.size < 6:
            continue
        try:
            pose = pnp_ransac(X[idx], tracks[v, idx], Ks[v], threshold_px=threshold_px, rng=rng, refine=refine)
        except ValueError:
            continue
        R[v], t[v] = pose.R, pose.t
        reg = np.flatnonzero(np.isfinite(t[:, 0]))
        new = np.flatnonzero(~np.isfinite(X[:, 0]) & seen[v] & (seen[reg].sum(0) >= 2))
        if new.size:
            X[new] = triangulate_tracks(tracks[:, new], Ks, R, t, reg, seen[:, new], threshold_px=threshold_px,
                                        min_angle_deg=min_angle_deg)[0]
    return R, t, X


def refine_reconstruction(rec, tracks, K, *, tol=1e-10, max_iter=50):
    """One last plain bundle adjustment of a reconstruction on its inlier observations, to convergence.

    :func:`labutils.sfm.incremental_sfm` ends with a robust (Cauchy) adjustment stopped at a relative cost
    change of 1e-8. The noise study compares with the least-squares optimum, so this runs plain least squares
    on the inliers on to ``tol``, which takes a few more iterations.

    Parameters
    ----------
    rec : labutils.sfm.Reconstruction
        Uses ``R, t, X, registered, inliers``.
    tracks : (V, T, 2) array_like
        The observations it was built from.
    K : (3, 3) array_like

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        NaN for the views that were not registered.
    """
    tracks = as_tracks(tracks)
    if tracks.shape[:2] != np.shape(rec.inliers):
        raise ValueError(f"tracks must have shape {np.shape(rec.inliers) + (2,)} like the reconstruction's; got "
                         f"{tracks.shape}")
    max_iter = as_count(max_iter, "max_iter", 1)
    cams = np.flatnonzero(rec.registered)
    pts = np.flatnonzero(rec.inliers[cams].any(0))
    ci, pi = np.nonzero(rec.inliers[np.ix_(cams, pts)])
    x = tracks[cams[ci], pts[pi]]
    # gauge=None: the errors are measured after alignment, and (at the time of writing) the LM-Schur
    # solver's default gauge moves an exact solution by ~1e-6 degrees
    res = bundle_adjust(rec.R[cams], rec.t[cams], rec.X[pts], ci, pi, x, K, tol=tol, max_iter=max_iter, gauge=None)
    R, t = np.full(np.shape(rec.R), np.nan), np.full(np.shape(rec.t), np.nan)
    R[cams], t[cams] = res.R, res.t
    return R, t


def rms_errors(rot_deg, centre_rel, axis=None):
    """RMS of per-camera errors (NaN-aware), e.g. over cameras and trials: ``(rot, centre)``."""
    rot_deg, centre_rel = as_array(rot_deg, "rot_deg", "(V,) or (trials, V)"), \
        as_array(centre_rel, "centre_rel", "(V,) or (trials, V)")
    if rot_deg.shape != centre_rel.shape or rot_deg.size == 0:
        raise ValueError(f"rot_deg and centre_rel must have one shape (NaN for views not registered); got "
                         f"{rot_deg.shape} and {centre_rel.shape}")
    if np.isinf(rot_deg).any() or np.isinf(centre_rel).any() or (np.isnan(rot_deg) != np.isnan(centre_rel)).any():
        raise ValueError("rot_deg and centre_rel must be finite, NaN together where a view was not registered")
    return (np.sqrt(np.nanmean(np.square(rot_deg), axis=axis)),
            np.sqrt(np.nanmean(np.square(centre_rel), axis=axis)))


def loglog_slope(sigmas, errors):
    """Least-squares slope of ``log(errors)`` against ``log(sigmas)`` (1 for errors ∝ σ).

    >>> round(loglog_slope([0.5, 1, 2], [0.1, 0.2, 0.4]), 12)
    1.0
    """
    s, e = as_array(sigmas, "sigmas", "(n,)"), as_array(errors, "errors", "(n,)")
    if s.shape != e.shape or s.ndim != 1 or s.size < 2:
        raise ValueError(f"sigmas and errors must be two 1-D arrays of the same length >= 2; got shapes {s.shape} "
                         f"and {e.shape}")
    if not (np.all(np.isfinite(s)) and np.all(s > 0) and np.all(np.isfinite(e)) and np.all(e > 0)):
        raise ValueError(f"sigmas and errors must be finite and positive (a NaN error: every trial at that σ "
                         f"failed?); got sigmas {s.tolist()}, errors {e.tolist()}")
    return float(np.polyfit(np.log(s), np.log(e), 1)[0])


class Progress:
    """A progress counter that works everywhere: an ipywidgets bar in a live notebook, and a
    line of text (printed at every ``every``-th step and at the end) in any case, so that headless
    runs (nbval, CI) still show where they are."""

    def __init__(self, total, label="", every=None):
        self.total, self.label, self.n = int(total), label, 0
        self.every = every or max(1, self.total // 5)
        self.bar = None
        try:
            import ipywidgets
            from IPython import get_ipython
            from IPython.display import display

            if get_ipython() is not None:
                self.bar = ipywidgets.IntProgress(value=0, min=0, max=self.total, description=label,
                                                  style={"description_width": "initial"})
                display(self.bar)
        except ImportError:
            pass
        self.tic = time.perf_counter()

    def step(self):
        self.n += 1
        if self.bar is not None:
            self.bar.value = self.n
        if self.n % self.every == 0 or self.n == self.total:
            print(f"{self.label} {self.n}/{self.total} ({time.perf_counter() - self.tic:.1f} s)", flush=True)


@dataclass
class NoiseStudy:
    """Pose errors of one pipeline over noise levels and trials (see :func:`run_noise_study`).

    Attributes
    ----------
    sigmas : list of float
    rot_deg, centre_rel : dict float -> (T, V) ndarray
        Per trial and camera, after similarity alignment of the registered cameras' centres; NaN for
        a camera the pipeline did not register, and for every camera of a failed trial.
    estimates : dict float -> list of (R, t)
        The raw estimates (the pipeline's own gauge; NaN for a failed trial), for single-trial plots.
    seconds : dict float -> (T,) ndarray
        Wall time of each pipeline call.
    failures : dict float -> list of str
        Why trials failed (the pipeline raised ``ValueError``, or registered fewer than 3 views).
    """

    sigmas: list
    rot_deg: dict
    centre_rel: dict
    estimates: dict
    seconds: dict
    failures: dict

    def flag_wrong_basins(self, pred, factor=10.0):
        """Count as failed the trials whose RMS rotation error exceeds ``factor`` times the predicted
        RMS (σ > 0 only); return how many.

        For the ML estimate a trial's ``Σ|φ_i|²`` is a Gaussian quadratic form; exceeding ``factor² = 100``
        times its mean is at most as likely as a χ²₁ exceeding 100 (all weight on one mode, the worst
        case): about 1e-23. Such a trial did not reach the ML optimum: the pipeline converged in a wrong
        basin (or its linearisation no longer holds).
        Its errors become NaN and the reason is added to ``failures``.
        """
        n = 0
        for s in self.sigmas:
            if s <= 0:
                continue
            d = self.rot_deg[s]
            seen = np.isfinite(d)
            r = np.sqrt(np.sum(np.where(seen, d, 0.0) ** 2, axis=1) / np.maximum(seen.sum(1), 1))
            bad = seen.any(1) & (r > factor * pred.rot_rms_deg_all * s)
            for k in np.flatnonzero(bad):
                self.failures[s].append(f"trial {k}: RMS rotation error {r[k]:.3g} deg, over {factor:g}x the bound "
                                        "(a wrong basin)")
            self.rot_deg[s][bad] = np.nan
            self.centre_rel[s][bad] = np.nan
            n += int(bad.sum())
        return n

    def n_ok(self, sigma):
        """Trials at ``sigma`` that produced at least 3 registered views."""
        return int(np.sum(np.any(np.isfinite(self.rot_deg[sigma]), axis=1)))

    def rms(self, which="rot"):
        """RMS error over cameras and successful trials, one per sigma: ``(S,)`` (NaN if none)."""
        d = self.rot_deg if which == "rot" else self.centre_rel
        return np.array([np.sqrt(np.nanmean(d[s] ** 2)) if np.isfinite(d[s]).any() else np.nan for s in self.sigmas])

    def trial_rms(self, which="rot"):
        """RMS error over the cameras of each trial: ``(S, T)`` array (NaN for a failed trial; with
        ``common_noise`` row ``k`` of every level is the same noise pattern)."""
        d = self.rot_deg if which == "rot" else self.centre_rel
        out = []
        for s in self.sigmas:
            seen = np.isfinite(d[s])
            sq = np.sum(np.where(seen, d[s], 0.0) ** 2, axis=1)
            out.append(np.where(seen.any(1), np.sqrt(sq / np.maximum(seen.sum(1), 1)), np.nan))
        return np.array(out)

    def table(self, pred=None):
        """A printable table: per sigma the successful / total trials, mean ± sd and RMS of both
        errors and, given a :class:`PosePrediction` for σ = 1, the predicted RMS and the ratio
        empirical / predicted."""
        head = f"{'sigma':>6} {'ok/trials':>9} | {'rot mean ± sd (deg)':>22} {'RMS':>9}"
        head += f" {'pred':>9} {'ratio':>6}" if pred else ""
        head += f" | {'centre mean ± sd (rel)':>24} {'RMS':>9}" + (f" {'pred':>9} {'ratio':>6}" if pred else "")
        lines = [head]
        for s, r_rms, c_rms in zip(self.sigmas, self.rms("rot"), self.rms("centre")):
            r, c = self.rot_deg[s], self.centre_rel[s]
            ok = f"{self.n_ok(s)}/{len(r)}"
            if not np.isfinite(r).any():
                lines.append(f"{s:6.2f} {ok:>9} | (every trial failed: {self.failures[s][0][:60]})")
                continue
            row = f"{s:6.2f} {ok:>9} | {np.nanmean(r):10.3g} ± {np.nanstd(r):9.3g} {r_rms:9.3g}"
            if pred:
                p = pred.rot_rms_deg_all * s
                row += f" {p:9.3g} {r_rms / p if s > 0 else np.nan:6.3f}"
            row += f" | {np.nanmean(c):11.3g} ± {np.nanstd(c):10.3g} {c_rms:9.3g}"
            if pred:
                p = pred.centre_rms_rel_all * s
                row += f" {p:9.3g} {c_rms / p if s > 0 else np.nan:6.3f}"
            lines.append(row)
        return "\n".join(lines)


def run_noise_study(scene, pipelines, sigmas, n_trials, *, rng, label="trials", keep_estimates=True,
                    common_noise=False):
    """Run pipelines on noisy copies of ``scene.x_true`` and measure their aligned pose errors.

    Every trial draws one noise sample and gives the same observations to every pipeline, so
    pipelines can be compared trial by trial.

    Parameters
    ----------
    scene : labutils.data.loaders.Scene
        Ground truth: ``R, t`` and the noise-free projections ``x_true`` (NaN where unseen).
    pipelines : callable or dict str -> callable
        ``reconstruct(scene, x_meas, sigma, *, rng) -> (R, t)``, NaN poses for unregistered views: the
        pipeline under study (the incremental SfM, or BA from the truth). It is told the noise level,
        as a real pipeline is told its thresholds. A ``ValueError`` it raises counts as a failed trial.
    sigmas : sequence of float
        Pixel noise levels.
    n_trials : int or dict float -> int
        Trials per level.
    rng : numpy.random.Generator
        Draws the noise and is passed on to the pipelines.
    common_noise : bool
        Common random numbers: trial ``k`` of every level uses the same standard-normal draw ``ε_k``,
        scaled by σ (``x = x_true + σ ε_k``). The errors of an estimator that is linear in the noise
        then scale exactly with σ, so their log–log slope measures the nonlinearity alone, free of
        Monte Carlo scatter. (Levels are then not independent of each other.)

    Returns
    -------
    NoiseStudy, or dict str -> NoiseStudy when ``pipelines`` is a dict.
    """
    as_rng(rng)
    single = callable(pipelines)
    pipes = {"pipeline": pipelines} if single else dict(pipelines)
    if not pipes or not all(callable(f) for f in pipes.values()):
        raise ValueError("pipelines must be a callable or a non-empty dict of callables")
    sigmas = [float(s) for s in sigmas]
    counts = {s: int(n_trials[s] if isinstance(n_trials, dict) else n_trials) for s in sigmas}
    if min(counts.values()) < 1:
        raise ValueError(f"need at least one trial per noise level; got {counts}")
    progress = Progress(sum(counts.values()), label)
    V = scene.n_views
    base = rng.normal(size=(max(counts.values()),) + np.shape(scene.x_true)) if common_noise else None
    out = {name: NoiseStudy(sigmas=sigmas, rot_deg={}, centre_rel={}, estimates={}, seconds={}, failures={})
           for name in pipes}
    for s in sigmas:
        for st in out.values():
            st.rot_deg[s], st.centre_rel[s] = np.full((counts[s], V), np.nan), np.full((counts[s], V), np.nan)
            st.estimates[s], st.seconds[s], st.failures[s] = [], np.zeros(counts[s]), []
        for k in range(counts[s]):
            if common_noise:
                x_meas = scene.x_true + s * base[k]
            else:
                x_meas, _ = noisy_observations(scene.x_true, s, rng=rng)
            for name, reconstruct in pipes.items():
                st = out[name]
                tic = time.perf_counter()
                why = None
                try:
                    R, t = reconstruct(scene, x_meas, s, rng=rng)
                    R, t = np.asarray(R, float), np.asarray(t, float)
                except ValueError as exc:
                    R, t = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan)
                    why = f"trial {k}: {str(exc).splitlines()[0]}"
                st.seconds[s][k] = time.perf_counter() - tic
                ok = np.all(np.isfinite(R), axis=(1, 2)) & np.all(np.isfinite(t), axis=1)
                if ok.sum() >= 3:
                    st.rot_deg[s][k, ok], st.centre_rel[s][k, ok] = pose_errors(R[ok], t[ok], scene.R[ok], scene.t[ok])
                elif why is None:
                    why = f"trial {k}: only {ok.sum()} views registered"
                if why is not None:
                    st.failures[s].append(why)
                if keep_estimates:
                    st.estimates[s].append((R, t))
            progress.step()
    return out["pipeline"] if single else out
