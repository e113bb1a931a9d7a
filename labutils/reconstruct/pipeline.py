"""From a folder of photos to cameras and coloured, oriented points: the stages of ``python -m labutils.reconstruct``.

1. **Images and features** — each photo read at a working size (longer side ``max_size``), SIFT features.
2. **Matches** — every pair (up to 20 photos, else neighbours in file order), ratio test, mutual check, and a
   fundamental-matrix RANSAC, which needs no calibration.
3. **Capture check** (:mod:`~labutils.reconstruct.capture`) — blur, features, the view graph: said before the long
   work.
4. **The camera** — given (``K`` and lens distortion from a calibration), or: the EXIF focal length
   (:mod:`~labutils.reconstruct.exif`); without one, self-calibration from the pairs' fundamental matrices
   (:func:`~labutils.reconstruct.intrinsics.focal_from_fundamentals`).
5. **SfM** — :func:`labutils.sfm.incremental_sfm` on the tracks (undistorted with the current lens), then one focal
   length and ``(k1, k2)`` refined with every camera and point
   (:func:`~labutils.reconstruct.intrinsics.refine_shared_intrinsics`); when that changed the camera, SfM runs once
   more with the refined camera, so that views the first guess kept out can register.
6. **Points** — colours from the photos, normals oriented towards the cameras that see them.
"""
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..calibrate.lens import undistort_points
from ..core.validation import as_array, as_calibration, as_count, as_rng
from ..match.descriptors import detect_features
from ..match.images import IMAGE_SUFFIXES, read_gray, scale_calibration
from ..match.pairs import select_pairs
from ..match.pipeline import match_views, tracks_from_matches
from ..model.pointcloud import estimate_normals, orient_normals
from ..sfm.incremental import bundle_from_cameras, incremental_sfm
from .capture import CaptureReport, capture_check
from .exif import focal_from_exif
from .intrinsics import focal_from_fundamentals, refine_shared_intrinsics

__all__ = ["PhotoReconstruction", "image_files", "reconstruct_photos"]


def image_files(folder):
    """The PNG and JPEG files of ``folder`` in sorted file-name order."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


@dataclass
class PhotoReconstruction:
    """What :func:`reconstruct_photos` returns; pixels and K are those of the original photos.

    Attributes
    ----------
    names : list of str
    K : (3, 3) ndarray
    dist : (2,) ndarray
        ``(k1, k2)``.
    R, t : (V, 3, 3), (V, 3) ndarray
        NaN for views that did not register.
    registered : (V,) bool ndarray
    X, colors, normals : (N, 3) ndarrays
        The points, their RGB colours (0..255) and unit normals.
    focal : dict
        ``value``, ``sd`` (pixels; 0 when given), ``source`` and ``start`` (the first guess).
    capture : CaptureReport
    self_calibration : (n, 2) ndarray or None
        The self-calibration's curve ``(f in original pixels, median asymmetry of E)``, when it ran.
    log : list of str
    """

    names: list
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    registered: np.ndarray
    X: np.ndarray
    colors: np.ndarray
    normals: np.ndarray
    focal: dict
    capture: CaptureReport
    self_calibration: np.ndarray = None
    log: list = field(default_factory=list, repr=False)

    def cameras(self):
        """One entry per image: ``{"R", "t", "K", "dist"}`` (lists) or None where the view did not register."""
        out = []
        for v in range(len(self.names)):
            out.append(None if not self.registered[v] else {"R": self.R[v].tolist(), "t": self.t[v].tolist(),
                                                           "K": self.K.tolist(), "dist": self.dist.tolist()})
        return out


class NotReconstructable(ValueError):
    """The photos cannot give a reconstruction; the message says why and what to reshoot."""


def _undistorted_tracks(x, K, dist):
    if not np.any(dist):
        return x
    out = np.full_like(x, np.nan)
    d5 = np.array([dist[0], dist[1], 0.0, 0.0, 0.0])
    for v in range(len(x)):
        ok = np.isfinite(x[v, :, 0])
        if ok.any():
            out[v, ok] = undistort_points(x[v, ok], K, d5)
    return out


def reconstruct_photos(paths, *, rng, K=None, dist=None, max_size=1200, min_inliers=20, log=print, progress=None,
                       focal_prior_sigma=None):
    """Reconstruct cameras and points from photos of one camera (module docstring).

    Parameters
    ----------
    paths : sequence of paths
        The photos, in the order of the result (e.g. :func:`image_files`).
    rng : numpy.random.Generator
    K : (3, 3) array_like, optional
        The calibration of the original photos; without it, estimated (EXIF, self-calibration, BA).
    dist : array_like, optional
        ``(k1, k2[, p1, p2, k3])`` with ``K``: held fixed (only k1, k2 are used: the report's model).
    max_size : int
        Longer side of the working images in pixels.
    min_inliers : int
        Verified matches for an edge of the view graph.
    log : callable
        Receives one line per step.
    progress : callable, optional
        ``progress(stage, done, total)``.
    focal_prior_sigma : float, optional
        σ of the prior on log f; by default 0.1 with an EXIF focal length, 0.5 without.

    Returns
    -------
    PhotoReconstruction

    Raises
    ------
    NotReconstructable
        When the view graph has no two connected views, or SfM registers fewer than two (the message says why).
    ValueError
        Bad input (an unreadable image, a K that is not a calibration, photos of different sizes).
    """
    rng = as_rng(rng)
    max_size = as_count(max_size, "max_size", 16)
    min_inliers = as_count(min_inliers, "min_inliers", 8)
    if dist is not None:
        dist = as_array(dist, "dist", "(2,) to (5,)")
        if dist.ndim != 1 or not 2 <= dist.size <= 5 or not np.all(np.isfinite(dist)):
            raise ValueError(f"dist must be 2 to 5 finite numbers (k1, k2[, p1, p2, k3]); got shape {dist.shape}")
        if K is None:
            raise ValueError("dist goes with K: a lens without its calibration is not used")
    paths = [Path(p) for p in paths]
    names = [p.name for p in paths]
    V = len(paths)
    if V < 2:
        raise NotReconstructable(f"{V} photo{'s' if V != 1 else ''}: at least 2 are needed (better 10 or more)")
    step = progress or (lambda *a: None)
    grays, feats, size0, scales = [], [], None, []
    for k, p in enumerate(paths):
        gray, s, size = read_gray(p, max_size)
        if size0 is None:
            size0 = size
        elif size != size0:
            raise ValueError(f"{p}: {size[0]}x{size[1]} px, the first photo is {size0[0]}x{size0[1]}: one camera, "
                             "one image size (rotate or crop none of them)")
        grays.append(gray)
        scales.append(s)
        feats.append(detect_features(gray, scale=s))
        step("features", k + 1, V)
    s = scales[0]
    log(f"{V} photos of {size0[0]}x{size0[1]} px, working at {grays[0].shape[1]}x{grays[0].shape[0]}; "
        f"{int(np.median([len(f) for f in feats]))} features per photo (median)")
    pairs = select_pairs(V, "all" if V <= 20 else "sequence", None if V <= 20 else 5)
    result = match_views(feats, pairs, rng=rng, min_inliers=min_inliers,
                         progress=lambda done, total=None: step("matching", done, len(pairs)))
    inl = {(r["i"], r["j"]): int(r["epipolar"]) for r in result.table}
    report = capture_check(names, grays, [len(f) for f in feats], inl, min_inliers=min_inliers)
    for line in report.problems:
        log(f"capture: {line}")
    if len(report.largest) < 2:
        raise NotReconstructable("no two photos share enough verified matches (" + (report.problems[-1] if
                                 report.problems else "") + ")")

    c_work = np.array([(grays[0].shape[1] - 1) / 2, (grays[0].shape[0] - 1) / 2])
    curve = None
    if K is not None:
        K = as_calibration(K, "K")
        Kw = scale_calibration(K, s)
        d = np.zeros(2) if dist is None else dist[:2]
        focal = {"value": float(K[0, 0]), "sd": 0.0, "source": "given", "start": float(K[0, 0])}
        log(f"camera: given, f = {K[0, 0]:.1f} px, k1 = {d[0]:.4f}, k2 = {d[1]:.4f}")
    else:
        guess = focal_from_exif(paths[0])
        Fs = [result.geometry[p].F for p in result.matches]
        f_self, curve, sharp = (focal_from_fundamentals(Fs, c_work, max(grays[0].shape)) if Fs
                                else (None, None, 1.0))
        if curve is not None:
            curve = np.column_stack([curve[:, 0] / s, curve[:, 1]])
        if guess.source != "guess":
            f_start, sigma = guess.f_px * s, focal_prior_sigma or 0.1
            log(f"camera: {guess.text}; self-calibration from {len(Fs)} pairs says {f_self / s:.0f} px")
        else:
            f_start, sigma = (f_self if f_self else guess.f_px * s), focal_prior_sigma or 0.5
            log(f"camera: no focal length in EXIF; self-calibration from {len(Fs)} pairs: {f_start / s:.0f} px"
                + (" (weakly determined: the pairs' geometry hardly constrains it)" if sharp > 0.5 else ""))
        Kw = np.array([[f_start, 0, c_work[0]], [0, f_start, c_work[1]], [0, 0, 1.0]])
        d = np.zeros(2)
        focal = {"value": f_start / s, "sd": np.nan, "source": guess.source if guess.source != "guess" else
                 "self-calibration", "start": f_start / s, "prior_sigma_log": sigma}
    tracks = tracks_from_matches(feats, result).x
    rec, refined = None, None
    for round_ in range(2):
        x = _undistorted_tracks(tracks, Kw, d)
        rec = incremental_sfm(x, Kw, rng=rng)
        log(f"sfm (pass {round_ + 1}): {rec.n_registered} of {V} views registered, {rec.n_points} points")
        step("sfm", round_ + 1, 2)
        if rec.n_registered < 2:
            raise NotReconstructable("structure from motion registered fewer than two views")
        if focal["source"] == "given":
            break
        refined = refine_shared_intrinsics(tracks, rec.R, rec.t, rec.X, rec.inliers, Kw, dist0=d,
                                           f_prior=(focal["start"] * s, focal["prior_sigma_log"]))
        moved = abs(refined.K[0, 0] / Kw[0, 0] - 1) > 0.01 or np.any(np.abs(refined.dist - d) > 0.01)
        Kw, d = refined.K, refined.dist
        focal.update(value=float(Kw[0, 0] / s), sd=float(refined.f_sd / s))
        log(f"camera refined: f = {focal['value']:.1f} ± {focal['sd']:.1f} px, k1 = {d[0]:.4f} ± "
            f"{refined.k_sd[0]:.4f}, k2 = {d[1]:.4f} ± {refined.k_sd[1]:.4f}; RMS {refined.rms_px[0]:.2f} -> "
            f"{refined.rms_px[1]:.2f} working px")
        if not moved or rec.n_registered == V:
            break
    if refined is not None:             # every point and camera with the refined camera fixed: the library's BA
        rec = bundle_from_cameras(_undistorted_tracks(tracks, Kw, d), Kw, refined.R, refined.t)
        log(f"bundle adjustment with the refined camera: {rec.n_registered} views, {rec.n_points} points")
    R, t, X = rec.R, rec.t, rec.X
    registered = np.isfinite(R).all(axis=(1, 2))
    ok = np.flatnonzero(np.isfinite(X).all(axis=1))
    vis = rec.inliers[:, ok] & registered[:, None]
    colors = _colours(paths, tracks[:, ok], vis, max_size)
    normals = (orient_normals(X[ok], estimate_normals(X[ok]), R, t, vis) if len(ok) >= 13
               else np.zeros((len(ok), 3)))
    K_out = scale_calibration(Kw, 1 / s)
    for v in np.flatnonzero(~registered):
        log(f"view {v} ({names[v]}) did not register" + (" (outside the connected group)"
                                                         if report.component[v] else ""))
    return PhotoReconstruction(names, K_out, np.asarray(d, float), R, t, registered, X[ok], colors, normals, focal,
                               report, curve, list(rec.log))


def _colours(paths, x, vis, max_size):
    """Per-channel median of each point's observed pixel colours (working images: ``read_gray``'s size)."""
    samples = np.full((len(paths), x.shape[1], 3), np.nan)
    for v, p in enumerate(paths):
        if not vis[v].any():
            continue
        gray, _, _ = read_gray(p, max_size)
        img = cv2.resize(cv2.imread(str(p), cv2.IMREAD_COLOR), (gray.shape[1], gray.shape[0]),
                         interpolation=cv2.INTER_AREA)[:, :, ::-1]
        xy = np.clip(np.round(x[v, vis[v]]).astype(int), 0, [img.shape[1] - 1, img.shape[0] - 1])
        samples[v, vis[v]] = img[xy[:, 1], xy[:, 0]]
    seen = np.isfinite(samples[..., 0]).any(axis=0)
    col = np.full((x.shape[1], 3), 128.0)
    col[seen] = np.nanmedian(samples[:, seen], axis=0)
    return col.round().astype(np.uint8)
