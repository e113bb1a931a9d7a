"""Loading the real data sets — the dinosaur, the EPFL fountain, the Middlebury temple ring — and the synthetic
fallback when they are missing.

Where the files are looked for is :mod:`labutils.data.paths`; ``python -m labutils.data fetch NAME|all`` downloads
them (:mod:`labutils.data.fetch`) and ``python -m labutils.data list`` shows what is present.
"""

import warnings

import numpy as np
import scipy.io

from ..core.geometry import KRt_from_P
from ..core.scene import Scene, Views, nan_tracks
from ..core.synthetic import make_scene
from ..core.validation import RotationProjectedWarning, as_rng, as_rotation
from .middlebury import read_par
from .paths import DataNotFoundError, find_data, how_to_get

DINO_HELP = """\
The Oxford dinosaur is not on the data path. Put it at <data>/dino/:
  dino/BAdino2.mat                   cameras, 3D points and tracks (the course's file; the
                                     tracks come from the Oxford VGG multi-view data page,
                                     https://www.robots.ox.ac.uk/~vgg/data/mview/, 'Dinosaur')
  dino/images/viff.000.png ... viff.035.png   the 36 images (720x576)"""


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


def load_scene(*, rng, verbose=True, **synthetic_kwargs):
    """The dinosaur if it is on the data path, else a synthetic turntable scene with ground truth.

    Parameters
    ----------
    rng : numpy.random.Generator
        Used only for the synthetic fallback.
    verbose : bool
        Print which scene was loaded (and, for the fallback, why).
    **synthetic_kwargs
        Passed to :func:`labutils.core.make_scene` for the fallback.
    """
    as_rng(rng)
    try:
        scene = load_dino()
    except DataNotFoundError as exc:
        # like the dinosaur: 36 views, ~1 px on the measured tracks; the 'real' tracks more precise, 2 % outliers
        kwargs = dict(layout="turntable", n_views=36, n_points=700, noise_px=1.0, track_noise_px=0.2,
                      track_outlier_ratio=0.02)
        kwargs.update(synthetic_kwargs)
        scene = make_scene(rng=rng, **kwargs)
        if verbose:
            missing = str(exc).split(" is not on the data path")[0]
            print(f"Real data not found: {missing} is not on the data path. {how_to_get('dino')}. Using the "
                  "SYNTHETIC fallback.")
    if verbose:
        print(scene.summary())
    return scene


FOUNTAIN_HELP = """\
The EPFL fountain-P11 set is not on the data path. Put it at <data>/fountain-P11/:
  fountain-P11/images/0000.jpg ... 0010.jpg            11 images, 3072x2048
  fountain-P11/gt_dense_cameras/0000.jpg.camera ...    K, R, C per image (Strecha et al., CVPR 2008)"""

TEMPLE_HELP = """\
The Middlebury temple ring is not on the data path. Put it at <data>/templeRing/:
  templeRing/templeR0001.png ... templeR0047.png   47 images, 640x480
  templeRing/templeR_par.txt                       one line per image: name, K, R, t (P = K [R | t])"""


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
    Ks, Rs, ts, paths, projected = [], [], [], [], [0.0]
    for f in files:
        v = np.array(f.read_text().split(), float)
        if v.size != 26:
            raise ValueError(f"{f}: expected 26 numbers (K, distortion, R, C, width, height); got {v.size}")
        K, R_c2w, C = v[:9].reshape(3, 3), v[12:21].reshape(3, 3), v[21:24]
        with warnings.catch_warnings():                     # 1e-6 off SO(3) in the files: the nearest rotation
            warnings.simplefilter("ignore", RotationProjectedWarning)
            R_c2w, R_file = as_rotation(R_c2w, f"{f}: R"), R_c2w
        projected.append(np.abs(R_c2w - R_file).max())
        Ks.append(K / K[2, 2])
        Rs.append(R_c2w.T)
        ts.append(-R_c2w.T @ C)
        paths.append(folder / "images" / f.name[:-len(".camera")])
    missing = [p for p in paths if not p.exists()]
    if not files or missing:
        raise DataNotFoundError(f"fountain-P11 is incomplete: {len(files)} camera files, missing images "
                                f"{[str(p) for p in missing[:3]]}\n" + FOUNTAIN_HELP)
    if max(projected) > 0:
        warnings.warn(f"{folder}: {sum(c > 0 for c in projected)} of {len(files)} rotations are off SO(3) by "
                      f"round-off: replaced by the nearest rotations, largest correction {max(projected):.2g}",
                      RotationProjectedWarning, stacklevel=2)
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
    try:
        views = read_par(par)
    except FileNotFoundError as exc:
        raise DataNotFoundError(f"templeRing is incomplete: {exc}\n" + TEMPLE_HELP) from None
    return Views(name="templeRing", K=views.K, R=views.R, t=views.t, image_paths=views.image_paths,
                 image_size=(640, 480))


TEMPLE_BOX = np.array([[-0.023121, -0.038009, -0.091940], [0.078626, 0.121636, -0.017395]])
"""The temple ring's tight bounding box (min corner, max corner), from the data set's README."""
