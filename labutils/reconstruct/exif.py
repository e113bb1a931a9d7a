"""The focal length of a photo in pixels from its EXIF header, or a stated guess.

Two EXIF routes give a focal length in pixels (EXIF 2.32, CIPA DC-008):

- ``FocalLength`` (mm) with ``FocalPlaneXResolution`` (pixels per ``FocalPlaneResolutionUnit`` on the sensor, for
  an image of ``PixelXDimension`` pixels): ``f_px = f_mm · resolution / unit_mm``, scaled to the file's width;
- ``FocalLengthIn35mmFilm``: the focal length that gives the same field of view on a 36 × 24 mm frame, defined on
  the diagonal (CIPA DC-008): ``f_px = f35 · diagonal_px / 43.27``.

Without either, the guess is ``1.2 · max(width, height)`` (a field of view of about 45°, COLMAP's default), and
the pipeline's self-calibration (:func:`labutils.reconstruct.focal_from_fundamentals`) and bundle adjustment
refine it.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["FocalGuess", "GUESS_FACTOR", "focal_from_exif"]

GUESS_FACTOR = 1.2
DIAGONAL_35MM = float(np.hypot(36.0, 24.0))               # 43.27 mm
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 1e-3}             # inch, cm, mm, µm (4 and 5: common extensions)
_EXIF_IFD = 0x8769
_TAGS = dict(focal=37386, fpx=41486, funit=41488, f35=41989, width=40962, height=40963)


@dataclass(frozen=True)
class FocalGuess:
    """A focal length in pixels of the file as read, and where it came from.

    Attributes
    ----------
    f_px : float
    source : str
        ``"exif-focal-plane"``, ``"exif-35mm"`` or ``"guess"``.
    text : str
        One line for the log, e.g. ``"EXIF FocalLength 4.3 mm at 1818 px/cm: 3101 px"``.
    """

    f_px: float
    source: str
    text: str


def _number(v):
    try:
        x = float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return x if np.isfinite(x) and x > 0 else None


def _exif_values(path):
    from PIL import Image  # Pillow comes with matplotlib

    with Image.open(path) as im:
        size = im.size
        exif = im.getexif()
        tags = dict(exif)
        try:
            tags.update(exif.get_ifd(_EXIF_IFD))
        except (KeyError, TypeError, ValueError):
            pass
    return size, {k: tags.get(t) for k, t in _TAGS.items()}


def focal_from_exif(path: str | Path) -> FocalGuess:
    """The focal length in pixels of the image file ``path`` (module docstring), or the stated guess.

    Parameters
    ----------
    path : str or Path
        A JPEG (or any image Pillow reads); a file without EXIF gets the guess.

    Returns
    -------
    FocalGuess

    Raises
    ------
    ValueError
        If the file cannot be read as an image (the message names it).

    Examples
    --------
    >>> import tempfile, os
    >>> from PIL import Image
    >>> p = os.path.join(tempfile.mkdtemp(), "a.jpg")
    >>> Image.new("RGB", (400, 300)).save(p)
    >>> focal_from_exif(p).f_px, focal_from_exif(p).source
    (480.0, 'guess')
    """
    try:
        (w, h), v = _exif_values(path)
    except (OSError, SyntaxError, ValueError) as exc:
        raise ValueError(f"{path}: cannot read the image ({exc})") from None
    f_mm, res, f35 = _number(v["focal"]), _number(v["fpx"]), _number(v["f35"])
    unit = _UNIT_MM.get(int(v["funit"]) if _number(v["funit"]) else 2)
    exif_w, exif_h = _number(v["width"]), _number(v["height"])
    if f_mm and res and unit:
        f_px = f_mm * res / unit
        sensor_w = exif_w if exif_w else None
        if sensor_w and exif_h and (sensor_w > exif_h) != (w > h) and w != h:
            sensor_w = exif_h                     # the file is rotated against the sensor's pixel grid
        if sensor_w:
            f_px *= w / sensor_w
        return FocalGuess(f_px, "exif-focal-plane",
                          f"EXIF FocalLength {f_mm:g} mm at {res:g} px per {unit:g} mm: {f_px:.0f} px")
    if f35:
        f_px = f35 * float(np.hypot(w, h)) / DIAGONAL_35MM
        return FocalGuess(f_px, "exif-35mm", f"EXIF FocalLengthIn35mmFilm {f35:g} mm: {f_px:.0f} px")
    f_px = GUESS_FACTOR * max(w, h)
    return FocalGuess(f_px, "guess", f"no focal length in EXIF: guessed {GUESS_FACTOR:g} x {max(w, h)} px = "
                                     f"{f_px:.0f} px (refined below)")
