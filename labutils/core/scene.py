"""The records the workbook passes around: a :class:`Scene` (cameras, points and their images, with ground truth)
and :class:`Views` (calibrated images without 3D truth), and the conversions between a track array and the
bundle-adjustment observation arrays."""
from dataclasses import dataclass, field

import cv2
import numpy as np

from .geometry import P_from_KRt, camera_center
from .validation import as_array, as_count, as_indices, as_points, as_tracks


class ImageNotReadable(OSError):
    """An image file of a data set cannot be read."""


class CameraRig:
    """What every record with one camera per view shares: ``n_views``, ``P`` and ``C`` from its ``K`` (V, 3, 3),
    ``R`` (V, 3, 3) and ``t`` (V, 3) (``x_cam = R @ X + t``). A mixin for the records' dataclasses; NaN cameras
    (unregistered views of a reconstruction) give NaN rows."""

    @property
    def n_views(self):
        return self.R.shape[0]

    @property
    def P(self):
        """(V, 3, 4) camera matrices ``K @ [R | t]``."""
        return np.einsum("vij,vjk->vik", self.K, np.concatenate([self.R, self.t[..., None]], axis=2))

    @property
    def C(self):
        """(V, 3) camera centres ``-Rᵀ t``."""
        return camera_center(self.R, self.t)


def read_rgb(path):
    """Read an image file as an ``(H, W, 3)`` uint8 RGB array; ``ImageNotReadable`` if it cannot be read."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ImageNotReadable(f"{path}: cannot read the image (missing, or not an image file)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def nan_tracks(raw, missing=-1):
    """Turn a ``(V, M, 2)`` array marked with ``missing`` into one with NaN where unseen.

    >>> nan_tracks(np.array([[[1., 2.], [-1., -1.]]]))
    array([[[ 1.,  2.],
            [nan, nan]]])
    """
    x = as_array(raw, "raw", "(V, M, 2)").copy()
    if x.ndim != 3 or x.shape[2] != 2:
        raise ValueError(f"raw must have shape (V, M, 2) (views, tracks, pixel); got shape {x.shape}")
    if np.isinf(x).any():
        raise ValueError("raw has infinite entries: mark an unseen observation with the missing value")
    if not (isinstance(missing, (int, float, np.integer, np.floating)) and not isinstance(missing, bool)
            and np.isfinite(missing)):
        raise ValueError(f"missing must be a finite number (the marker of an unseen observation); got {missing!r}")
    half = np.isnan(x[..., 0]) != np.isnan(x[..., 1])
    if half.any():
        v, k = np.argwhere(half)[0]
        raise ValueError(f"raw[{v}, {k}] has one NaN coordinate: an observation is two numbers or unseen")
    x[np.any(x == missing, axis=-1)] = np.nan
    return x


def observations(x):
    """Flatten a ``(V, M, 2)`` track array (NaN where unseen) into bundle-adjustment arrays.

    Returns
    -------
    camera_indices : (n_obs,) int ndarray
    point_indices : (n_obs,) int ndarray
    points_2d : (n_obs, 2) ndarray

    >>> x = np.full((2, 3, 2), np.nan); x[0, 1] = [5, 6]; x[1, 2] = [7, 8]
    >>> cam, pt, p2 = observations(x)
    >>> cam.tolist(), pt.tolist(), p2.tolist()
    ([0, 1], [1, 2], [[5.0, 6.0], [7.0, 8.0]])
    """
    x = as_tracks(x, "x")
    cam, pt = np.nonzero(np.all(np.isfinite(x), axis=-1))
    return cam, pt, x[cam, pt]


def tracks_from_observations(camera_indices, point_indices, points_2d, n_views, n_points):
    """Inverse of :func:`observations`: a ``(n_views, n_points, 2)`` array, NaN where unseen.

    Each (view, point) pair may be observed once; indices must be integers in range (``ValueError`` otherwise).

    >>> tracks_from_observations([0, 1], [1, 0], [[5.0, 6.0], [7.0, 8.0]], 2, 2)[:, :, 0].tolist()
    [[nan, 5.0], [7.0, nan]]
    """
    n_views, n_points = as_count(n_views, "n_views"), as_count(n_points, "n_points")
    ci = as_indices(camera_indices, "camera_indices", n_views, what="view", holder="n_views")
    pi = as_indices(point_indices, "point_indices", n_points, length=len(ci), what="point", holder="n_points")
    xy = as_points(points_2d, "points_2d", min_n=0, like=(ci, "camera_indices"))
    key = ci * n_points + pi
    if np.unique(key).size < key.size:
        dup = int(np.flatnonzero(np.bincount(key) > 1)[0])
        raise ValueError(f"view {dup // n_points} observes point {dup % n_points} more than once")
    x = np.full((n_views, n_points, 2), np.nan)
    x[ci, pi] = xy
    return x


@dataclass
class Scene:
    """Cameras, points and their images, with ground truth where known.

    Attributes
    ----------
    name : str
    K : (3, 3) ndarray
        Shared calibration.
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        True poses, ``x_cam = R[i] @ X + t[i]``; every true point is in front of the cameras that see it.
    X : (M, 3) ndarray
        True 3D points.
    x_true : (V, M, 2) ndarray
        Noise-free projections, NaN where unseen.
    x_meas : (V, M, 2) ndarray
        Measured projections of the same tracks (noise, maybe outliers), NaN where unseen.
    image_size : (width, height)
    source : str
        ``'real'`` or ``'synthetic'``.
    noise_px : float or None
        The pixel noise added to ``x_meas`` when known.
    outliers : (V, M) bool ndarray or None
        Which measurements were replaced by outliers, when known.
    tracks : (V, T, 2) ndarray or None
        Extra real tracks without 3D truth (the dinosaur's 4,983 ``viff`` tracks), NaN where unseen.
    tracks_noise_px : float or None
        The pixel noise of ``tracks`` when known (synthetic scenes).
    image_paths : list of Path or None
    """

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    X: np.ndarray
    x_true: np.ndarray
    x_meas: np.ndarray
    image_size: tuple
    source: str = "synthetic"
    noise_px: float = None
    outliers: np.ndarray = None
    tracks: np.ndarray = None
    tracks_noise_px: float = None
    image_paths: list = field(default=None, repr=False)

    @property
    def n_views(self):
        return self.R.shape[0]

    @property
    def n_points(self):
        return self.X.shape[0]

    @property
    def P(self):
        """(V, 3, 4) camera matrices ``K @ [R | t]``."""
        return np.stack([P_from_KRt(self.K, R, t) for R, t in zip(self.R, self.t)])

    @property
    def C(self):
        """(V, 3) camera centres."""
        return camera_center(self.R, self.t)

    @property
    def visible(self):
        """(V, M) bool: which true point each view sees."""
        return np.all(np.isfinite(self.x_true), axis=-1)

    def pair(self, i, j, which="meas"):
        """Correspondences between views ``i`` and ``j``.

        Parameters
        ----------
        which : {'meas', 'true', 'tracks'}
            The measured tracks, the noise-free ones, or the extra real tracks.

        Returns
        -------
        x1, x2 : (N, 2) ndarray
            Pixels in views i and j of the tracks seen in both.
        idx : (N,) int ndarray
            Their track (point) indices.
        """
        x = {"meas": self.x_meas, "true": self.x_true, "tracks": self.tracks}[which]
        if x is None:
            raise ValueError(f"this scene has no '{which}' tracks")
        both = np.all(np.isfinite(x[i]), axis=-1) & np.all(np.isfinite(x[j]), axis=-1)
        idx = np.flatnonzero(both)
        return x[i, idx], x[j, idx], idx

    def image(self, i):
        """View ``i`` as an RGB ``(H, W, 3)`` uint8 array (real data only)."""
        if not self.image_paths:
            raise ValueError(f"the {self.source} scene '{self.name}' has no images")
        return read_rgb(self.image_paths[i])

    def summary(self):
        """One line: what this scene is."""
        obs = int(self.visible.sum())
        extra = "" if self.tracks is None else (f", {np.isfinite(self.tracks[..., 0]).sum()} observations in "
                                                f"{self.tracks.shape[1]} extra tracks")
        return (f"{self.source} scene '{self.name}': {self.n_views} views, {self.n_points} points, "
                f"{obs} observations{extra}")


@dataclass
class Views(CameraRig):
    """Calibrated images without 3D truth: the cameras of a multi-view data set and its image files.

    Attributes
    ----------
    name : str
    K : (V, 3, 3) ndarray
        Calibration of each view (``K[:, 2, 2] == 1``).
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        Poses, ``x_cam = R[i] @ X + t[i]`` (the data set's own convention converted to ours).
    image_paths : list of Path
    image_size : (width, height)
        Of the images as stored (before any ``scale`` given to :meth:`image`).
    source : str
        ``'real'`` or ``'synthetic'``.
    """

    name: str
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    image_paths: list = field(repr=False)
    image_size: tuple = None
    source: str = "real"

    def image(self, i):
        """View ``i`` as an RGB ``(H, W, 3)`` uint8 array."""
        return read_rgb(self.image_paths[i])
