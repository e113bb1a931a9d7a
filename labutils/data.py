"""Finding and loading the data: the data path, the dinosaur, and the :class:`Scene` record.

The data path is searched in this order:

1. ``$LABUTILS_DATA`` (a folder; the value ``none`` turns real data off, as on a fresh clone),
2. the project's own ``data/`` folder,
3. ``../shared/data/`` beside the project's root.

Real data is never committed. When it is missing, :func:`load_scene` falls back to a synthetic
scene from :mod:`labutils.synthetic`, with ground truth, and says so.
"""
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .geometry import KRt_from_P, P_from_KRt, camera_center

PROJECT_ROOT = Path(__file__).resolve().parents[1]

DINO_HELP = """\
The Oxford dinosaur is not on the data path. Put it at <data>/dino/:
  dino/BAdino2.mat                   cameras, 3D points and tracks (the course's file; the
                                     tracks come from the Oxford VGG multi-view data page,
                                     https://www.robots.ox.ac.uk/~vgg/data/mview/, 'Dinosaur')
  dino/images/viff.000.png ... viff.035.png   the 36 images (720x576)
where <data> is $LABUTILS_DATA, the project's data/ folder, or ../shared/data/ beside the project."""


class DataNotFoundError(FileNotFoundError):
    """A real data set is not on the data path; the message says what is missing and where to get it."""


def data_dirs():
    """The folders searched for real data, in order (those that exist).

    >>> isinstance(data_dirs(), list)
    True
    """
    env = os.environ.get("LABUTILS_DATA", "")
    if env.strip().lower() == "none":
        return []
    candidates = ([Path(env).expanduser()] if env else []) + [PROJECT_ROOT / "data", PROJECT_ROOT.parent / "shared" / "data"]
    return [p for p in candidates if p.is_dir()]


def find_data(relpath, help_text=None):
    """Path of ``relpath`` in the first data folder that has it, else :class:`DataNotFoundError`."""
    for d in data_dirs():
        p = d / relpath
        if p.exists():
            return p
    searched = ", ".join(str(d) for d in data_dirs()) or "(no data folder: $LABUTILS_DATA=none or none exists)"
    raise DataNotFoundError(f"{relpath} not found; searched {searched}.\n" + (help_text or ""))


def has_data(relpath):
    """True if ``relpath`` is on the data path."""
    try:
        find_data(relpath)
        return True
    except DataNotFoundError:
        return False


def nan_tracks(raw, missing=-1):
    """Turn a ``(V, M, 2)`` array marked with ``missing`` into one with NaN where unseen.

    >>> nan_tracks(np.array([[[1., 2.], [-1., -1.]]]))
    array([[[ 1.,  2.],
            [nan, nan]]])
    """
    x = np.array(raw, dtype=float)
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
    x = np.asarray(x, dtype=float)
    cam, pt = np.nonzero(np.all(np.isfinite(x), axis=-1))
    return cam, pt, x[cam, pt]


def tracks_from_observations(camera_indices, point_indices, points_2d, n_views, n_points):
    """Inverse of :func:`observations`: a ``(n_views, n_points, 2)`` array, NaN where unseen."""
    x = np.full((n_views, n_points, 2), np.nan)
    x[np.asarray(camera_indices), np.asarray(point_indices)] = points_2d
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
        return np.stack([camera_center(R, t) for R, t in zip(self.R, self.t)])

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
        import cv2

        img = cv2.imread(str(self.image_paths[i]), cv2.IMREAD_COLOR)
        if img is None:
            raise DataNotFoundError(f"cannot read {self.image_paths[i]}")
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)

    def summary(self):
        """One line: what this scene is."""
        obs = int(self.visible.sum())
        extra = f", {np.isfinite(self.tracks[..., 0]).sum()} observations in {self.tracks.shape[1]} extra tracks" if self.tracks is not None else ""
        return (f"{self.source} scene '{self.name}': {self.n_views} views, {self.n_points} points, "
                f"{obs} observations{extra}")


@dataclass
class Views:
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

    @property
    def n_views(self):
        return self.R.shape[0]

    @property
    def P(self):
        """(V, 3, 4) camera matrices ``K @ [R | t]``."""
        return np.einsum("vij,vjk->vik", self.K, np.concatenate([self.R, self.t[..., None]], axis=2))

    @property
    def C(self):
        """(V, 3) camera centres."""
        return -np.einsum("vji,vj->vi", self.R, self.t)

    def image(self, i):
        """View ``i`` as an RGB ``(H, W, 3)`` uint8 array."""
        import cv2

        img = cv2.imread(str(self.image_paths[i]), cv2.IMREAD_COLOR)
        if img is None:
            raise DataNotFoundError(f"cannot read {self.image_paths[i]}")
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def load_dino():
    """The Oxford dinosaur (36 views, 720×576) from ``dino/BAdino2.mat`` on the data path.

    The data's world frame is mirrored: with K from an RQ decomposition (positive diagonal) and a
    proper rotation R, every point lies behind every camera. We use ``X' = -X`` and ``t' = -t``
    (R unchanged), which keeps every pixel (``P' X' = -P X``) and puts all points in front.
    K, shared by all views, has skew and a principal point off the image: that is how the data is.

    Returns
    -------
    Scene
        ``x_true`` is ``newPoints2D`` (exactly ``P @ X``), ``x_meas`` is ``points2DMatrix``
        (about 1 px of noise), ``tracks`` the 4,983 ``viff`` tracks; -1 entries become NaN.

    Raises
    ------
    DataNotFoundError
        With the files expected and where to get them.
    """
    import scipy.io

    path = find_data("dino/BAdino2.mat", DINO_HELP)
    m = scipy.io.loadmat(path)
    Ps = [np.asarray(m["newPs"][0, i], float) for i in range(m["newPs"].shape[1])]
    KRt = [KRt_from_P(P) for P in Ps]
    K = np.mean([k for k, _, _ in KRt], axis=0)
    R = np.stack([r for _, r, _ in KRt])
    t = -np.stack([tt for _, _, tt in KRt])          # the mirror flip: t' = -t
    X = -np.asarray(m["newPoints3D"], float)          # and X' = -X
    x_true = nan_tracks(np.stack([np.asarray(m["newPoints2D"][0, i], float).T for i in range(len(Ps))]))
    x_meas = nan_tracks(np.asarray(m["points2DMatrix"], float).transpose(1, 0, 2))
    viff = np.asarray(m["viff"], float)
    tracks = nan_tracks(np.stack([viff[:, 0::2], viff[:, 1::2]], axis=-1).transpose(1, 0, 2))
    images = [path.parent / "images" / f"viff.{i:03d}.png" for i in range(len(Ps))]
    return Scene(name="dino", K=K, R=R, t=t, X=X, x_true=x_true, x_meas=x_meas, image_size=(720, 576),
                 source="real", noise_px=None, tracks=tracks,
                 image_paths=images if all(p.exists() for p in images) else None)


def load_scene(rng, verbose=True, **synthetic_kwargs):
    """The dinosaur if it is on the data path, else a synthetic turntable scene with ground truth.

    Parameters
    ----------
    rng : numpy.random.Generator
        Used only for the synthetic fallback.
    verbose : bool
        Print which scene was loaded (and, for the fallback, why).
    **synthetic_kwargs
        Passed to :func:`labutils.synthetic.make_scene` for the fallback.
    """
    try:
        scene = load_dino()
    except DataNotFoundError as exc:
        from .synthetic import make_scene

        # like the dinosaur: 36 views, ~1 px on the measured tracks; the 'real' tracks more precise, 2 % outliers
        kwargs = dict(layout="turntable", n_views=36, n_points=700, noise_px=1.0, track_noise_px=0.2,
                      track_outlier_ratio=0.02)
        kwargs.update(synthetic_kwargs)
        scene = make_scene(rng=rng, **kwargs)
        if verbose:
            print(f"Real data not found ({str(exc).splitlines()[0]}): using the SYNTHETIC fallback.")
    if verbose:
        print(scene.summary())
    return scene


# ---------------------------------------------------------------------------------------------
# Multi-view image sets with known cameras
# ---------------------------------------------------------------------------------------------
FOUNTAIN_HELP = """\
The EPFL fountain-P11 set is not on the data path. Put it at <data>/fountain-P11/:
  fountain-P11/images/0000.jpg ... 0010.jpg            11 images, 3072x2048
  fountain-P11/gt_dense_cameras/0000.jpg.camera ...    K, R, C per image (Strecha et al., CVPR 2008)
where <data> is $LABUTILS_DATA, the project's data/ folder, or ../shared/data/ beside the project."""

TEMPLE_HELP = """\
The Middlebury temple ring is not on the data path. Put it at <data>/templeRing/:
  templeRing/templeR0001.png ... templeR0047.png   47 images, 640x480
  templeRing/templeR_par.txt                       one line per image: name, K, R, t (P = K [R | t])
where <data> is $LABUTILS_DATA, the project's data/ folder, or ../shared/data/ beside the project."""


def load_fountain():
    """The EPFL/Strecha fountain-P11 set: 11 views, 3072×2048, with known K, R, t.

    The ``.camera`` files hold K, distortion (zero), R and the centre C with ``P = K [Rᵀ | -Rᵀ C]``
    (their R maps camera to world); here ``R = Rᵀ_file`` and ``t = -Rᵀ_file C`` in our convention.

    Returns
    -------
    Views

    Raises
    ------
    DataNotFoundError
        With the files expected and where to get them.
    """
    folder = find_data("fountain-P11/gt_dense_cameras", FOUNTAIN_HELP).parent
    files = sorted((folder / "gt_dense_cameras").glob("*.jpg.camera"))
    Ks, Rs, ts, paths = [], [], [], []
    for f in files:
        v = np.array(f.read_text().split(), float)
        if v.size != 26:
            raise ValueError(f"{f}: expected 26 numbers (K, distortion, R, C, width, height); got {v.size}")
        K, R_c2w, C = v[:9].reshape(3, 3), v[12:21].reshape(3, 3), v[21:24]
        Ks.append(K / K[2, 2])
        Rs.append(R_c2w.T)
        ts.append(-R_c2w.T @ C)
        paths.append(folder / "images" / f.name[:-len(".camera")])
    missing = [p for p in paths if not p.exists()]
    if not files or missing:
        raise DataNotFoundError(f"fountain-P11 is incomplete: {len(files)} camera files, missing images "
                                f"{[str(p) for p in missing[:3]]}\n" + FOUNTAIN_HELP)
    return Views(name="fountain-P11", K=np.stack(Ks), R=np.stack(Rs), t=np.stack(ts), image_paths=paths,
                 image_size=(int(v[24]), int(v[25])))


def load_temple():
    """The Middlebury temple ring: 47 views, 640×480, with known K, R, t (``P = K [R | t]``).

    The object's tight bounding box (from the set's README) is ``TEMPLE_BOX``.

    Returns
    -------
    Views

    Raises
    ------
    DataNotFoundError
        With the files expected and where to get them.
    """
    par = find_data("templeRing/templeR_par.txt", TEMPLE_HELP)
    lines = par.read_text().split("\n")
    n = int(lines[0].split()[0])
    Ks, Rs, ts, paths = [], [], [], []
    for k, line in enumerate(lines[1:1 + n], 2):
        tok = line.split()
        if len(tok) != 22:
            raise ValueError(f"{par}, line {k}: expected a name and 21 numbers; got {len(tok)} fields")
        v = np.array(tok[1:], float)
        Ks.append(v[:9].reshape(3, 3) / v[8])
        Rs.append(v[9:18].reshape(3, 3))
        ts.append(v[18:21])
        paths.append(par.parent / tok[0])
    missing = [p for p in paths if not p.exists()]
    if missing:
        raise DataNotFoundError(f"templeRing is incomplete: missing {[str(p) for p in missing[:3]]}\n" + TEMPLE_HELP)
    return Views(name="templeRing", K=np.stack(Ks), R=np.stack(Rs), t=np.stack(ts), image_paths=paths,
                 image_size=(640, 480))


TEMPLE_BOX = np.array([[-0.023121, -0.038009, -0.091940], [0.078626, 0.121636, -0.017395]])
"""The temple ring's tight bounding box (min corner, max corner), from the data set's README."""


if __name__ == "__main__":
    # `python -m labutils.data fetch NAME|all` and `list`: the registry and the command line live in fetch.py
    import sys

    from .fetch import main

    sys.exit(main())
