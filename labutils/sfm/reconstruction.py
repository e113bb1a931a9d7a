"""The result of structure from motion: a :class:`Reconstruction` (cameras, points, the observations that support
them), its JSON form, and its errors against reference cameras."""
import json
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..core.cli import write_atomically
from ..core.metrics import align_cameras, apply_similarity, pose_errors
from ..core.scene import CameraRig
from ..core.validation import as_array, as_calibration, as_mask, as_rotations, as_tracks, as_translations


@dataclass
class Reconstruction(CameraRig):
    """Cameras, points and the observations that support them, as built by :func:`incremental_sfm`.

    Attributes
    ----------
    R : (V, 3, 3) ndarray
        Rotations, ``x_cam = R[i] @ X + t[i]``; NaN for views that were not registered.
    t : (V, 3) ndarray
        Translations; NaN for views that were not registered.
    registered : (V,) bool ndarray
    X : (T, 3) ndarray
        One world point per track; NaN for tracks that were not triangulated.
    inliers : (V, T) bool ndarray
        The observations the reconstruction uses (registered view, triangulated track, not rejected).
    order : list of int
        The views in the order they were added (the first two are the initial pair).
    K : (V, 3, 3) ndarray
        The calibration of each view.
    timings : dict
        Seconds spent per stage (``'total'`` included).
    log : list of str
        One line per step, for reading what happened.
    """

    R: np.ndarray
    t: np.ndarray
    registered: np.ndarray
    X: np.ndarray
    inliers: np.ndarray
    order: list
    K: np.ndarray
    timings: dict = field(default_factory=dict)
    log: list = field(default_factory=list, repr=False)

    @property
    def n_tracks(self):
        return self.X.shape[0]

    @property
    def n_registered(self):
        return int(self.registered.sum())

    @property
    def n_points(self):
        """Triangulated tracks."""
        return int(np.isfinite(self.X[:, 0]).sum())

    @property
    def n_observations(self):
        return int(self.inliers.sum())

    def reprojection_errors(self, tracks):
        """(V, T) reprojection errors in pixels of the inlier observations of ``tracks`` (NaN elsewhere)."""
        return masked_reprojection_errors(self.K, self.R, self.t, self.X, tracks, self.inliers)

    def summary(self):
        """One line: what was reconstructed, and how long it took."""
        secs = self.timings.get("total")
        return (f"{self.n_registered} of {self.n_views} views registered, {self.n_points} of {self.n_tracks} "
                f"tracks triangulated, {self.n_observations} observations"
                + (f", {secs:.2f} s" if secs is not None else ""))

    def to_dict(self):
        """The result as plain JSON types (the format of the command line's RESULT.json).

        ``cameras`` has one entry per view in input order, ``{"R": 3x3, "t": [3]}`` or ``None`` for a
        view that was not registered; ``points`` lists ``{"track": index, "X": [3], "views": [...]}``
        for each triangulated track (``views``: the views whose observation supports it); ``order`` is
        the registration order. No timings: the same seed gives the same file.
        """
        cameras = [{"R": self.R[v].tolist(), "t": self.t[v].tolist()} if self.registered[v] else None
                   for v in range(self.n_views)]
        points = [{"track": int(k), "X": self.X[k].tolist(), "views": np.flatnonzero(self.inliers[:, k]).tolist()}
                  for k in np.flatnonzero(np.isfinite(self.X[:, 0]))]
        return {"cameras": cameras, "points": points, "order": [int(v) for v in self.order]}

    def to_json(self, path):
        """Write :meth:`to_dict` to ``path`` (JSON, atomically)."""
        write_atomically(path, json.dumps(self.to_dict()) + "\n")


def masked_reprojection_errors(K, R, t, X, tracks, mask):
    """Reprojection errors in pixels, ``‖x - π(K (R X + t))‖``, of the observations in ``mask``.

    Parameters
    ----------
    K : (V, 3, 3) array_like
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    X : (T, 3) array_like
    tracks : (V, T, 2) array_like
    mask : (V, T) bool array_like
        The observations to evaluate.

    Returns
    -------
    err : (V, T) ndarray
        NaN outside ``mask``; ``inf`` where the point is not in front of the camera (cheirality).

    >>> K = np.eye(3)[None]; R = np.eye(3)[None]; t = np.zeros((1, 3))
    >>> masked_reprojection_errors(K, R, t, [[0.3, 0.4, 1.0], [0, 0, -1]], [[[0.0, 0.0], [0.0, 0.0]]], [[True, True]])
    array([[0.5, inf]])
    """
    tracks = as_tracks(tracks)
    V, N = tracks.shape[:2]
    mask = as_mask(mask, "mask", (V, N), like="tracks")
    unseen = mask & ~np.all(np.isfinite(tracks), axis=-1)
    if unseen.any():
        v, k = np.argwhere(unseen)[0]
        raise ValueError(f"mask marks observation ({v}, {k}) that tracks does not have (NaN)")
    K = as_calibration(K, "K", n_views=V, like_name="tracks")
    R, t, X = _poses_and_points(R, t, X, mask)
    err = np.full(mask.shape, np.nan)
    cam, pt = np.nonzero(mask)
    c = np.einsum("nij,nj->ni", R[cam], X[pt]) + t[cam]
    q = np.einsum("nij,nj->ni", K[cam], c)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.linalg.norm(q[:, :2] / q[:, 2:] - tracks[cam, pt], axis=1)
    e[~(c[:, 2] > 0)] = np.inf
    err[cam, pt] = e
    return err


def _poses_and_points(R, t, X, mask):
    """R ``(V, 3, 3)``, t ``(V, 3)`` and X ``(N, 3)`` for a ``(V, N)`` mask: the views and points the mask uses must
    be finite (rotations and translations), the others may be NaN (not registered, not triangulated)."""
    V, N = mask.shape
    R, t, X = as_array(R, "R", f"({V}, 3, 3)"), as_array(t, "t", f"({V}, 3)"), as_array(X, "X", f"({N}, 3)")
    if R.shape != (V, 3, 3):
        raise ValueError(f"R must have shape ({V}, 3, 3) (one rotation per view of mask); got shape {R.shape}")
    if t.shape != (V, 3):
        raise ValueError(f"t must have shape ({V}, 3) (one translation per row); got shape {t.shape}"
                         + (" — transposed?" if t.shape == (3, V) else ""))
    if X.shape != (N, 3):
        raise ValueError(f"X must have shape ({N}, 3) (one point per column of mask); got shape {X.shape}"
                         + (" — transposed?" if X.shape == (3, N) else ""))
    views, points = mask.any(axis=1), mask.any(axis=0)
    R = R.copy()
    R[views] = as_rotations(R[views], "R")
    as_translations(t[views], "t")
    bad = np.flatnonzero(points & ~np.all(np.isfinite(X), axis=1))
    if bad.size:
        raise ValueError(f"X has non-finite rows {bad[:5].tolist()} that mask uses")
    return R, t, X


def camera_errors(rec: "Reconstruction", R_true: ArrayLike, t_true: ArrayLike) -> tuple:
    """Per-camera errors against reference poses, after a similarity alignment of the centres (Umeyama).

    Parameters
    ----------
    rec : Reconstruction
    R_true : (V, 3, 3) array_like
    t_true : (V, 3) array_like

    Returns
    -------
    rot_deg : (V,) ndarray
        Rotation error in degrees (NaN for views that were not registered).
    centre_rel : (V,) ndarray
        Centre error divided by the scene size (RMS distance of the reference centres from their mean).
    """
    reg = np.asarray(rec.registered, bool)
    if reg.sum() < 3:
        raise ValueError(f"need at least 3 registered views to align; got {reg.sum()}")
    V = reg.size
    R_true = as_rotations(as_array(R_true, "R_true", f"({V}, 3, 3)"), "R_true", n=V)
    t_true = as_translations(t_true, "t_true", n=V)
    rot, cen = np.full(reg.shape, np.nan), np.full(reg.shape, np.nan)
    rot[reg], cen[reg] = pose_errors(rec.R[reg], rec.t[reg], np.asarray(R_true, float)[reg],
                                     np.asarray(t_true, float)[reg])
    return rot, cen


def align_reconstruction(rec, R_true, t_true):
    """The reconstruction moved into the frame (and scale) of reference poses, for plotting.

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
    X : (T, 3) ndarray
        Poses and points after the similarity that best maps the registered centres onto the reference.
    """
    if not isinstance(rec, Reconstruction):
        raise ValueError(f"rec must be a Reconstruction (what incremental_sfm returns); got {type(rec).__name__}")
    reg = np.asarray(rec.registered, bool)
    V = reg.size
    R_true = as_rotations(as_array(R_true, "R_true", f"({V}, 3, 3)"), "R_true", n=V, like_name="rec.R")
    t_true = as_translations(t_true, "t_true", n=V, like_name="rec.R")
    R, t = np.full_like(rec.R, np.nan), np.full_like(rec.t, np.nan)
    R[reg], t[reg], sim = align_cameras(rec.R[reg], rec.t[reg], R_true[reg], t_true[reg])
    return R, t, apply_similarity(sim, rec.X)


