"""Middlebury multi-view camera files (``*_par.txt``): one calibrated camera per image.

The format (Seitz, Curless, Diebel, Scharstein & Szeliski, "A comparison and evaluation of multi-view stereo
reconstruction algorithms", CVPR 2006; the data sets' README): the first line holds the number of images, then
one line per image::

    imgname.png k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 r12 r13 r21 r22 r23 r31 r32 r33 t1 t2 t3

with ``P = K [R | t]`` mapping world points to pixels (origin top-left, x right, y down): our convention.
Image names are relative to the file's folder.
"""
import os
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..core.scene import Views
from ..core.validation import ROTATION_TOL, RotationProjectedWarning, as_calibration, as_rotation

__all__ = ["read_par", "write_par"]


def read_par(path: str | os.PathLike, *, check_images: bool = True, rotation_tol: float = ROTATION_TOL) -> Views:
    """Read a Middlebury camera file into a :class:`labutils.core.Views` (K, R, t and image paths per view).

    Parameters
    ----------
    path : str or Path
    check_images : bool
        Check that every image exists beside the file.
    rotation_tol : float
        Largest entry of ``R Rᵀ - I`` accepted (1e-4: the files print 6 digits); an R off by more than round-off
        is replaced by the nearest rotation; one one-line
        :class:`labutils.core.validation.RotationProjectedWarning` for the file reports how many and the largest
        correction (and its line).

    Returns
    -------
    Views
        ``K`` scaled so that ``K[2, 2] == 1``; ``image_size`` is None (read it from the images).

    Raises
    ------
    ValueError
        ``<file>, line N: ...``: a first line that is not a positive image count; a line without a name and 21
        numbers; a number that is not finite; a K whose last row is not ``0 0 k`` (k ≠ 0), that is singular
        or has a negative focal length;
        an R that is not a rotation; a repeated image name; fewer or more lines than announced; a missing image.
    FileNotFoundError
        If the file itself does not exist.

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp(); p = os.path.join(d, "cams_par.txt")
    >>> write_par(p, ["a.png"], np.eye(3)[None], np.eye(3)[None], np.zeros((1, 3)))
    >>> read_par(p, check_images=False).K.shape
    (1, 3, 3)
    >>> _ = open(p, "a").write("b.png 1 2 3\\n")
    >>> read_par(p, check_images=False)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: .../cams_par.txt, line 3: more lines than the 1 images announced on line 1
    """
    path = Path(path)
    lines = path.read_text(errors="replace").splitlines()
    first = lines[0].split() if lines else []
    if len(first) != 1 or not first[0].isdigit() or int(first[0]) == 0:
        raise ValueError(f"{path}, line 1: expected the number of images (a positive integer); "
                         f"got {lines[0][:60] if lines else 'an empty file'!r}")
    n = int(first[0])
    Ks, Rs, ts, names, paths, projected = [], [], [], {}, [], []
    for k, line in enumerate(lines[1:], 2):
        tok = line.split()
        if not tok:
            continue
        where = f"{path}, line {k}"
        if len(paths) == n:
            raise ValueError(f"{where}: more lines than the {n} images announced on line 1")
        if len(tok) != 22:
            raise ValueError(f"{where}: expected an image name and 21 numbers (K, R, t row by row); got "
                             f"{len(tok)} fields")
        try:
            v = np.array(tok[1:], dtype=float)
        except ValueError:
            bad = next(s for s in tok[1:] if not _is_float(s))
            raise ValueError(f"{where}: {bad!r} is not a number") from None
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{where}: non-finite number (NaN or inf)")
        K = as_calibration(v[:9].reshape(3, 3), f"{where}: K")
        with warnings.catch_warnings():                  # one report for the file, below
            warnings.simplefilter("ignore", RotationProjectedWarning)
            R, t = as_rotation(v[9:18].reshape(3, 3), f"{where}: R", tol=rotation_tol), v[18:21]
        change = np.abs(R - v[9:18].reshape(3, 3)).max()
        if change > 0:
            projected.append((change, k))
        if tok[0] in names:
            raise ValueError(f"{where}: image {tok[0]} is listed twice (also on line {names[tok[0]]})")
        names[tok[0]] = k
        img = path.parent / tok[0]
        if check_images and not img.is_file():
            raise ValueError(f"{where}: image {tok[0]} not found (looked for {img})")
        Ks.append(K)
        Rs.append(R)
        ts.append(t)
        paths.append(img)
    if len(paths) < n:
        raise ValueError(f"{path}, line 1: {n} images announced; the file lists {len(paths)}")
    if projected:
        change, k = max(projected)
        warnings.warn(f"{path}: {len(projected)} of {n} rotations are off SO(3) by round-off (within "
                      f"{rotation_tol:g}): replaced by the nearest rotations, largest correction {change:.2g} "
                      f"(line {k})",
                      RotationProjectedWarning, stacklevel=2)
    return Views(name=path.stem, K=np.stack(Ks), R=np.stack(Rs), t=np.stack(ts), image_paths=paths)


def _is_float(s):
    try:
        float(s)
        return True
    except ValueError:
        return False


def write_par(path: str | os.PathLike, names: Sequence[str], K: ArrayLike, R: ArrayLike, t: ArrayLike) -> None:
    """Write cameras as a Middlebury camera file (the inverse of :func:`read_par`).

    Parameters
    ----------
    path : str or Path
    names : sequence of str
        Image file names, relative to the file's folder.
    K, R : (V, 3, 3) array_like
    t : (V, 3) array_like
    """
    K, R, t = np.asarray(K, float), np.asarray(R, float), np.asarray(t, float)
    if K.shape != (len(names), 3, 3) or R.shape != K.shape or t.shape != (len(names), 3):
        raise ValueError(f"K, R must be ({len(names)}, 3, 3) and t ({len(names)}, 3) for {len(names)} names; got "
                         f"{K.shape}, {R.shape}, {t.shape}")
    rows = [f"{len(names)}"]
    for nm, k, r, tt in zip(names, K, R, t):
        rows.append(" ".join([str(nm)] + [repr(float(x)) for x in np.concatenate([k.ravel(), r.ravel(), tt])]))
    Path(path).write_text("\n".join(rows) + "\n")
