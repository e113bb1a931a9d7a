"""``python -m labutils.match IMAGE_DIR K.txt --out TRACKS.txt [--max-size PIXELS] [--seed N]``.

Tracks from a folder of calibrated images: the images (PNG, JPEG) in sorted file-name order, K as
``python -m labutils.sfm`` reads it (one shared 3×3, or one per image stacked), and a VGG track file
out (one row per track, ``x y`` per image in that order, ``-1 -1`` where unseen), in the pixels of the
original images, ready for ``python -m labutils.sfm TRACKS.txt K.txt --out RESULT.json``.

The work is :mod:`labutils.features`; this module only reads, reports and writes. Progress (a bar per
stage) goes to stderr; every failure is one line on stderr, ``error: <file>[, line N]: what is wrong``,
with exit status 2, and nothing is written.
"""
import argparse
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .features import (
    IMAGE_SUFFIXES,
    detect_features,
    match_views,
    read_gray,
    scale_calibration,
    select_pairs,
    to_original_pixels,
    track_statistics,
    tracks_from_matches,
)
from .sfm import read_calibration, write_tracks


class _Fail(Exception):
    """A failure reported as one line, ``error: <message>``, with exit status 2."""


class ProgressBar:
    """A one-line text progress bar on a stream (stderr): ``label [#####.....] 12/55 3.1 s``."""

    def __init__(self, label, total, stream=None, width=30, enabled=True):
        self.label, self.total, self.width = label, max(int(total), 1), width
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled
        self.t0 = time.perf_counter()

    def __call__(self, done, total=None):
        if not self.enabled:
            return
        n = int(self.width * done / self.total)
        self.stream.write(f"\r{self.label:<10} [{'#' * n}{'.' * (self.width - n)}] {done}/{self.total} "
                          f"{time.perf_counter() - self.t0:.1f} s")
        if done >= self.total:
            self.stream.write("\n")
        self.stream.flush()


def image_files(folder: str | Path) -> list[Path]:
    """The PNG and JPEG files of ``folder`` in sorted file-name order."""
    return sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def _check_output(out):
    out = Path(out)
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise _Fail(f"{out}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise _Fail(f"{out}: the folder {folder} is not writable")
    if out.is_dir():
        raise _Fail(f"{out}: is a folder; give a file name")


def _write_tracks_atomically(out, tracks):
    """Write to a temporary file beside ``out``, give it the usual mode, then rename it; clean up on failure."""
    out = Path(out)
    fd, tmp = tempfile.mkstemp(dir=out.parent if str(out.parent) else ".", prefix=f".{out.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write_tracks(tmp, tracks)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, out)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def run(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    """Do the work of :func:`main` for parsed ``args``; ``log`` prints a line to stderr. Returns the track count."""
    folder = Path(args.image_dir)
    if not folder.is_dir():
        raise _Fail(f"{folder}: not a folder")
    if args.max_size is not None and args.max_size < 16:
        raise _Fail(f"--max-size must be at least 16 pixels; got {args.max_size}")
    if args.window is not None and args.window < 1:
        raise _Fail(f"--window must be at least 1; got {args.window}")
    if not 0 < args.ratio <= 1:
        raise _Fail(f"--ratio must be in (0, 1]; got {args.ratio}")
    if not args.threshold > 0:
        raise _Fail(f"--threshold must be positive; got {args.threshold}")
    paths = image_files(folder)
    if len(paths) < 2:
        raise _Fail(f"{folder}: {len(paths)} image{'s' if len(paths) != 1 else ''} (PNG, JPEG); at least 2 are needed")
    try:
        K = read_calibration(args.K, len(paths))
    except ValueError as exc:
        raise _Fail(str(exc).replace("views of the tracks file", f"images in {folder}")) from None
    _check_output(args.out)
    import cv2

    for p in paths:                      # a format check from each file's first bytes, before any work
        if not cv2.haveImageReader(str(p)):
            raise _Fail(f"{p}: cannot read the image (not a PNG/JPEG file, or damaged)")
    V = len(paths)
    log(f"{V} images in {folder}" + (f", reduced to at most {args.max_size} px" if args.max_size else ""))

    bar = ProgressBar("features", V, enabled=not args.quiet)
    features = []
    for v, p in enumerate(paths):
        try:
            gray, scale, _ = read_gray(p, args.max_size)
        except ValueError as exc:
            if not args.quiet:
                sys.stderr.write("\n")
            raise _Fail(str(exc)) from None
        features.append(detect_features(gray, scale=scale))
        bar(v + 1)
    K_work = np.stack([scale_calibration(K[v], f.scale) for v, f in enumerate(features)])

    strategy = args.pairs
    if strategy == "auto":
        strategy = "all" if V <= 20 else "sequence"
    window = args.window if args.window is not None else 5
    pairs = select_pairs(V, strategy, window if strategy != "all" else None)
    log(f"{sum(len(f) for f in features)} features ({min(len(f) for f in features)}-{max(len(f) for f in features)} "
        f"per image); matching {len(pairs)} pairs ({strategy}" + ("" if strategy == "all" else f", window {window}")
        + ")")
    bar = ProgressBar("matching", len(pairs), enabled=not args.quiet)
    result = match_views(features, pairs, rng=np.random.default_rng(args.seed), K=K_work, ratio=args.ratio,
                         threshold_px=args.threshold, min_inliers=args.min_inliers, progress=bar)
    tot = result.totals()
    log(f"matches: {tot['ratio']} after the ratio test, {tot['mutual']} mutual, {tot['epipolar']} epipolar inliers "
        f"in {len(result.matches)} of {len(pairs)} pairs "
        f"({result.seconds['matching']:.1f} s matching, {result.seconds['epipolar']:.1f} s epipolar filter)")
    tracks = tracks_from_matches(features, result)
    stats = track_statistics(tracks.x)
    log(f"tracks: {stats['tracks']} ({tracks.n_conflicts} rejected for two features in one image), "
        f"{stats['observations']} observations, length {2 if stats['tracks'] else 0}-{stats['max_length']}, "
        f"mean {stats['mean_length']:.2f}")
    if stats["tracks"] == 0:
        raise _Fail(f"{folder}: no tracks found (no pair of images has {args.min_inliers} verified matches)")
    x = np.stack([to_original_pixels(tracks.x[v], f.scale) for v, f in enumerate(features)])
    try:
        _write_tracks_atomically(args.out, x)
    except OSError as exc:
        raise _Fail(f"{args.out}: cannot write the tracks ({exc.strerror or exc})") from None
    return stats["tracks"]


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit status (0, or 2 after a one-line error on stderr)."""
    parser = argparse.ArgumentParser(
        prog="python -m labutils.match",
        description="Tracks from a folder of calibrated images (SIFT, ratio test, mutual check, epipolar filter "
                    "with known K, union-find), written as a VGG track file for python -m labutils.sfm.")
    parser.add_argument("image_dir", help="folder of images (PNG, JPEG), used in sorted file-name order")
    parser.add_argument("K", help="calibration: one 3x3 matrix shared by all images, or one per image (3V rows)")
    parser.add_argument("--out", required=True, help="the track file to write: one row per track, 'x y' per image, "
                                                     "-1 -1 where unseen, in the pixels of the original images")
    parser.add_argument("--max-size", type=int, default=None,
                        help="reduce each image so that its longer side is at most this many pixels (default: none)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random generator (default 0)")
    parser.add_argument("--pairs", choices=("auto", "all", "sequence", "ring"), default="auto",
                        help="which pairs to match (default auto: all for up to 20 images, else sequence)")
    parser.add_argument("--window", type=int, default=None,
                        help="for --pairs sequence/ring: match images at most this far apart (default 5)")
    parser.add_argument("--ratio", type=float, default=0.8, help="ratio-test threshold (default 0.8)")
    parser.add_argument("--threshold", type=float, default=1.0,
                        help="epipolar (Sampson) threshold in pixels of the reduced images (default 1)")
    parser.add_argument("--min-inliers", type=int, default=20,
                        help="fewest verified matches to keep a pair (default 20)")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)

    def log(msg):
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    try:
        n = run(args, log)
    except _Fail as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}: {n} tracks in {len(image_files(args.image_dir))} images")
    return 0


if __name__ == "__main__":
    sys.exit(main())
