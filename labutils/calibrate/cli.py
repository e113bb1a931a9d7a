"""Command line: calibrate a camera from photos of a chessboard.

``python -m labutils.calibrate "IMAGES_GLOB" --board 9x6 --square 0.025 --out CALIB.json [--k-out K.txt]
[--undistort "PHOTOS_GLOB" --undistort-out DIR]``

Finds the board's inner corners in every image (:func:`labutils.calibrate.detect_corners`), skips (and
reports) the images where it is not found or that cannot be read, calibrates with Zhang's method and Levenberg–Marquardt
(:func:`labutils.calibrate.calibrate_camera`) and writes

- ``CALIB.json``: ``{"K": 3×3, "dist": [k1, k2, p1, p2, k3], "rms_px": float, "image_size": [w, h],
  "views_used": [...], "views_rejected": [{"image": ..., "reason": ...}], "per_view_rms_px": [...],
  "std": {"fx": ..., ...}, "board": [nx, ny], "square": float, "settings": {...}}``;
- with ``--k-out K.txt``: K as 3 rows of 3 numbers, the calibration format of ``python -m labutils.sfm`` and
  ``python -m labutils.match``;
- with ``--undistort "PHOTOS_GLOB" --undistort-out DIR``: each photo (of your object, taken with the same camera
  at the same size and focus) undistorted into the ideal pinhole camera K, under the same file name in DIR: the
  pinhole K of ``K.txt`` then holds for them exactly.

All files are written at the end, each through a temporary file and ``os.replace``; on any failure none is.

Exit status 0 on success; 2 with one line ``error: <file>: what is wrong`` on stderr for any failure (no image
matches, fewer than 3 usable views, images of different sizes, an output folder that does not exist, an output
that would replace one of the input photos (e.g. ``--undistort-out`` the photos' own folder), an unreadable photo
to undistort, a write that fails), and then nothing is written. Progress goes to stderr, the
summary to stdout.

This module is only the command line; the estimators live in :mod:`labutils.calibrate.camera`.
"""
import argparse
import glob
import json
import os
import sys
from pathlib import Path

import cv2
import numpy as np

from ..core import cli as _cli
from .camera import calibrate_camera
from .chessboard import board_points, detect_corners
from .lens import undistort_points
from .rectification import remap_grid


def _board_arg(text):
    try:
        nx, ny = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected COLUMNSxROWS of inner corners, e.g. 9x6; got {text!r}") from None
    if nx < 2 or ny < 2:
        raise argparse.ArgumentTypeError(f"the board needs at least 2x2 inner corners; got {text!r}")
    return nx, ny


def _positive(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number; got {text!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number; got {text!r}")
    return v


def _expand(patterns):
    """The image files: each argument is a glob pattern (quoted) or a file name (the shell expanded it)."""
    files = []
    for pat in patterns:
        hits = sorted(glob.glob(pat)) if glob.has_magic(pat) else [pat]
        if not hits:
            raise _cli.CommandError(f"{pat}: no file matches this pattern")
        files += hits
    seen, out = set(), []
    for f in files:
        if f not in seen and not os.path.isdir(f):
            seen.add(f)
            out.append(f)
    if not out:
        raise _cli.CommandError(f"{' '.join(patterns)}: no image files (only folders) match")
    return out


def detect_all(files, board, quiet=False):
    """Read every image and find the board. Returns (names, corners, image_size, rejected).

    Raises CommandError when two readable images differ in size (one camera, one resolution at a time).
    """
    progress = _cli.Progress(len(files), "images", quiet=quiet)
    names, corners, rejected = [], [], []
    size, size_from = None, None
    for f in files:
        img = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        if img is None:
            rejected.append({"image": f, "reason": "unreadable: not an image file OpenCV can read"})
            progress.step(note=f"{f}: " + "unreadable, skipped")
            continue
        h, w = img.shape
        if size is None:
            size, size_from = (w, h), f
        elif (w, h) != size:
            raise _cli.CommandError(f"{f}: image size {w}x{h} differs from {size[0]}x{size[1]} ({size_from}); "
                                    "calibrate one camera at one resolution at a time (do not resize or mix cameras)")
        x = detect_corners(img, board)
        if x is None:
            rejected.append({"image": f, "reason": f"board not found ({board[0]}x{board[1]} inner corners)"})
            progress.step(note=f"{f}: " + "board not found, skipped")
            continue
        names.append(f)
        corners.append(x)
        progress.step()
    return names, corners, size, rejected


def k_text(K):
    """K as 3 rows of 3 numbers (the calibration format of ``python -m labutils.sfm``)."""
    return "".join(" ".join(f"{v:.10g}" for v in row) + "\n" for row in np.asarray(K, float))


def max_distortion_px(K, dist, image_size):
    """Largest displacement (px) the lens causes along the image border: how much undistortion matters.

    Returns None when the distortion model cannot be inverted somewhere on the border: the polynomial folds over
    there, which happens when no view showed the board near the image corners (it was extrapolated).
    """
    w, h = image_size
    s = np.linspace(0, 1, 33)
    border = np.vstack([np.c_[s * (w - 1), np.zeros_like(s)], np.c_[s * (w - 1), np.full_like(s, h - 1)],
                        np.c_[np.zeros_like(s), s * (h - 1)], np.c_[np.full_like(s, w - 1), s * (h - 1)]])
    try:
        return float(np.linalg.norm(undistort_points(border, K, dist) - border, axis=1).max())
    except ValueError:
        return None


_ENCODABLE = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp")


def undistorted_path(photo, out_dir):
    """Where the undistorted copy of ``photo`` goes: the same file name in ``out_dir`` (``.png`` for other types)."""
    p = Path(photo)
    return str(Path(out_dir) / (p.name if p.suffix.lower() in _ENCODABLE else p.stem + ".png"))


def check_no_input_overwritten(outputs, inputs):
    """Raise CommandError when an output (``[(path, what), ...]``) is one of the input photos or another output
    (:func:`labutils.core.cli.check_distinct`): it would replace it."""
    _cli.check_distinct(outputs, [(f, "an input photo") for f in inputs])


def undistorted_images(files, K, dist, size, out_dir, quiet=False):
    """``{out_dir/name: encoded bytes}`` of each photo undistorted into the ideal camera K (same K, same size).

    Raises CommandError for an unreadable photo, one of another size than the calibration images, or two photos
    with the same file name.
    """
    names = {}
    for f in files:
        name = Path(f).name
        if name in names:
            raise _cli.CommandError(f"{f}: same file name as {names[name]}; "
                                    "the undistorted copies would overwrite each other")
        names[name] = f
    maps = remap_grid(K, dist, size)
    progress = _cli.Progress(len(files), "images", quiet=quiet)
    out = {}
    for f in files:
        img = cv2.imread(f, cv2.IMREAD_COLOR)
        if img is None:
            raise _cli.CommandError(f"{f}: cannot read this image (--undistort)")
        if (img.shape[1], img.shape[0]) != tuple(size):
            raise _cli.CommandError(f"{f}: image size {img.shape[1]}x{img.shape[0]} differs from "
                                    f"the calibration images' {size[0]}x{size[1]}; K holds for that size only "
                                    "(--undistort)")
        und = cv2.remap(img, *maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        ext = Path(f).suffix.lower()
        ok, buf = cv2.imencode(ext if ext in _ENCODABLE else ".png", und,
                               [cv2.IMWRITE_JPEG_QUALITY, 95] if ext in (".jpg", ".jpeg") else [])
        if not ok:
            raise _cli.CommandError(f"{f}: cannot encode the undistorted image")
        out[undistorted_path(f, out_dir)] = buf.tobytes()
        progress.step(note=f"{f}: " + "undistorted")
    return out


def main(argv=None):
    parser = _cli.Parser(
        prog="python -m labutils.calibrate",
        description="Calibrate a camera (K and lens distortion) from photos of a chessboard, by Zhang's method and "
                    "Levenberg-Marquardt.",
        epilog='example: python -m labutils.calibrate "board/*.jpg" --board 9x6 --square 0.025 --out calib.json '
               "--k-out K.txt")
    parser.add_argument("images", nargs="+", help="the board photos: a quoted glob pattern (\"board/*.jpg\") or files")
    parser.add_argument("--board", type=_board_arg, required=True,
                        help="inner corners per row x per column, e.g. 9x6 (count the corners where 4 squares meet)")
    parser.add_argument("--square", type=_positive, default=1.0,
                        help="side of one square, in the unit you want t in (e.g. 0.025 for 25 mm; default 1)")
    parser.add_argument("--out", required=True, help="the result, JSON")
    parser.add_argument("--k-out", help="also write K as 3 rows (the K.txt of python -m labutils.sfm / match)")
    parser.add_argument("--fix-aspect-ratio", action="store_true", help="fx = fy (OpenCV's CALIB_FIX_ASPECT_RATIO)")
    parser.add_argument("--zero-tangential", action="store_true", help="p1 = p2 = 0")
    parser.add_argument("--fix-k3", action="store_true", help="k3 = 0 (for lenses with little distortion)")
    parser.add_argument("--undistort", nargs="+", metavar="PHOTO",
                        help="also undistort these photos (e.g. of your object; a quoted glob or files) into the "
                             "ideal camera K, for python -m labutils.match")
    parser.add_argument("--undistort-out", metavar="DIR", help="the folder for the undistorted photos (must exist)")
    parser.add_argument("--quiet", action="store_true", help="no progress, only the summary")
    args = parser.parse_args(argv)
    try:
        for path, what in [(args.out, "--out")] + ([(args.k_out, "--k-out")] if args.k_out else []):
            _cli.check_output_path(path, what)
        if bool(args.undistort) != bool(args.undistort_out):
            raise _cli.CommandError("--undistort and --undistort-out go together: the photos and the folder for them")
        if args.undistort_out and not Path(args.undistort_out).is_dir():
            raise _cli.CommandError(f"{args.undistort_out}: the folder does not exist (--undistort-out)")
        files = _expand(args.images)
        photos = _expand(args.undistort) if args.undistort else []
        planned = [(args.out, "--out"), (args.k_out, "--k-out")] + [
            (undistorted_path(f, args.undistort_out), f"--undistort-out (for {f})") for f in photos]
        check_no_input_overwritten(planned, files + photos)
        names, corners, size, rejected = detect_all(files, args.board, args.quiet)
        pattern = " ".join(args.images)
        if len(names) < 3:
            why = "; ".join(f"{r['image']}: {r['reason']}" for r in rejected[:3])
            why += " ..." if len(rejected) > 3 else ""
            raise _cli.CommandError(f"{pattern}: {len(names)} usable view{'s' if len(names) != 1 else ''} "
                                    f"of {len(files)} image{'s' if len(files) != 1 else ''}; at least 3 are needed"
                                    + (f" (rejected: {why})" if rejected else ""))
        X = board_points(args.board, args.square)
        try:
            cal = calibrate_camera([X] * len(names), corners, size, fix_aspect_ratio=args.fix_aspect_ratio,
                                   zero_tangential=args.zero_tangential, fix_k3=args.fix_k3)
        except ValueError as exc:
            raise _cli.CommandError(f"{pattern}: calibration failed: {exc}") from None
        result = {
            "K": cal.K.tolist(), "dist": cal.dist.tolist(), "rms_px": cal.rms_px, "image_size": list(size),
            "views_used": names, "views_rejected": rejected,
            "per_view_rms_px": cal.per_view_rms.tolist(), "std": {k: float(v) for k, v in cal.std.items()},
            "board": list(args.board), "square": args.square,
            "settings": {"fix_aspect_ratio": args.fix_aspect_ratio, "zero_tangential": args.zero_tangential,
                         "fix_k3": args.fix_k3},
        }
        outputs = {args.out: json.dumps(result, indent=1) + "\n"}
        if args.k_out:
            outputs[args.k_out] = k_text(cal.K)
        if photos:
            outputs.update(undistorted_images(photos, cal.K, cal.dist, size, args.undistort_out, args.quiet))
        _cli.write_all_atomically(outputs)
    except (_cli.CommandError, OSError) as exc:       # an OSError from writing names the file already
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:                  # a bug or an unforeseen input: still one line, no traceback
        print(f"error: {' '.join(args.images)}: unexpected {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    worst = int(np.argmax(cal.per_view_rms))
    print(f"calibrated from {len(names)} of {len(files)} images ({len(rejected)} skipped): {cal.summary()}")
    print(f"worst view: {names[worst]} (RMS {cal.per_view_rms[worst]:.3f} px)")
    shift = max_distortion_px(cal.K, cal.dist, size)
    if shift is None:
        print("warning: the distortion model folds over before the image border (it was extrapolated there): "
              "add photos with the board near the corners of the image")
    else:
        print(f"the lens moves pixels by up to {shift:.1f} px at the image border"
              + (": undistort your photos before matching them" if shift > 1 else ""))
    print(f"wrote {args.out}" + (f" and {args.k_out}" if args.k_out else "")
          + (f"; {len(photos)} undistorted photos in {args.undistort_out}" if photos else ""))
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
