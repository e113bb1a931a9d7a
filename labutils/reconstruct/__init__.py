"""Your own object from your own photos: ``python -m labutils.reconstruct PHOTOS_DIR --out RESULT.json`` (notebook 15).

The stage on top of the others: it joins matching (:mod:`labutils.match`), structure from motion
(:mod:`labutils.sfm`), the lens model (:mod:`labutils.calibrate`) and the point cloud (:mod:`labutils.model`) for a
folder of photos taken with one camera, with or without its calibration.

- :mod:`~labutils.reconstruct.exif` — the focal length from the photo's EXIF header, or a stated guess;
- :mod:`~labutils.reconstruct.capture` — the capture check (blur, features, the view graph, what to reshoot);
- :mod:`~labutils.reconstruct.intrinsics` — self-calibration of the focal length from the pairs' fundamental
  matrices, and one focal length with radial distortion refined in a bundle adjustment with a prior;
- :mod:`~labutils.reconstruct.pipeline` — the stages in order (:func:`reconstruct_photos`);
- :mod:`~labutils.reconstruct.synthetic` — rendered photos through a known lens, for tests and notebook 15;
- :mod:`~labutils.reconstruct.cli` — the command line.
"""
from .capture import CaptureReport, capture_check, sharpness
from .exif import FocalGuess, focal_from_exif
from .intrinsics import SharedIntrinsics, focal_from_fundamentals, refine_shared_intrinsics
from .pipeline import NotReconstructable, PhotoReconstruction, image_files, reconstruct_photos
from .synthetic import render_photo_folder

__all__ = ["CaptureReport", "FocalGuess", "NotReconstructable", "PhotoReconstruction", "SharedIntrinsics",
           "capture_check", "focal_from_exif", "focal_from_fundamentals", "image_files", "reconstruct_photos",
           "refine_shared_intrinsics", "render_photo_folder", "sharpness"]
